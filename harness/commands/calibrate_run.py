"""One calibration: the stage run on the in-memory calibrate case, the exported row and its
network (with its volume or kn term) taken from the stage's result, and the optional cap on
the constants' spread."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

import reference
from harness.commands.calibrate_case import mesh_case
from harness.commands.calibrate_progress import tracker
from harness.export.engine import spring_damping, stable_step
from harness.mechanics import statics
from harness.progress import Clock
from harness.scoring import case_weights, fit_and_heldout, ref_status, reference_displacements
from harness.stages import StageContext
from harness.stages import sms as stage
from harness.stages.sms_measures import validation_rank


def run(s, mesh, tmp: Path, spent: dict | None = None):
    """(rows, the exported network, the case) of one calibration (settings ``s``; a mesh in
    other units than m is handed over as a file in tmp); the exported row carries its
    held-out displacements as ``_heldout`` (:class:`harness.stages.sms.Heldout` or None).
    ``spent`` gets the wall seconds of the stage's phases (calibrate_progress.tracker)."""
    case = mesh_case(s, mesh, tmp)
    clock = Clock("calibrate")  # on a terminal only (and not with --quiet)
    status = tracker(clock, spent=spent)
    try:
        ctx = StageContext(out_dir=tmp / "out", seed=s.seed, status=status)
        result = stage.models(case, ctx)
    finally:
        status.stop()
        clock.close()
    rows = list(result.rows)
    if s.method == "rule":
        at = rows.index(min(rows, key=validation_rank)) if s.rule == "best" else 0
    else:
        at = len(rows) - 1
    exported, net, heldout = rows[at], result.networks[at], result.heldout[at]
    if result.validations[at]:  # the validated fit's table (harness/stages/sms_select.py)
        exported["_validation"] = [dict(r) for r in result.validations[at]]
    if s.k_ratio is not None:
        capped = capped_row(net, case, exported, s.k_ratio, s.damping_ratio)
        rows.append(capped)
        net, exported, heldout = capped.pop("_net"), capped, capped.pop("_heldout")
    exported["_heldout"] = heldout  # the picture of the fit (calibrate_picture.py)
    for r in rows:
        r["exported"] = r is exported
    return rows, net, case


# the columns a capped row keeps from the row it caps
KEPT = ("model", "stiffness", "n_nodes", "n_springs", "seed", "G_ref", "G_ref_heldout")
KEPT += ("ref_error_max", "ref_error_heldout")


def capped_row(net, case, row, ratio: float, zeta: float) -> dict:
    """The exported constants capped at ratio x their median, scored like the stage does
    (fitted and held-out loads), with the stable step of both (what the cap gains) and the
    held-out displacements (``_heldout``)."""

    k = np.asarray(net.k, float)
    capped = net.with_k(np.minimum(k, ratio * np.median(k)))
    ref = reference.solve(case)  # cached by the stage's solve
    res = statics.solve(capped, case)
    u_ref = reference_displacements(ref, capped.points, res.names)
    sc, sh = fit_and_heldout(
        u_ref, res.u, capped.classes, case_weights(case), res.names, case.fit_loads, case.heldout
    )
    out = {c: v for c, v in row.items() if c in KEPT}
    out.update(
        optimizer=f"{row.get('optimizer', 'none')}+k-ratio {ratio:g}",
        G_norm_initial=row.get("G_norm_final"),
        G_norm_final=sc.G_norm,
        G_heldout=sh.G_norm if sh else math.nan,
        k_ratio=float(capped.k.max() / np.median(capped.k)),
        _net=capped,
        _heldout=None,
    )
    if case.heldout:
        at = [res.names.index(n) for n in case.heldout]
        out["_heldout"] = stage.Heldout(tuple(case.heldout), u_ref[at], res.u[at])
    if sh is not None:
        per = {f"G_heldout_{name}": float(v) for name, v in sh.per_load_norm.items()}
        out.update(G_heldout_mean=float(np.mean(list(per.values()))), **per)
    if "status" in row:  # the reference's error against the capped constants' (ref_status)
        out["status"] = ref_status(row.get("G_ref", math.nan), sc.G_norm, row.get("ref_met_tol"))
        held = (
            None if sh is None else ref_status(row.get("G_ref_heldout", math.nan), sh.G_norm, None)
        )
        if held not in (None, "ok"):
            out["status"] = "ref-coarse"
    if np.all(net.masses > 0):
        for r, n in ((row, net), (out, capped)):
            kd = spring_damping(n.springs, n.k, n.masses, zeta)
            r["dt_stable"] = stable_step(
                n.points, n.springs, n.k, n.masses, kd, volume=getattr(n, "volume", None)
            )["dt_stable"]
    row["k_ratio"] = float(k.max() / np.median(k))
    return out
