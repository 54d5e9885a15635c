"""The sms stage's validated fit (``[optimizer.select]``): the capacity of the fit chosen by
leave-one-family-out validation on the fitted loads (harness/optimize/select.py), the
rule when nothing beats it, the final fit from several starts; then the validation loads
(harness/stages/sms_accept.py) export the fit only when it beats every rule there, else
the rule they rank first.

The row is the stage's optimised row with, besides, ``choice`` (the rule, or the
candidate chosen), ``val_<model>`` (each model's validation score), ``val_families``,
``n_starts``, ``val_skipped`` (always NaN: the validation always runs; the column stays
for the scripts that read it, as calibrate's JSON ``validation_skipped``, always null) and
``G_heldout_mean_spread`` (max - min of G_heldout_mean over the final fit's starts:
differences inside it are ties, not rankings; NaN with one start), ``seconds_validation``
and ``seconds_final`` (the wall time of the validation and of the final fit, within ``seconds``),
``start_rule`` (the rule the fits started from), ``val_fold_choice`` (the leave-one-family-
out choice), the validation loads' ``val_fit``, ``val_best_rule``, ``val_best_rule_score``,
``val_accepted`` and the exported model's ``G_val_mean`` and ``G_<load>``. The validation
table is ``validation.csv`` (one row per model, one column per left-out family and the
score).

Every fit stops by counts fixed before the run: the validation fits by
``[optimizer.select] maxiter``, the final fit's starts by the case's ``[optimizer]
options`` maxiter (FINAL_MAXITER without one), or on a large mesh by the fewer counts
harness/optimize/select_counts.py chooses from its flop counts (row columns ``fit_*``); the case's
``max_seconds`` caps the whole validated fit and only aborts (harness/optimize/deadline.py),
so the same mesh and seed export the same model on any machine under any load. The fits
run side by side in worker processes where the machine has the cores
(harness/forkpool.py), with the same numbers as one after the other.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
import pandas as pd
import scipy.sparse as sp

from harness.errors import CaseError
from harness.mechanics import statics
from harness.models.learned_rule import geometry
from harness.models.springs import spring_directions
from harness.models.volume import initial_kv, with_volume
from harness.optimize import select as sel
from harness.optimize import select_counts
from harness.optimize.problem import FitProblem
from harness.scoring import node_weights
from harness.stages import sms_accept as accept
from harness.stages.sms_measures import families, heldout_columns, scored_columns

# L-BFGS-B iterations of each start of the final fit when the case's options set none (the
# lug's default fit: ~15 s of one core). Its constants are exported: on the held-out bench
# bodies 100 iterations stopped far from the minimum (held-out error 1.3x that of 300)
FINAL_MAXITER = 300


def optimise(setting, run_, base, first, first_res=None, rules=()):
    """(row, network, trace) of the validated fit of ``base``, a springs-only network (the
    stage gives the other model classes their plain fit); ``setting``: the class's
    :class:`harness.stages.classes.base.Setting`; ``first_res``: base's statics, when the
    stage has them (the rule's validation scores and its row reuse them); ``rules``:
    (row, network, statics) of every solved rule, which the validation loads rank
    (harness/stages/sms_accept.py): the fit is exported only when it beats all of them
    there, else the rule they rank first."""
    _check_method(setting.case, run_)
    t0 = time.perf_counter()
    s, cands, counts = _selection(setting, run_, base, first_res, len(rules))
    seconds = time.perf_counter() - t0
    pd.DataFrame(list(s.table)).to_csv(setting.ctx.file("validation.csv"), index=False)
    scored = _scored_starts(setting, base, s, first_res)
    fit = setting.validated(*scored[0][:2]).get("G_val_mean", math.nan)
    verdict = accept.judge(
        fit if s.choice != "rule" else math.nan,
        {r["stiffness"]: r.get("G_val_mean", math.nan) for r, _, _ in rules},
    )
    start, folds_chose = first["stiffness"], s.choice
    if verdict.best is not None and not verdict.accepted:
        first, s, scored = _rule_export(
            setting, s, next(t for t in rules if t[0]["stiffness"] == verdict.best)
        )
    net, res, sc, sh = scored[0]
    tag = f"{base.info['stiffness']}-select"
    setting.write(net, res, tag)
    row = _row(setting, first, base, s, cands, scored, seconds)
    row.update(fit_counts(counts))
    row.update(verdict.columns, start_rule=start, val_fold_choice=folds_chose)
    row.update(setting.validated(net, res))
    return row, net, None


def fit_counts(counts) -> dict:
    """The row's record of the counts the validated fit ran (harness/optimize/select_counts.py
    RECORDED, as fit_<key> columns; the candidates space-separated)."""
    out = {f"fit_{key}": getattr(counts, key) for key in select_counts.RECORDED}
    out["fit_candidates"] = " ".join(counts.candidates)
    return out


def _rule_export(setting, s, rule) -> tuple:
    """(the rule's row, the Selection and scored starts of exporting rule ``rule``, a
    (row, network, statics) of the stage's rule rows): its own constants, one 'start'."""
    row, net, res = rule
    return (
        row,
        dataclasses.replace(s, choice="rule", starts=(net.k,), stops=()),
        [(net, *setting.evaluate(net, res))],
    )


def _check_method(case, run_) -> None:
    """The validated fit fits by L-BFGS-B: another method is the case's mistake."""
    if run_["method"] != "lbfgs":
        raise CaseError(
            f"[optimizer.select] fits by lbfgs, not {run_['method']}",
            file=str(case.path) if case.path else None,
            field="optimizer.method",
            fix="method = 'lbfgs'",
        )


def _volume_terms(base, cands, kv0):
    """The volume terms some candidate needs, their columns after the springs: (terms,
    {volume: (first column, end)})."""
    terms, volumes, at = ([], {}, base.n_springs)
    for on in dict.fromkeys(c.volume for c in cands if c.volume):
        terms.append(with_volume(base, on, kv0).volume)
        volumes[on] = (at, at + terms[-1].n_elements)
        at += terms[-1].n_elements
    return terms, volumes


def _problem(setting, base, terms) -> FitProblem:
    """The fit on the fitted loads of the columns [springs | every candidate's volume terms]."""
    fit = setting.fit
    _, free, forces = statics.all_load_arrays(base, setting.case)
    wdof = np.repeat(node_weights(base.classes, setting.weights), base.dim)
    return FitProblem.from_network(
        base.points,
        base.springs,
        np.concatenate([base.k] + [t.kv for t in terms]),
        free[fit],
        forces[fit],
        setting.u_ref[fit].reshape(len(fit), -1),
        wdof,
        [setting.names[i] for i in fit],
        extra_columns=sp.hstack([t.columns(base.points) for t in terms]).tocsc() if terms else None,
    )


def _selection(setting, run_, base, first_res, n_rules: int = 0):
    """(harness/optimize/select.py's Selection, the candidates it chose among, the counts it
    ran: harness/optimize/select_counts.py's level for this network and ``n_rules`` solved
    rules): validation fits stopped by ``[optimizer.select] maxiter``, the final fit by the
    case's maxiter, either lowered on a large network."""
    spec = run_["select"]
    kv0 = initial_kv(setting.case.material, setting.case.dim)
    cands = [c for c in sel.CANDIDATES if c.name in spec["candidates"]]
    terms, volumes = _volume_terms(base, cands, kv0)
    problem = _problem(setting, base, terms)
    fit_names = [setting.names[i] for i in setting.fit]
    fams = families(setting.case, fit_names)
    # the fits stop by their counts; the budget caps the whole validated fit (it aborts)
    opts = {k: v for k, v in run_["options"].items() if k != "max_seconds"}
    counts = select_counts.choose(
        problem,
        fams,
        n_rules,
        [c.name for c in cands],
        int(spec["maxiter"]),
        int(spec["starts"]),
        int(opts.get("maxiter") or FINAL_MAXITER),
        fixed=spec.get("work", "budget") == "fixed",
    )
    cands = [c for c in sel.CANDIDATES if c.name in counts.candidates]
    rule_scores = None
    if first_res is not None:
        _, sc0, _ = setting.evaluate(base, first_res)
        rule_scores = [sc0.per_load_norm[n] for n in fit_names]
    d, L = spring_directions(base.points, base.springs)
    s = sel.select(
        problem,
        base.n_springs,
        fams,
        kv0,
        direction_groups(d, L),
        cands,
        {**opts, "maxiter": counts.maxiter},
        {**opts, "maxiter": counts.final_maxiter},
        counts.starts,
        int(base.info["seed"]),
        setting.ctx.status,
        features=geometry(base.points, base.springs, base.cells)
        if any(c.groups == "features" for c in cands)
        else None,
        rule_scores=rule_scores,
        volumes=volumes,
        criterion=spec["criterion"],
        max_seconds=run_["options"].get("max_seconds"),
        folds=counts.folds,
        shared_final=counts.shared_final,
    )
    return s, cands, counts


def _scored_starts(setting, base, s, first_res) -> list:
    """(network, statics, score, held-out score) of each start of the final fit, the
    exported one first (the rule's own constants reuse ``first_res``)."""
    stiffness = f"{base.info['stiffness']}+select"
    scored = []
    for k in s.starts:
        net = base.with_k(k[: base.n_springs], stiffness=stiffness)
        net = with_volume(net, s.volume, k[base.n_springs :]) if s.volume else net
        same = first_res is not None and s.choice == "rule"
        scored.append((net, *setting.evaluate(net, first_res if same else None)))
    return scored


def _row(setting, first, base, s, cands, scored, seconds) -> dict:
    """The validated fit's row (module doc) from its exported start, ``scored[0]``."""
    net, _, sc, sh = scored[0]
    means = [heldout_columns(h).get("G_heldout_mean", math.nan) for _, _, _, h in scored]
    columns = setting.fit_columns(
        first,
        first["stiffness"],
        "lbfgs",
        sc,
        seconds=seconds,
        # the wall time's split: reported, never used for a choice
        seconds_validation=s.seconds.get("validation", math.nan),
        seconds_final=s.seconds.get("final", math.nan),
        objective="G",
        n_params=int(len(s.k)),
    )
    chosen = {
        "choice": s.choice,
        "val_families": " ".join(s.families),
        "n_starts": len(s.starts),
        "val_skipped": math.nan,  # the validation always runs (module doc)
        # a spread needs two starts (one start: NaN, no tie band)
        "G_heldout_mean_spread": float(np.nanmax(means) - np.nanmin(means))
        if sh is not None and len(means) > 1
        else math.nan,
    }
    row = columns.row(
        setting.common, scored=scored_columns(setting.case, sc, sh, first), chosen=chosen
    )
    row.update(
        _tag=f"{base.info['stiffness']}-select",
        _validation=tuple(s.table),
        opt_prior=next((c.prior for c in cands if c.name == s.choice), math.nan),
    )
    row.update({f"val_{r['model']}": r["score"] for r in s.table})
    if s.stops:  # the exported start's stop, and every start's (" | " between them)
        row.update(opt_stop=s.stops[0], opt_stops=" | ".join(s.stops))
    if s.volume:
        row.update(volume=s.volume, n_volumes=net.volume.n_elements)
    return row


def direction_groups(directions: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """(e,) group ids: the axis a spring points along most (|n_a| largest) times its
    length tercile: 9 groups in 3-D, 6 in 2-D (empty ones renumbered away)."""
    axis = np.argmax(np.abs(directions), axis=1)
    cuts = np.quantile(lengths, [1 / 3, 2 / 3])
    tercile = np.searchsorted(cuts, lengths, side="right")
    _, ids = np.unique(axis * 3 + tercile, return_inverse=True)
    return ids
