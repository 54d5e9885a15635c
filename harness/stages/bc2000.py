"""Stage "bc2000": the experiments of Bourguignon & Cani 2000 on the original meshes.

``[dynamics] experiment`` picks one (functions registered in ``harness.registry.EXPERIMENTS``):
- ``volume`` (Fig. 3): MS, MT0, MT under gravity; writes ``volume.csv`` (t, MS, MT0, MT in
  percent); rows: peak and final |dV/V|, and the deviation from the original program's
  curve when ``[dynamics] original`` names its file (relative to the case).
- ``pull`` (Fig. 1a / 5a): pulled bottom nodes; elongation and lateral drift per mesh/model.
- ``cantilever`` (Fig. 1c / 5c): tip deflection at the end of the run, the static
  equilibrium (Newton, continuation past limit points, one-line status) and, with [loads],
  the linearised model against the FEM reference (small strain).
- ``fibres`` (Fig. 6): one run per ``[model] fibre_fields``; elongation, thinning, twist,
  drift; ``fibres-<field>.npz`` (+ ``fibres.npz`` of the first field) for the figure.
- ``timing`` (Table 1): wall time per simulated second of every mesh x model, the model/MS
  ratio beside the paper's.
- ``fem``: static G of MS / MT0 / MT against the FEM reference (isotropic or with the
  material's fibre), calibration, and the undesired anisotropy of direction pulls.
- ``run``: plain runs with the per-step volume.
"""

from __future__ import annotations

import time

import numpy as np
import pandas as pd

from harness import registry
from harness.case import schema
from harness.case.parts import classify_nodes
from harness.case.sections import DYNAMICS
from harness.errors import CaseError, SimulationError
from harness.mechanics.dynamics import simulate, stiffness
from harness.mechanics.static_path import solve_static_path
from harness.models.anisotropic import frame
from harness.models.masses import sub_tet_volumes
from harness.scoring import case_weights, g_arrays, ref_columns, ref_status, reference_displacements
from harness.stages.bc2000_build import (  # noqa: F401
    _cells,
    _dt,
    _label,
    _meshes,
    build,
    fibre_angles,
    loading,
    lumped_masses,
)

NAME = "bc2000"
PAPER_RATIO = {"tetra": 14.5, "hexa": 3.6}  # Table 1: model time / MS time


def applies(case) -> bool:
    m = case.section("model")
    return m is not None and m.get("kind") == "bc2000"


def run(case, ctx) -> list[dict]:
    model = dict(case.section("model"))
    dyn = dict(case.section("dynamics") or {})
    if not dyn:
        dyn = schema.check({}, DYNAMICS, str(case.path), "dynamics.")
    exp = dyn["experiment"]
    return registry.EXPERIMENTS.load(exp)(case, ctx, model, dyn)


def _steps(dyn, dt) -> int:
    return int(round(dyn["duration"] / dt)) if dyn["duration"] is not None else dyn["steps"]


def _simulate(case, ctx, model, dyn, mesh, name, field=None, **kw):
    dt = _dt(dyn, mesh, name)
    m = build(name, model, mesh, dt, field)
    ld = loading(model, dyn, mesh, dt)
    steps = _steps(dyn, dt)
    ctx.status(f"{name} {steps} steps")
    t0 = time.perf_counter()
    try:
        tr = simulate(m, ld, dt, steps, integrator=dyn["integrator"], **kw)
    except SimulationError as exc:  # a blow-up: the case's time step is the field to change
        fld = "dynamics.hexa_model_dt" if dt != dyn["dt"] else "dynamics.dt"
        raise SimulationError(
            f"{name}: {exc.message}", file=str(case.path), field=fld, fix=exc.fix
        ) from None
    return m, ld, tr, time.perf_counter() - t0


def volume(case, ctx, model, dyn):
    rows, curves = [], {}
    path, mesh = _meshes(case, dyn)[0]
    ref = None
    if dyn["original"]:
        f = (case.path.parent / dyn["original"]).resolve()
        try:
            ref = np.loadtxt(f, skiprows=1)
        except (OSError, ValueError) as exc:
            raise CaseError(
                f"cannot read the original curve ({exc})",
                file=str(case.path),
                field="dynamics.original",
                fix="give a whitespace table with a header line",
            )
    for i, name in enumerate(model["models"]):
        m, ld, tr, sec = _simulate(case, ctx, model, dyn, mesh, name)
        dv = tr.volume_change_percent()
        curves[name] = dv
        row = {
            "model": name,
            "mesh": _label(path, mesh),
            "steps": len(dv) - 1,
            "peak_abs_dV_percent": float(np.abs(dv).max()),
            "final_dV_percent": float(dv[-1]),
            "run_seconds": sec,
        }
        if ref is not None and name in ("MS", "MT0", "MT"):
            col = ("MS", "MT0", "MT").index(name) + 1 if ref.shape[1] == 4 else 2
            k = min(len(ref), len(dv) - 1)
            row["max_dev_vs_original_percent"] = float(np.abs(dv[1 : k + 1] - ref[:k, col]).max())
        rows.append(row)
    t = dyn["dt"] * np.arange(len(next(iter(curves.values()))))
    pd.DataFrame({"t": t, **curves}).to_csv(ctx.file("volume.csv"), index=False)
    return rows


