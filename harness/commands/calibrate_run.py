"""One calibration: the stage run on the in-memory calibrate case, the exported row and its
network (with its volume or kn term) taken from the stage's result, the optional cap on
the constants' spread, and the plain linear tetrahedra with the user's (E, nu) on the mesh
(your engine's own body at this mesh): a row to compare with, never a candidate."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

import reference
from harness import registry
from harness.commands.calibrate_case import mesh_case
from harness.commands.calibrate_progress import tracker
from harness.export.engine import spring_damping, stable_step
from harness.mechanics import statics
from harness.models.p1 import with_p1
from harness.progress import Clock
from harness.scoring import case_weights, fit_and_heldout, ref_status, reference_displacements
from harness.stages import StageContext
from harness.stages import sms as stage
from harness.stages.sms_measures import engine_columns, fit_score, validation_rank


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
    if has_tets_row(s, net):  # after every choice: never a candidate, never exported
        at = max((i for i, r in enumerate(rows) if r.get("optimizer") == "none"), default=-1)
        scored = next((r for r in rows if "status" in r), rows[0])  # a scored stage row
        rows.insert(at + 1, {**plain_tets_row(net, case, scored), "exported": False})
    return rows, net, case


# the columns a capped row keeps from the row it caps
KEPT = ("model", "stiffness", "n_nodes", "n_springs", "seed", "G_ref", "G_ref_heldout")
KEPT += ("ref_error_max", "ref_error_heldout")


# the plain tetrahedra's row: its labels (its optimizer is no rule's "none", so no choice
# over the rule rows, the verdict's, the export's or a bench's, ever takes it)
TETS = dict(model="tets[E, nu]", stiffness="p1", optimizer="not-a-candidate")


def tets_row(rows) -> dict | None:
    """The plain tetrahedra's row among ``rows`` (None: calibrate made none)."""
    return next((r for r in rows if r.get("model") == TETS["model"]), None)


def has_tets_row(s, net) -> bool:
    """Whether calibrate adds the plain tetrahedra's row: a springs calibration (with
    --model p1-global or p1 the rule row "p1" is that row already) on a mesh of
    tetrahedra (2-D: triangles) alone."""
    simplex = "tetra" if net.dim == 3 else "triangle"
    return s.model in registry.SPRINGS_CLASSES and set(dict(net.cells or {})) == {simplex}


def plain_tets_row(net, case, row) -> dict:
    """Linear tetrahedra (2-D: triangles) on the mesh's own cells with the case's material
    and ``net``'s nodes and masses (harness/models/p1.py), scored as the stage scores every
    row: on the fitted loads the stage kept (``row``'s ``training_dropped`` left out) and on
    the held-out ones, the reference's columns and status taken from the rule row ``row``
    (the same nodes, loads and weights)."""
    p1 = with_p1(net, case.material)
    dropped = str(row.get("training_dropped") or "").split()
    fit = [n for n in case.fit_loads if n not in dropped]
    kept = tuple(load for load in case.loads if load.name not in dropped)
    out = {
        c: v for c, v in row.items() if c in KEPT + ("ref_met_tol", "ref_note", "training_dropped")
    }
    out.update(TETS)
    ref = reference.solve(case)  # cached by the stage's solve
    res = statics.solve(p1, case)
    u_ref = reference_displacements(ref, p1.points, res.names)
    weights = case_weights(case)
    sc, sh = fit_and_heldout(u_ref, res.u, p1.classes, weights, res.names, fit, case.heldout)
    out.update(
        G_initial=sc.G,
        G_final=sc.G,
        G_norm_initial=sc.G_norm,
        G_norm_final=sc.G_norm,
        **fit_score(dataclasses.replace(case, loads=kept) if dropped else case, sc),
    )
    out.update(_heldout_columns(sh), **_status(row, sc, sh))
    out["dt_stable"] = engine_columns(p1, p1=True)["dt_stable"]  # the tets' own explicit step
    return out


def _heldout_columns(sh) -> dict:
    """G_heldout, G_heldout_mean and G_heldout_<load> of the held-out score (none: {})."""
    if sh is None:
        return {}
    per = {f"G_heldout_{name}": float(v) for name, v in sh.per_load_norm.items()}
    return dict(G_heldout=sh.G_norm, G_heldout_mean=float(np.mean(list(per.values()))), **per)


def _status(row, sc, sh) -> dict:
    """``status`` of a row scored ``sc`` (fitted) and ``sh`` (held-out) against the
    reference columns of ``row`` (harness/stages/sms_rows.py add_ref_columns); {} when
    ``row`` has none."""
    if "status" not in row:
        return {}
    status = ref_status(row.get("G_ref", math.nan), sc.G_norm, row.get("ref_met_tol"))
    held = None if sh is None else ref_status(row.get("G_ref_heldout", math.nan), sh.G_norm, None)
    return {"status": "ref-coarse" if held not in (None, "ok") else status}


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
    out.update(_heldout_columns(sh), **_status(row, sc, sh))
    if np.all(net.masses > 0):
        for r, n in ((row, net), (out, capped)):
            kd = spring_damping(n.springs, n.k, n.masses, zeta)
            r["dt_stable"] = stable_step(
                n.points, n.springs, n.k, n.masses, kd, volume=getattr(n, "volume", None)
            )["dt_stable"]
    row["k_ratio"] = float(k.max() / np.median(k))
    return out
