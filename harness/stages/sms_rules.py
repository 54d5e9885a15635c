"""The stiffness rules' statics on one mesh: the sms stage's unoptimised rows.

Every rule is solved under every load, each constraint set ordered and factorised
symbolically once for all of them (harness.mechanics.statics.solve_all). A network of more
than ALL_RULES_DOFS dofs (a 200k-tet mesh: 110k dofs, ~10 s a factorisation, six rules
under six constraint sets) solves its free-traction training states (one constraint set)
for every rule first, then the other loads rule by rule in the order of their
free-traction score, and stops at the rules that cannot rank first: a rule's
``G_fit_score`` (harness/optimize/select.py ``training_score``: the mean of its
free-traction part and its clamped part) is at least half its free-traction part, so a
rule whose half is above the best complete score so far is not solved under the clamps.
Its row keeps that bound (``G_fit_score_bound``) and says why it has no other score. A case
that ranks by [loads] rank_by (calibrate's) solves every rule on the free-traction and the
rank_by states instead, and under the other clamps only the rule they rank first.
"""

from __future__ import annotations

import math

import numpy as np

from harness.mechanics import statics
from harness.mechanics.statics import StaticsResult
from harness.optimize.select import training_score
from harness.scoring import g_arrays

ALL_RULES_DOFS = 60_000  # networks up to this many dofs solve every rule under every load


def free_loads(case) -> list[str]:
    """The fitted loads of the linear stress sets (free traction, minimal constraints)."""
    return [l.name for l in case.loads if l.family is not None and l.name in case.fit_loads]


def _merge(a, b, names):
    """One StaticsResult over ``names`` from two that cover them."""
    pick = [(a, a.names.index(n)) if n in a.names else (b, b.names.index(n)) for n in names]
    return StaticsResult(
        tuple(names),
        np.array([r.u[i] for r, i in pick]),
        np.array([r.forces[i] for r, i in pick]),
        np.array([r.load_seconds[i] for r, i in pick]),
    )


def solve_rules(
    case, nets: dict, score, first: str | None = None, status=lambda msg: None, rank=None
) -> tuple[dict, dict]:
    """({rule: StaticsResult over every load}, {rule: lower bound of its G_fit_score} for
    the rules left unsolved under the clamps). ``score(res)``: a complete result's
    G_fit_score, and of a free-traction-only result its free-traction part; ``first``: a
    rule always solved (the one the user named); ``rank(res)``: the G_rank_score of a
    result holding the [loads] rank_by states (None: the case has none)."""
    rules = list(nets)
    if score is None:
        return dict(zip(rules, statics.solve_all(list(nets.values()), case))), {}
    n_dofs = next(iter(nets.values())).points.size
    free = free_loads(case)
    rest = [l.name for l in case.loads if l.name not in free]
    if n_dofs <= ALL_RULES_DOFS or not free or not rest:
        status(f"statics of the {len(rules)} stiffness rule{'s' * (len(rules) > 1)}")
        return dict(zip(rules, statics.solve_all(list(nets.values()), case))), {}
    if rank is not None:
        return _ranked(case, nets, score, first, status, rank)
    status(f"statics of the {len(rules)} stiffness rules on the free-traction states")
    part = dict(zip(rules, statics.solve_all(list(nets.values()), case, free)))
    halves = {
        r: 0.5 * score(part[r]) if len(free) < len(case.fit_loads) else score(part[r])
        for r in rules
    }
    names = [l.name for l in case.loads]
    solved, bounds, best = {}, {}, math.inf
    for r in sorted(rules, key=lambda r: (r != first, halves[r])):
        if r != first and halves[r] > best:
            bounds[r] = halves[r]
            continue
        status(f"statics of the stiffness rule {r} under the clamps")
        res = _merge(part[r], statics.solve_all([nets[r]], case, rest)[0], names)
        solved[r] = res
        best = min(best, score(res))
    return solved, bounds


def _ranked(case, nets: dict, score, first, status, rank) -> tuple[dict, dict]:
    """solve_rules on a large mesh of a case with [loads] rank_by: every rule on the
    free-traction and the rank_by states, then under every other clamp only ``first`` and
    the rule of the lowest G_rank_score (the others get their G_fit_score bound)."""
    rules, free = list(nets), free_loads(case)
    some = free + [n for n in dict.fromkeys(case.rank_by) if n not in free]
    rest = [l.name for l in case.loads if l.name not in some]
    status(f"statics of the {len(rules)} stiffness rules on the free and the ranking states")
    part = dict(zip(rules, statics.solve_all(list(nets.values()), case, some)))
    best = min(rules, key=lambda r: (rank(part[r]), r))
    names = [l.name for l in case.loads]
    solved, bounds = {}, {}
    for r in rules:
        if r not in (first, best):
            bounds[r] = 0.5 * score(_merge(part[r], part[r], free))  # as solve_rules bounds
            continue
        status(f"statics of the stiffness rule {r} under the clamps")
        solved[r] = _merge(part[r], statics.solve_all([nets[r]], case, rest)[0], names)
    return solved, bounds


def _per_load(res, held, u_ref, names, classes, weights) -> dict:
    """{load: own normalised G} of a statics result over the loads ``held``."""
    sc = g_arrays(
        u_ref[[names.index(n) for n in held]],
        res.u[[res.names.index(n) for n in held]],
        classes,
        weights,
        held,
    )
    return sc.per_load_norm


def rank_score_of(res, case, u_ref, names, classes, weights) -> float:
    """The G_rank_score of a statics result holding the [loads] rank_by states."""
    held = [n for n in case.rank_by if n in case.fit_loads]  # a repeated name counts again
    if not held:
        return math.inf
    per = _per_load(res, list(dict.fromkeys(held)), u_ref, names, classes, weights)
    return float(np.mean([per[n] for n in held]))


def fit_score_of(res, case, u_ref, names, classes, weights) -> float:
    """The G_fit_score of a statics result over the fitted loads it holds (of the
    free-traction states alone: their part of it)."""
    from harness.stages.sms_measures import families

    held = [n for n in case.fit_loads if n in res.names]
    per = _per_load(res, held, u_ref, names, classes, weights)
    return training_score([per[n] for n in held], families(case, held))
