"""The sms stage's validated fit (``[optimizer.select]``): the capacity of the fit chosen by
leave-one-family-out validation on the fitted loads (harness/optimize/select.py), the
rule when nothing beats it, the final fit from several starts.

The row is the stage's optimised row with, besides, ``choice`` (the rule, or the
candidate chosen), ``val_<model>`` (each model's validation score), ``val_families``,
``n_starts``, ``val_skipped`` (NaN when the validation ran; else the budget in seconds
that would let it run: on large meshes its fits cannot take enough steps within
VALIDATION_BUDGET x the budget, and the rule is the choice) and ``G_heldout_mean_spread``
(max - min of G_heldout_mean over the final fit's starts: differences inside it are
ties, not rankings). The validation table is
``validation.csv`` (one row per model, one column per left-out family and the score).
"""

from __future__ import annotations

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
from harness.optimize.problem import FitProblem
from harness.scoring import node_weights

VALIDATION_BUDGET = 2.0  # the validation fits together: at most this many times the fit's budget


def optimise(setting, run_, base, first, first_res=None):
    """(row, network, trace) of the validated fit of ``base``, a springs-only network (the
    stage gives the other model classes their plain fit); ``setting``: the class's
    :class:`harness.stages.classes.base.Setting`; ``first_res``: base's statics, when the
    stage has them (a validation they show unaffordable then costs no solve, and the
    rule's row reuses them)."""
    from harness.stages.sms_measures import families, fit_score, heldout_columns, per_load_columns

    case, ctx, u_ref, names, fit, weights = (
        setting.case,
        setting.ctx,
        setting.u_ref,
        setting.names,
        setting.fit,
        setting.weights,
    )
    label, common, evaluate, write = setting.label, setting.common, setting.evaluate, setting.write
    spec = run_["select"]
    if run_["method"] != "lbfgs":
        raise CaseError(
            f"[optimizer.select] fits by lbfgs, not {run_['method']}",
            file=str(case.path) if case.path else None,
            field="optimizer.method",
            fix="method = 'lbfgs'",
        )
    t0 = time.perf_counter()
    kv0 = initial_kv(case.material, case.dim)
    cands = [c for c in sel.CANDIDATES if c.name in spec["candidates"]]
    # the volume terms some candidate needs, after the springs
    terms, volumes, at = ([], {}, base.n_springs)
    for on in dict.fromkeys(c.volume for c in cands if c.volume):
        terms.append(with_volume(base, on, kv0).volume)
        volumes[on] = (at, at + terms[-1].n_elements)
        at += terms[-1].n_elements
    _, free, forces = statics.all_load_arrays(base, case)
    fit_names = [names[i] for i in fit]
    wdof = np.repeat(node_weights(base.classes, weights), base.dim)
    problem = FitProblem.from_network(
        base.points,
        base.springs,
        np.concatenate([base.k] + [t.kv for t in terms]),
        free[fit],
        forces[fit],
        u_ref[fit].reshape(len(fit), -1),
        wdof,
        fit_names,
        extra_columns=sp.hstack([t.columns(base.points) for t in terms]).tocsc() if terms else None,
    )
    d, L = spring_directions(base.points, base.springs)
    fams = families(case, fit_names)
    budget = run_["options"].get("max_seconds")
    # validation fits stop at maxiter (so on small meshes the choice does not depend on the
    # machine's speed) or at their share of VALIDATION_BUDGET x the budget (large meshes)
    n_fits = len(cands) * len(sel.make_folds(fams))
    val = {
        **run_["options"],
        "maxiter": int(spec["maxiter"]),
        "max_seconds": None if budget is None else VALIDATION_BUDGET * budget / max(n_fits, 1),
    }
    final = {
        **run_["options"],
        "max_seconds": None if budget is None else budget / int(spec["starts"]),
    }
    rule_solve = None
    if first_res is not None:
        _, sc0, _ = evaluate(base, first_res)
        at = {n: i for i, n in enumerate(first_res.names)}
        rule_solve = (
            [sc0.per_load_norm[n] for n in fit_names],
            float(sum(first_res.load_seconds[at[n]] for n in fit_names)),
        )
    s = sel.select(
        problem,
        base.n_springs,
        fams,
        kv0,
        sel.direction_groups(d, L),
        cands,
        val,
        final,
        int(spec["starts"]),
        int(base.info["seed"]),
        ctx.status,
        features=geometry(base.points, base.springs, base.cells)
        if any(c.groups == "features" for c in cands)
        else None,
        rule_solve=rule_solve,
        volumes=volumes,
        criterion=spec["criterion"],
    )
    seconds = time.perf_counter() - t0
    pd.DataFrame(list(s.table)).to_csv(ctx.file("validation.csv"), index=False)

    def network(k):
        net = base.with_k(k[: base.n_springs], stiffness=f"{base.info['stiffness']}+select")
        return with_volume(net, s.volume, k[base.n_springs :]) if s.volume else net

    scored = []
    for k in s.starts:
        net = network(k)
        # the rule's own constants: solved already
        same = first_res is not None and s.choice == "rule"
        scored.append((net, *evaluate(net, first_res if same else None)))
    net, res, sc, sh = scored[0]
    stiff = base.info["stiffness"]
    tag = f"{stiff}-select"
    write(net, res, tag)
    means = [heldout_columns(h).get("G_heldout_mean", math.nan) for _, _, _, h in scored]
    row = {
        **common,
        "model": f"{label}[{stiff}]",
        "stiffness": stiff,
        "optimizer": "lbfgs",
        "seconds": seconds,
        "G_initial": first["G_initial"],
        "G_norm_initial": first["G_norm_initial"],
        "G_s_initial": first.get("G_s_initial", math.nan),
        "G_final": sc.G,
        "G_norm_final": sc.G_norm,
        "G_s_final": sc.G_s,
        **per_load_columns(sc, sh),
        **fit_score(case, sc),
        **heldout_columns(sh, first),
        "objective": "G",
        "choice": s.choice,
        "val_families": " ".join(s.families),
        "n_starts": len(s.starts),
        "val_skipped": s.skipped / VALIDATION_BUDGET if s.skipped else math.nan,
        "G_heldout_mean_spread": float(np.nanmax(means) - np.nanmin(means))
        if sh is not None
        else math.nan,
        "n_params": int(len(s.k)),
        "_tag": tag,
        "opt_prior": next((c.prior for c in cands if c.name == s.choice), math.nan),
    }
    row.update({f"val_{r['model']}": r["score"] for r in s.table})
    if s.stops:  # the exported start's stop, and every start's (" | " between them)
        row.update(opt_stop=s.stops[0], opt_stops=" | ".join(s.stops))
    if s.volume:
        row.update(volume=s.volume, n_volumes=net.volume.n_elements)
    return row, net, None