def _pulled(mesh):
    sel = mesh.flags == 2
    if not sel.any():
        sel = mesh.points[:, 1] <= mesh.points[:, 1].min() + 1e-9
    return np.flatnonzero(sel)


def _pulled_measures(mesh, tr):
    """Elongation (mean y displacement of the pulled nodes) and lateral drift (norm of
    their mean x, z displacement), both averaged over the second half of the run (lateral
    modes are barely damped and still swing), and drift / |elongation|."""
    sel = _pulled(mesh)
    u = (tr.observed - mesh.points[sel]).mean(axis=1)  # (steps + 1, 3)
    u = u[len(u) // 2 :].mean(axis=0)
    drift = float(np.hypot(u[0], u[2]))
    return {
        "elongation": float(u[1]),
        "lateral_drift": drift,
        "drift_ratio": drift / max(abs(float(u[1])), 1e-300),
    }


def pull(case, ctx, model, dyn):
    rows = []
    for path, mesh in _meshes(case, dyn):
        for name in model["models"]:
            m, ld, tr, sec = _simulate(case, ctx, model, dyn, mesh, name, observe=_pulled(mesh))
            rows.append(
                {
                    "model": name,
                    "mesh": _label(path, mesh),
                    "steps": len(tr.t) - 1,
                    **_pulled_measures(mesh, tr),
                    "run_seconds": sec,
                }
            )
    return rows


def _load_direction(case, load) -> np.ndarray:
    """Unit vector of a load's gravity, else of its first traction, else of its body force."""
    v = (
        load.gravity
        if load.gravity is not None
        else (load.tractions[0].vector if load.tractions else load.body_force)
    )
    n = 0.0 if v is None else float(np.linalg.norm(v))
    if not n > 0:
        raise CaseError(
            f"load '{load.name}' has no force: the tip ratio needs a direction",
            file=str(case.path),
            field="loads.case",
            fix="give it a non-zero gravity, traction or body_force",
        )
    return np.asarray(v, float) / n


COMPARISON = (
    "linear (small strain): the model linearised at rest vs linear FEM, same clamp, "
    "gravity, density (consistent nodal masses), E, nu"
)


def _fem_comparison(case, ref, mesh, m, tip) -> dict:
    """Columns comparing the linearised model with the FEM reference under the case's
    loads: per load the mean tip displacement along the load (model, FEM, ratio); the
    gravity load is ``tip_deflection_linear / _fem / tip_ratio``; ``flexion_ratio`` =
    tip_ratio / stretch ratio (1: the model bends as stiffly as its stretching implies;
    > 1: too soft in bending); G of the gravity field, raw and after the best single
    scale (the shape error alone), with ``G_ref`` / ``ref_error_max`` of that load and a
    "ref-coarse" status when G_ref exceeds 10 % of the scaled G or the reference missed
    its tol."""
    from harness.stages import bc2000_linear as linear

    P = mesh.points
    masses = lumped_masses(P, _cells(mesh), case.material.density)
    loads = linear.case_loads(P, case, masses)
    u = linear.solve(stiffness(m), loads)
    u_ref = reference_displacements(ref, P, loads.names)
    out = {
        "comparison": COMPARISON,
        "ref_error_estimate": float(max(ref.error_estimate.values())),
        "ref_n_dofs": int(ref.n_dofs),
    }
    ratios = {}
    for i, load in enumerate(case.loads):
        d = _load_direction(case, load)
        um, uf = float((u[i][tip] @ d).mean()), float((u_ref[i][tip] @ d).mean())
        ratios[load.name] = um / uf
        if load.gravity is not None and "tip_ratio" not in out:
            out.update(
                {
                    "tip_deflection_linear": float(u[i][tip, 1].mean()),
                    "tip_deflection_fem": float(u_ref[i][tip, 1].mean()),
                    "tip_ratio": um / uf,
                    "E_bending": case.material.E / (um / uf),
                }
            )
            classes = classify_nodes(P, case.body.bbox())
            w = np.asarray(case_weights(case))[classes]
            c = float(
                np.einsum("p,pd,pd->", w, u_ref[i], u[i]) / np.einsum("p,pd,pd->", w, u[i], u[i])
            )
            s_raw = g_arrays(u_ref[i : i + 1], u[i : i + 1], classes, case_weights(case))
            s_fit = g_arrays(u_ref[i : i + 1], c * u[i : i + 1], classes, case_weights(case))
            out.update({"G_norm_gravity": s_raw.G_norm, "G_norm_gravity_scaled": s_fit.G_norm})
            # the reference's own error as G of the same load and nodes, against the smaller
            # (shape-only) G: a scaled G near the FEM's error is flagged
            out.update(
                ref_columns(ref, P, [loads.names[i]], u_ref[i : i + 1], classes, case_weights(case))
            )
            out["status"] = ref_status(out["G_ref"], s_fit.G_norm, out.get("ref_met_tol"))
        else:
            out[f"tip_{load.name}_ratio"] = um / uf
    if "tip_ratio" in out and "stretch" in ratios:
        out["E_stretch"] = case.material.E / ratios["stretch"]
        out["flexion_ratio"] = out["tip_ratio"] / ratios["stretch"]
    return out


def inverted_elements(model, x) -> int:
    """Elements with a sub-tetrahedron of negative signed volume at x (turned inside out)."""
    cells = np.asarray(model.cells)
    flipped = np.sign(sub_tet_volumes(x, cells)) != np.sign(sub_tet_volumes(model.points, cells))
    return int(flipped.any(axis=1).sum())


def _static_columns(m, ld, tip, points, arc_steps: int = 150) -> dict:
    """The nonlinear static equilibrium under the program's load (Newton, load stepping,
    continuation past limit points) beside the linearised response to the same load."""
    import scipy.sparse.linalg as spla

    free = np.repeat(~ld.fixed, 3)
    K = stiffness(m).tocsr()[free][:, free]
    u = np.zeros(3 * len(points))
    u[free] = spla.spsolve(K.tocsc(), ld.external().ravel()[free])
    lin = float(u.reshape(-1, 3)[tip, 1].mean())
    res = solve_static_path(m, ld, load_steps=10, arc_steps=arc_steps)
    row = {
        "tip_deflection_linear_program_load": lin,
        "static_status": res.status,
        "static_load_factor": res.load_factor,
    }
    if res.x is not None:
        st = float((res.x - points)[tip, 1].mean())
        row.update(
            {
                "tip_deflection_static": st,
                "static_nonlinearity": st / lin,
                "static_inverted_elements": inverted_elements(m, res.x),
            }
        )
    if res.x_limit is not None:  # what the model looks like where it loses stability
        row.update(
            {
                "limit_load_factor": res.folds[0],
                "limit_tip_deflection": float((res.x_limit - points)[tip, 1].mean()),
                "limit_inverted_elements": inverted_elements(m, res.x_limit),
            }
        )
        if row["limit_inverted_elements"]:
            row["static_status"] += (
                f"; {row['limit_inverted_elements']} elements inside out at the limit point"
            )
    return row


def cantilever(case, ctx, model, dyn):
    """Tip deflection (mean y displacement of the nodes at the far end z = max), averaged
    over the second half of the run, its swing there, and the static equilibrium; with
    [loads] in the case, the linearised model against the FEM reference
    (:func:`_fem_comparison`)."""
    rows = []
    ref = None
    if case.loads:
        for load in case.loads:  # mistakes before the solves
            _load_direction(case, load)
        from reference import solve as reference_solve

        ctx.status("FEM reference")
        ref = reference_solve(case)
    for path, mesh in _meshes(case, dyn):
        tip = np.flatnonzero(mesh.points[:, 2] >= mesh.points[:, 2].max() - 1e-9)
        for name in model["models"]:
            m, ld, tr, sec = _simulate(case, ctx, model, dyn, mesh, name, observe=tip)
            u = (tr.observed[:, :, 1] - mesh.points[tip, 1]).mean(axis=1)
            late = u[len(u) // 2 :]
            row = {
                "model": name,
                "mesh": _label(path, mesh),
                "steps": len(tr.t) - 1,
                "tip_deflection": float(late.mean()),
                "tip_swing": float(np.ptp(late)),
                "tip_deflection_max": float(u.min()),
                "run_seconds": sec,
            }
            if dyn["static"]:
                ctx.status(f"{name} statics")
                row.update(_static_columns(m, ld, tip, mesh.points))
            if ref is not None:
                ctx.status(f"{name} vs FEM")
                row.update(_fem_comparison(case, ref, mesh, m, tip))
            rows.append(row)
    return rows


def _twist_thinning(mesh, x):
    """Twist (degrees, about y through the pulled nodes' centroid) of the pulled nodes and
    thinning = mean distance from the vertical centre line at mid height, deformed / rest."""
    P = mesh.points
    sel = mesh.flags == 2
    if not sel.any():
        sel = P[:, 1] <= P[:, 1].min() + 1e-9
    c0, c1 = P[sel].mean(axis=0), x[sel].mean(axis=0)
    r0, r1 = P[sel] - c0, x[sel] - c1
    ang = np.arctan2(r0[:, 2], r0[:, 0]) - np.arctan2(r1[:, 2], r1[:, 0])
    ang = (ang + np.pi) % (2 * np.pi) - np.pi
    ymid = np.median(np.unique(P[:, 1]))
    mid = np.abs(P[:, 1] - ymid) < 1e-9
    if not mid.any():
        mid = np.ones(len(P), bool)
    w0 = np.hypot(*(P[mid] - P[mid].mean(0))[:, [0, 2]].T).mean()
    w1 = np.hypot(*(x[mid] - x[mid].mean(0))[:, [0, 2]].T).mean()
    return float(np.degrees(np.mean(ang))), float(w1 / w0)


def fibres(case, ctx, model, dyn):
    rows = []
    path, mesh = _meshes(case, dyn)[0]
    fields = model["fibre_fields"] or (
        (model["fibre_field"],) if model["fibre_field"] else ("vertical",)
    )
    names = [n for n in model["models"] if n != "MS"] or ["MT"]
    for k, field in enumerate(fields):
        for name in names:
            m, ld, tr, sec = _simulate(
                case, ctx, model, dyn, mesh, name, field=field, observe=_pulled(mesh)
            )
            twist, thin = _twist_thinning(mesh, tr.x)
            rows.append(
                {
                    "model": f"{name}-{field}",
                    "mesh": _label(path, mesh),
                    "fibre_field": field,
                    "steps": len(tr.t) - 1,
                    **_pulled_measures(mesh, tr),
                    "twist_deg": twist,
                    "thinning": thin,
                    "run_seconds": sec,
                }
            )
            cells = _cells(mesh)
            a, e = fibre_angles(model, mesh.points, cells, field)
            data = dict(
                points=mesh.points[cells].mean(axis=1),
                directions=frame(a, e)[:, 0],
                u=tr.x[cells].mean(axis=1) - mesh.points[cells].mean(axis=1),
            )
            np.savez(ctx.file(f"fibres-{field}.npz"), **data)
            if k == 0 and name == names[0]:
                np.savez(ctx.file("fibres.npz"), **data)
    return rows


def timing(case, ctx, model, dyn):
    rows = []
    for path, mesh in _meshes(case, dyn):
        kind = "hexa" if "hexahedron" in mesh.cells else "tetra"
        per = {}
        for name in model["models"]:
            dt = _dt(dyn, mesh, name)
            m = build(name, model, mesh, dt)
            ld = loading(model, dyn, mesh, dt)
            steps = int(round(1.0 / dt))
            simulate(m, ld, dt, 2)  # compile / warm up
            best = np.inf
            for _ in range(dyn["repeats"]):
                t0 = time.perf_counter()
                simulate(m, ld, dt, steps, volume=False)
                best = min(best, time.perf_counter() - t0)
            per[name] = best
            n_el = len(_cells(mesh))
            rows.append(
                {
                    "model": name,
                    "mesh": _label(path, mesh),
                    "n_nodes": len(mesh.points),
                    "n_elements": n_el,
                    "dt": dt,
                    "per_sim_second_ms": 1e3 * best,
                }
            )
        if "MS" in per:
            for r in rows[-len(model["models"]) :]:
                if r["model"] != "MS":
                    r["model_MS_ratio_per_second"] = per[r["model"]] / per["MS"]
                    r["paper_model_MS_ratio"] = PAPER_RATIO[kind]
    return rows


def plain(case, ctx, model, dyn):
    rows = []
    for path, mesh in _meshes(case, dyn):
        for name in model["models"]:
            m, ld, tr, sec = _simulate(case, ctx, model, dyn, mesh, name)
            dv = tr.volume_change_percent()
            rows.append(
                {
                    "model": name,
                    "mesh": _label(path, mesh),
                    "steps": len(tr.t) - 1,
                    "final_dV_percent": float(dv[-1]),
                    "run_seconds": sec,
                }
            )
    return rows
