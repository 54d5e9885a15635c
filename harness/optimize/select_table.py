"""The validation table's arithmetic (harness/optimize/select.py): the folds of the training
states, each model's free-traction and clamped errors, the ratio to the rule and the
choice. Pure functions of the scores: no fit, no solve."""

from __future__ import annotations

import math

import numpy as np

from harness.case.sections import SELECT_CRITERIA

CLAMPED = "clamped"  # the family of the training states that hold a face (not the linear sets')


def make_folds(families) -> dict:
    """{fold name: block indices left out}: each free-traction family as one fold, and
    the clamped states together as one ('clamped'): its fit has seen no clamp at all, as
    the final fit has never seen the clamps users put elsewhere (with one clamped state
    out at a time the fit would learn the shared clamp from the others)."""
    folds: dict = {}
    for i, f in enumerate(families):
        folds.setdefault(f, []).append(i)
    return folds


FREE = "free"  # the fold of every free-traction family together (two_folds)


def two_folds(families) -> dict:
    """{fold: block indices}, two folds for the cheaper levels of
    harness/optimize/select_counts.py (two fits per candidate instead of one per family):
    the free-traction families together ('free') and the clamped states ('clamped'); with
    no clamped state (every one dropped: the FEM's error on them too large), the free
    families alternately into 'free-a' and 'free-b', in the order they come; with a single
    family, its one fold (no validation: the rule is kept)."""
    free = list(dict.fromkeys(f for f in families if f != CLAMPED))
    if CLAMPED in families:
        name = {f: FREE for f in free}
    elif len(free) >= 2:
        name = {f: f"{FREE}-{'ab'[i % 2]}" for i, f in enumerate(free)}
    else:
        return make_folds(families)
    folds: dict = {}
    for i, f in enumerate(families):
        folds.setdefault(CLAMPED if f == CLAMPED else name[f], []).append(i)
    return folds


def rule_row(scores, folds: dict) -> dict:
    """The table's row of the rule: the mean of its scores (each block's own normalised G)
    over each fold's blocks."""
    scores = np.asarray(scores, float)
    return dict(model="rule", **{f: float(scores[i].mean()) for f, i in folds.items()})


def summary(row: dict, folds) -> dict:
    """A table row's ``free`` (mean over the free-traction families' folds), ``clamped``
    (the clamped fold's) and ``score`` (their mean, or the one there)."""
    if not all(f in row for f in folds):
        return {"free": math.nan, "clamped": math.nan, "score": math.nan}
    free = [row[f] for f in folds if f != CLAMPED]
    held = [row[f] for f in folds if f == CLAMPED]
    parts = [float(np.mean(v)) if v else math.nan for v in (free, held)]
    return {"free": parts[0], "clamped": parts[1], "score": float(np.nanmean(parts))}


def training_score(values, families) -> float:
    """The score :func:`summary` gives a model that is not fitted (a rule): ``values`` each
    training state's own normalised G, ``families`` theirs, averaged per fold first. The
    stage starts its fits from the rule this ranks first: the pooled G would let the
    states with the largest displacements (the clamped ones) decide alone."""
    if not len(values):
        return math.nan
    folds = make_folds(families)
    return summary(
        {f: float(np.mean([values[i] for i in idx])) for f, idx in folds.items()}, folds
    )["score"]


# a candidate beats the rule by more than 1 % (of its score, or a ratio below 0.99): less is a tie
MARGIN = 0.01


def ratio_to_rule(row: dict, rule: dict) -> float:
    """The geometric mean of the row's free and clamped errors each divided by the rule's
    (the parts the table has; NaN when a part the rule has is missing or a rule error is 0)."""
    parts = [(row[k], rule[k]) for k in ("free", "clamped") if math.isfinite(rule[k])]
    if not parts or any(not math.isfinite(a) or b <= 0 for a, b in parts):
        return math.nan
    return float(np.exp(np.mean([math.log(max(a, 1e-300) / b) for a, b in parts])))


def choose(table, criterion: str = "ratio") -> dict:
    """The row chosen (module doc): 'ratio', the lowest ``ratio`` below 1 - MARGIN; 'score',
    the lowest score among the candidates that beat the rule (the table's first row) on
    the score and are no worse on the clamped states, where there are any; else the rule."""
    if criterion not in SELECT_CRITERIA:
        raise ValueError(f"criterion {criterion!r} is not one of {SELECT_CRITERIA}")
    rule = table[0]
    if criterion == "ratio":
        ok = [r for r in table[1:] if math.isfinite(r["ratio"]) and r["ratio"] < 1.0 - MARGIN]
        return min(ok, key=lambda r: r["ratio"]) if ok else rule

    def beats(a, b):
        return a < b - max(MARGIN * b, 1e-9)

    ok = [
        r
        for r in table[1:]
        if math.isfinite(r["score"])
        and beats(r["score"], rule["score"])
        and not (math.isfinite(rule["clamped"]) and r["clamped"] > rule["clamped"] + 1e-9)
    ]
    return min(ok, key=lambda r: r["score"]) if ok else rule


def scored(table: list, names: tuple) -> list:
    """The table's rows with their ``free``, ``clamped``, ``score`` (:func:`summary`) and
    ``ratio`` to the rule (the first row)."""
    for row in table:
        row.update(summary(row, names))
    for row in table:
        row["ratio"] = ratio_to_rule(row, table[0])
    return table
