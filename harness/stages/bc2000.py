"""Stage "bc2000": the experiments of Bourguignon & Cani 2000 on the original meshes.

``[dynamics] experiment`` picks one:
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
from pathlib import Path

import numpy as np
import pandas as pd

from harness.dynamics import Loading, simulate, solve_static
from harness.errors import CaseError, SpringbenchError
from harness.fibres import named_field_angles
from harness.meshfile import read_mesh
from harness.models.anisotropic import angles_of, build_anisotropic
from harness.models.massspring import build_massspring

NAME = "bc2000"
PAPER_RATIO = {"tetra": 14.5, "hexa": 3.6}   # Table 1: model time / MS time


def applies(case) -> bool:
    m = case.section("model")
    return m is not None and m.get("kind") == "bc2000"


def _meshes(case, dyn):
    out = [(case.body.file, read_mesh(case.body.file, case.body.format))]
    for rel in dyn["meshes"]:
        p = (case.path.parent / rel).resolve()
        try:
            out.append((p, read_mesh(p)))
        except SpringbenchError as exc:
            raise CaseError(exc.message, file=str(case.path), field="dynamics.meshes", fix=exc.fix)
    return out


def _label(path: Path, mesh) -> str:
    kind = "hexa" if "hexahedron" in mesh.cells else "tetra"
    return f"{kind}/{path.parent.name}/{path.name}"


def _cells(mesh):
    return mesh.cells.get("tetra", mesh.cells.get("hexahedron"))


def fibre_angles(model: dict, points, cells, field: str | None = None, material=None):
    """(azimuth, elevation) per element from the [model] keys, else from the case's
    [material.fibre] (the FEM reference's fibre), else vertical (tetra) / x, y, z (hexa)."""
    X = points[cells]
    g = X.mean(axis=1)
    fib = getattr(material, "fibre", None)
    if fib is not None and not any(model.get(k) is not None for k in
                                   ("direction", "azimuth_deg", "elevation_deg", "fibre_field")) and field is None:
        model = dict(model, direction=fib.direction, azimuth_deg=fib.azimuth_deg,
                     elevation_deg=fib.elevation_deg, fibre_field=fib.field, seed=fib.seed)
    field = field or model.get("fibre_field")
    if model.get("direction") is not None:
        a, e = angles_of(np.tile(model["direction"], (len(cells), 1)))
        return a, e
    if model.get("azimuth_deg") is not None or model.get("elevation_deg") is not None:
        return (np.full(len(cells), np.deg2rad(model.get("azimuth_deg") or 0.0)),
                np.full(len(cells), np.deg2rad(model.get("elevation_deg") or 0.0)))
    if field is None:
        field = "vertical" if cells.shape[1] == 4 else None
    if field is None:           # hexa program: axes along x, y, z
        return np.zeros(len(cells)), np.zeros(len(cells))
    return named_field_angles(field, g, model.get("seed", 0), model.get("fibre_origin"))


def build(name: str, model: dict, mesh, dt: float, field: str | None = None, material=None):
    """One of MS, MT0, MT on the mesh, damping converted to physical units."""
    cells = _cells(mesh)
    scale = dt if model["damping_units"] == "per-step" else 1.0
    if name == "MS":
        return build_massspring(mesh.points, cells, ks=model["ms_ks"], kd=model["ms_kd"] * scale)
    a, e = fibre_angles(model, mesh.points, cells, field, material)
    ks = model["ks"] if len(model["ks"]) == 6 else model["ks"] * 6
    kd = model["kd"] if len(model["kd"]) == 3 else model["kd"] * 3
    return build_anisotropic(mesh.points, cells, azimuth=a, elevation=e, ks=ks,
                             kd=np.asarray(kd) * scale, kvs=model["kvs"], kvd=model["kvd"] * scale,
                             volume=(name == "MT"), rest_angle=model["rest_angle"], seed=model["seed"])


def loading(model: dict, dyn: dict, mesh, dt: float) -> Loading:
    return Loading.from_flags(mesh.flags, mass=model["mass"], gravity=dyn["gravity"], push=dyn["push"],
                              drag=dyn["drag"] * dt)


def _dt(dyn, mesh, name):
    if name != "MS" and "hexahedron" in mesh.cells and dyn["hexa_model_dt"]:
        return dyn["hexa_model_dt"]
    return dyn["dt"]


def run(case, ctx) -> list[dict]:
    model = dict(case.section("model"))
    dyn = dict(case.section("dynamics") or {})
    if not dyn:
        from harness.case_sections import DYNAMICS
        from harness.schema import check
        dyn = check({}, DYNAMICS, str(case.path), "dynamics.")
    exp = dyn["experiment"]
    return EXPERIMENTS[exp](case, ctx, model, dyn)


def _steps(dyn, dt) -> int:
    return int(round(dyn["duration"] / dt)) if dyn["duration"] is not None else dyn["steps"]


def _simulate(case, ctx, model, dyn, mesh, name, field=None, **kw):
    dt = _dt(dyn, mesh, name)
    m = build(name, model, mesh, dt, field)
    ld = loading(model, dyn, mesh, dt)
    steps = _steps(dyn, dt)
    ctx.status(f"{name} {steps} steps")
    t0 = time.perf_counter()
    tr = simulate(m, ld, dt, steps, integrator=dyn["integrator"], **kw)
    return m, ld, tr, time.perf_counter() - t0


def _volume(case, ctx, model, dyn):
    rows, curves = [], {}
    path, mesh = _meshes(case, dyn)[0]
    ref = None
    if dyn["original"]:
        f = (case.path.parent / dyn["original"]).resolve()
        try:
            ref = np.loadtxt(f, skiprows=1)
        except (OSError, ValueError) as exc:
            raise CaseError(f"cannot read the original curve ({exc})", file=str(case.path),
                            field="dynamics.original", fix="give a whitespace table with a header line")
    for i, name in enumerate(model["models"]):
        m, ld, tr, sec = _simulate(case, ctx, model, dyn, mesh, name)
        dv = tr.volume_change_percent()
        curves[name] = dv
        row = {"model": name, "mesh": _label(path, mesh), "steps": len(dv) - 1,
               "peak_abs_dV_percent": float(np.abs(dv).max()), "final_dV_percent": float(dv[-1]),
               "run_seconds": sec}
        if ref is not None and name in ("MS", "MT0", "MT"):
            col = ("MS", "MT0", "MT").index(name) + 1 if ref.shape[1] == 4 else 2
            k = min(len(ref), len(dv) - 1)
            row["max_dev_vs_original_percent"] = float(np.abs(dv[1:k + 1] - ref[:k, col]).max())
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
    u = (tr.observed - mesh.points[sel]).mean(axis=1)       # (steps + 1, 3)
    u = u[len(u) // 2:].mean(axis=0)
    drift = float(np.hypot(u[0], u[2]))
    return {"elongation": float(u[1]), "lateral_drift": drift,
            "drift_ratio": drift / max(abs(float(u[1])), 1e-300)}


def _pull(case, ctx, model, dyn):
    rows = []
    for path, mesh in _meshes(case, dyn):
        for name in model["models"]:
            m, ld, tr, sec = _simulate(case, ctx, model, dyn, mesh, name, observe=_pulled(mesh))
            rows.append({"model": name, "mesh": _label(path, mesh), "steps": len(tr.t) - 1,
                         **_pulled_measures(mesh, tr), "run_seconds": sec})
    return rows


def lumped_masses(points, cells, density: float) -> np.ndarray:
    """Node masses (n,) of a constant density: each element's volume times ``density``
    shared equally by its vertices (for a constant body force this is the consistent
    P1 / Q1 load of a tetrahedron / parallelepiped, i.e. the FEM's linear load)."""
    cells = np.asarray(cells)
    per_cell = np.abs(_sub_tet_volumes(points, cells)).sum(axis=1)
    m = np.zeros(len(points))
    np.add.at(m, cells.ravel(), np.repeat(density * per_cell / cells.shape[1], cells.shape[1]))
    return m


def _load_direction(case, load) -> np.ndarray:
    """Unit vector of a load's gravity, else of its first traction, else of its body force."""
    v = load.gravity if load.gravity is not None else (load.tractions[0].vector if load.tractions else load.body_force)
    n = 0.0 if v is None else float(np.linalg.norm(v))
    if not n > 0:
        raise CaseError(f"load '{load.name}' has no force: the tip ratio needs a direction", file=str(case.path),
                        field="loads.case", fix="give it a non-zero gravity, traction or body_force")
    return np.asarray(v, float) / n


COMPARISON = ("linear (small strain): the model linearised at rest vs linear FEM, same clamp, "
              "gravity, density (consistent nodal masses), E, nu")


def _fem_comparison(case, ref, mesh, m, tip) -> dict:
    """Columns comparing the linearised model with the FEM reference under the case's
    loads: per load the mean tip displacement along the load (model, FEM, ratio); the
    gravity load is ``tip_deflection_linear / _fem / tip_ratio``; ``flexion_ratio`` =
    tip_ratio / stretch ratio (1: the model bends as stiffly as its stretching implies;
    > 1: too soft in bending); G of the gravity field, raw and after the best single
    scale (the shape error alone), with ``G_ref`` / ``ref_error_max`` of that load and a
    "ref-coarse" status when G_ref exceeds 10 % of the scaled G or the reference missed
    its tol."""
    from harness.dynamics import stiffness
    from harness.models.bc2000 import linear
    from harness.parts import classify_nodes
    from harness.scoring import case_weights, g_arrays, ref_columns, ref_status, reference_displacements
    P = mesh.points
    masses = lumped_masses(P, _cells(mesh), case.material.density)
    loads = linear.case_loads(P, case, masses)
    u = linear.solve(stiffness(m), loads)
    u_ref = reference_displacements(ref, P, loads.names)
    out = {"comparison": COMPARISON, "ref_error_estimate": float(max(ref.error_estimate.values())),
           "ref_n_dofs": int(ref.n_dofs)}
    ratios = {}
    for i, load in enumerate(case.loads):
        d = _load_direction(case, load)
        um, uf = float((u[i][tip] @ d).mean()), float((u_ref[i][tip] @ d).mean())
        ratios[load.name] = um / uf
        if load.gravity is not None and "tip_ratio" not in out:
            out.update({"tip_deflection_linear": float(u[i][tip, 1].mean()),
                        "tip_deflection_fem": float(u_ref[i][tip, 1].mean()), "tip_ratio": um / uf,
                        "E_bending": case.material.E / (um / uf)})
            classes = classify_nodes(P, case.body.bbox())
            w = np.asarray(case_weights(case))[classes]
            c = float(np.einsum("p,pd,pd->", w, u_ref[i], u[i]) / np.einsum("p,pd,pd->", w, u[i], u[i]))
            s_raw = g_arrays(u_ref[i:i + 1], u[i:i + 1], classes, case_weights(case))
            s_fit = g_arrays(u_ref[i:i + 1], c * u[i:i + 1], classes, case_weights(case))
            out.update({"G_norm_gravity": s_raw.G_norm, "G_norm_gravity_scaled": s_fit.G_norm})
            # the reference's own error as G of the same load and nodes, against the smaller
            # (shape-only) G: a scaled G near the FEM's error is flagged
            out.update(ref_columns(ref, P, [loads.names[i]], u_ref[i:i + 1], classes, case_weights(case)))
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
    flipped = np.sign(_sub_tet_volumes(x, cells)) != np.sign(_sub_tet_volumes(model.points, cells))
    return int(flipped.any(axis=1).sum())


def _sub_tet_volumes(points, cells) -> np.ndarray:
    """Signed volumes (m, k) of each element's tetrahedra (k = 1 for a tet, the hex split
    of harness.models.anisotropic.hex_to_tets for a hex)."""
    from harness.models.anisotropic import hex_to_tets
    tets = cells if cells.shape[1] == 4 else hex_to_tets(cells)
    X = np.asarray(points, float)[tets]
    v = np.einsum("ij,ij->i", np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]), X[:, 3] - X[:, 0]) / 6
    return v.reshape(len(cells), -1)


def _static_columns(m, ld, tip, points, arc_steps: int = 150) -> dict:
    """The nonlinear static equilibrium under the program's load (Newton, load stepping,
    continuation past limit points) beside the linearised response to the same load."""
    from harness.dynamics import solve_static_path, stiffness
    import scipy.sparse.linalg as spla
    free = np.repeat(~ld.fixed, 3)
    K = stiffness(m).tocsr()[free][:, free]
    u = np.zeros(3 * len(points))
    u[free] = spla.spsolve(K.tocsc(), ld.external().ravel()[free])
    lin = float(u.reshape(-1, 3)[tip, 1].mean())
    res = solve_static_path(m, ld, load_steps=10, arc_steps=arc_steps)
    row = {"tip_deflection_linear_program_load": lin, "static_status": res.status,
           "static_load_factor": res.load_factor}
    if res.x is not None:
        st = float((res.x - points)[tip, 1].mean())
        row.update({"tip_deflection_static": st, "static_nonlinearity": st / lin,
                    "static_inverted_elements": inverted_elements(m, res.x)})
    if res.x_limit is not None:     # what the model looks like where it loses stability
        row.update({"limit_load_factor": res.folds[0],
                    "limit_tip_deflection": float((res.x_limit - points)[tip, 1].mean()),
                    "limit_inverted_elements": inverted_elements(m, res.x_limit)})
        if row["limit_inverted_elements"]:
            row["static_status"] += f"; {row['limit_inverted_elements']} elements inside out at the limit point"
    return row


def _cantilever(case, ctx, model, dyn):
    """Tip deflection (mean y displacement of the nodes at the far end z = max), averaged
    over the second half of the run, its swing there, and the static equilibrium; with
    [loads] in the case, the linearised model against the FEM reference
    (:func:`_fem_comparison`)."""
    rows = []
    ref = None
    if case.loads:
        for load in case.loads:          # mistakes before the solves
            _load_direction(case, load)
        from reference import solve as reference_solve
        ctx.status("FEM reference")
        ref = reference_solve(case)
    for path, mesh in _meshes(case, dyn):
        tip = np.flatnonzero(mesh.points[:, 2] >= mesh.points[:, 2].max() - 1e-9)
        for name in model["models"]:
            m, ld, tr, sec = _simulate(case, ctx, model, dyn, mesh, name, observe=tip)
            u = (tr.observed[:, :, 1] - mesh.points[tip, 1]).mean(axis=1)
            late = u[len(u) // 2:]
            row = {"model": name, "mesh": _label(path, mesh), "steps": len(tr.t) - 1,
                   "tip_deflection": float(late.mean()), "tip_swing": float(np.ptp(late)),
                   "tip_deflection_max": float(u.min()), "run_seconds": sec}
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


def _fibres(case, ctx, model, dyn):
    rows = []
    path, mesh = _meshes(case, dyn)[0]
    fields = model["fibre_fields"] or ((model["fibre_field"],) if model["fibre_field"] else ("vertical",))
    names = [n for n in model["models"] if n != "MS"] or ["MT"]
    for k, field in enumerate(fields):
        for name in names:
            m, ld, tr, sec = _simulate(case, ctx, model, dyn, mesh, name, field=field, observe=_pulled(mesh))
            twist, thin = _twist_thinning(mesh, tr.x)
            rows.append({"model": f"{name}-{field}", "mesh": _label(path, mesh), "fibre_field": field,
                         "steps": len(tr.t) - 1, **_pulled_measures(mesh, tr), "twist_deg": twist,
                         "thinning": thin, "run_seconds": sec})
            cells = _cells(mesh)
            from harness.models.anisotropic import frame
            a, e = fibre_angles(model, mesh.points, cells, field)
            data = dict(points=mesh.points[cells].mean(axis=1), directions=frame(a, e)[:, 0],
                        u=tr.x[cells].mean(axis=1) - mesh.points[cells].mean(axis=1))
            np.savez(ctx.file(f"fibres-{field}.npz"), **data)
            if k == 0 and name == names[0]:
                np.savez(ctx.file("fibres.npz"), **data)
    return rows


def _timing(case, ctx, model, dyn):
    rows = []
    for path, mesh in _meshes(case, dyn):
        kind = "hexa" if "hexahedron" in mesh.cells else "tetra"
        per = {}
        for name in model["models"]:
            dt = _dt(dyn, mesh, name)
            m = build(name, model, mesh, dt)
            ld = loading(model, dyn, mesh, dt)
            steps = int(round(1.0 / dt))
            simulate(m, ld, dt, 2)           # compile / warm up
            best = np.inf
            for _ in range(dyn["repeats"]):
                t0 = time.perf_counter()
                simulate(m, ld, dt, steps, volume=False)
                best = min(best, time.perf_counter() - t0)
            per[name] = best
            n_el = len(_cells(mesh))
            rows.append({"model": name, "mesh": _label(path, mesh), "n_nodes": len(mesh.points),
                         "n_elements": n_el, "dt": dt, "per_sim_second_ms": 1e3 * best})
        if "MS" in per:
            for r in rows[-len(model["models"]):]:
                if r["model"] != "MS":
                    r["model_MS_ratio_per_second"] = per[r["model"]] / per["MS"]
                    r["paper_model_MS_ratio"] = PAPER_RATIO[kind]
    return rows


def _plain(case, ctx, model, dyn):
    rows = []
    for path, mesh in _meshes(case, dyn):
        for name in model["models"]:
            m, ld, tr, sec = _simulate(case, ctx, model, dyn, mesh, name)
            dv = tr.volume_change_percent()
            rows.append({"model": name, "mesh": _label(path, mesh), "steps": len(tr.t) - 1,
                         "final_dV_percent": float(dv[-1]), "run_seconds": sec})
    return rows


def _fem(case, ctx, model, dyn):
    """Static G of MS / MT0 / MT against the FEM reference under the case's loads (small:
    the models are linearised at rest), first with the case's constants scaled by the best
    single factor, then calibrated (all constants, least squares); also the anisotropy
    measures: the six clamped face pulls and the direction pulls (harness.anisotropy) of
    the calibrated model beside the FEM's. Rows per model: G_initial/G_final (+
    normalised), ``G_ref`` / ``ref_error_max`` (the reference's own error at the same nodes;
    status "ref-coarse" above 10 % of the final normalised G or when the reference missed
    its tol), the fitted constants, the pull columns; anisotropy.csv per direction. Loads
    held out (``[loads] heldout``) are neither scaled to nor fitted: ``G_heldout``
    (``_initial``: with the scaled constants), ``G_ref_heldout``, ``ref_error_heldout``."""
    from harness.models.bc2000 import linear
    from harness.parts import classify_nodes
    from harness.scoring import case_weights, g_arrays, ref_columns, ref_status, reference_displacements
    from reference import solve as reference_solve
    path, mesh = _meshes(case, dyn)[0]
    P = mesh.points
    ctx.status("FEM reference")
    ref = reference_solve(case)
    loads = linear.case_loads(P, case, lumped_masses(P, _cells(mesh), case.material.density))  # gravity: rho V
    classes = classify_nodes(P, case.body.bbox())
    weights = case_weights(case)
    u_ref = reference_displacements(ref, P, loads.names)
    w = np.asarray(weights)[classes]
    fit = [loads.names.index(n) for n in case.fit_loads]        # held-out loads: scored, never fitted
    held = [loads.names.index(n) for n in case.heldout]
    fitted = linear.Loads([loads.names[i] for i in fit], loads.free[fit], loads.forces[fit])
    refcols = ref_columns(ref, P, fitted.names, u_ref[fit], classes, weights)   # same nodes, loads, weights as G
    if held:
        hc = ref_columns(ref, P, [loads.names[i] for i in held], u_ref[held], classes, weights)
        refcols.update(G_ref_heldout=hc["G_ref"], ref_error_heldout=hc["ref_error_max"])

    def heldout(u):
        return g_arrays(u_ref[held], u[held], classes, weights, [loads.names[i] for i in held]).G_norm
    rows, aniso = [], []
    ctx.status("FEM direction pulls")
    bbox = (P.min(axis=0), P.max(axis=0))
    from harness import anisotropy as an
    try:                                 # before the FEM solves: the mesh must reach the corners
        an.pull_arrays(P, bbox, an.pull_load((1.0, 0.0, 0.0)))
    except SpringbenchError as exc:
        raise CaseError(exc.message, file=str(case.path), field="body.file", fix=exc.fix) from None
    pull_loads, fem_dir, fem_dir_err = _fem_directions(case, reference_solve, P)
    kf = [r["stiffness"] for r in fem_dir]
    for a, r in zip(ANGLES, fem_dir):
        aniso.append({"angle": a, "model": "FEM", "stiffness": r["stiffness"], "drift": r["drift"],
                      "stiffness_fem": r["stiffness"]})
    fem_cols = {"pull_stiffness_spread_fem": an.spread(kf)[0], "pull_drift_max_fem": max(r["drift"] for r in fem_dir),
                "pull_ref_error_estimate": fem_dir_err, "ref_error_estimate": float(max(ref.error_estimate.values()))}
    for name in model["models"]:
        ctx.status(f"{name}: stiffness")
        m = build(name, model, mesh, 1.0, material=case.material)
        Ks = linear.unit_stiffnesses(m)
        theta = linear.current_parameters(m)
        K0 = sum(t * K for t, K in zip(theta, Ks))
        zm = linear.zero_modes(K0, loads)
        if zm > 0:       # a mechanism (hexa MS under rollers, hourglass modes of MT0 on hexes)
            rows.append({"model": name, "mesh": _label(path, mesh), "n_nodes": len(P),
                         "n_elements": len(_cells(mesh)), "mechanisms": zm,
                         "note": f"{zm} zero-energy modes under the case's constraints: no static answer"})
            continue
        u = linear.solve(K0, loads)
        c = float(np.einsum("p,lpd,lpd->", w, u_ref[fit], u[fit]) / np.einsum("p,lpd,lpd->", w, u[fit], u[fit]))
        theta0 = theta / c                                   # best single scale (on the fitted loads)
        s0 = g_arrays(u_ref[fit], u[fit] * c, classes, weights, fitted.names)
        row = {"model": name, "mesh": _label(path, mesh), "n_nodes": len(P), "n_elements": len(_cells(mesh)),
               "mechanisms": zm, "G_initial": s0.G, "G_norm_initial": s0.G_norm, **fem_cols}
        if held:
            row["G_heldout_initial"] = row["G_heldout"] = heldout(u * c)
        names = linear.parameter_names(m)
        row.update({f"scaled_{k}": float(v) for k, v in zip(names, theta0)})
        if dyn["calibrate"]:
            ctx.status(f"{name}: calibration")
            theta1, _, _ = linear.fit(Ks, theta0, u_ref[fit], fitted, w)
            u1 = linear.solve(sum(t * K for t, K in zip(theta1, Ks)), loads)
            s1 = g_arrays(u_ref[fit], u1[fit], classes, weights, fitted.names)
            row.update({"G_final": s1.G, "G_norm_final": s1.G_norm})
            if held:
                row["G_heldout"] = heldout(u1)
            row.update({f"fit_{k}": float(v) for k, v in zip(names, theta1)})
        else:
            theta1 = theta0
        row.update(refcols)
        row["status"] = ref_status(row["G_ref"], row.get("G_norm_final", row["G_norm_initial"]),
                                   refcols.get("ref_met_tol"))
        if held and ref_status(row["G_ref_heldout"], row["G_heldout"], None) != "ok":
            row["status"] = "ref-coarse"
        # undesired anisotropy (1): the six clamped face pulls, fibre along the pull
        def K_of(d, name=name, theta1=theta1):
            mm = m if name == "MS" else build(name, dict(model, direction=tuple(d), fibre_field=None), mesh, 1.0)
            return sum(t * K for t, K in zip(theta1, linear.unit_stiffnesses(mm)))
        pulls = linear.face_pull(P, K_of)
        k = np.array([r["stiffness"] for r in pulls])
        row.update({"stiffness_spread": float((k.max() - k.min()) / k.mean()),
                    "drift_max": float(max(r["drift"] for r in pulls))})
        # (2): uniaxial stress along directions in the x-y plane (harness.anisotropy)
        K1 = sum(t * K for t, K in zip(theta1, Ks))
        row.update(_direction_columns(name, K1, P, bbox, pull_loads, fem_dir, aniso, ""))
        if name != "MS" and case.material.fibre is None:   # frame turned with the pull: the mesh's share
            Kr = [sum(t * K for t, K in zip(theta1, linear.unit_stiffnesses(_turned(m, name, model, mesh, ang))))
                  for ang in ANGLES]
            row.update(_direction_columns(name, Kr, P, bbox, pull_loads, fem_dir, aniso, "_mesh"))
        rows.append(row)
    pd.DataFrame(aniso).to_csv(ctx.file("anisotropy.csv"), index=False)
    return rows


ANGLES = tuple(range(0, 180, 15))   # pull directions in the x-y plane (degrees from +x)


def _turned(m, name, model, mesh, angle_deg):
    """The element model with every element frame (x, y, z) turned by ``angle_deg`` about z:
    its fibre along the pull direction at that angle, whatever the mesh."""
    from harness.models.anisotropic import build_anisotropic
    c, s = np.cos(np.deg2rad(angle_deg)), np.sin(np.deg2rad(angle_deg))
    F = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    return build_anisotropic(m.points, m.cells, frames=F, ks=m.ks, kvs=m.kvs, volume=(name == "MT"),
                             rest_angle=model["rest_angle"], seed=model["seed"])


def _direction_columns(name, K, P, bbox, loads, fem_dir, aniso, suffix) -> dict:
    """Columns of the direction pulls of one model (K one matrix, or one per direction):
    spread (max/min), coefficient of variation, largest drift, and the largest deviation of
    the stiffness per direction from the FEM's; rows of anisotropy.csv."""
    from harness import anisotropy as an
    Ks = K if isinstance(K, list) else [K] * len(loads)
    res = []
    for ang, load, Kd in zip(ANGLES, loads, Ks):
        u = an.solve_model(Kd, P, bbox, [load])[0]
        res.append(an.measures(P, u, an.directions_xy([ang])[0]))
    k = np.array([r["stiffness"] for r in res])
    kf = np.array([r["stiffness"] for r in fem_dir])
    label = name + ("-turned" if suffix else "")
    for ang, r, f in zip(ANGLES, res, kf):
        aniso.append({"angle": ang, "model": label, "stiffness": r["stiffness"], "drift": r["drift"],
                      "stiffness_fem": f})
    mx, cv = an.spread(k)
    return {f"pull_stiffness_spread{suffix}": mx, f"pull_stiffness_cv{suffix}": cv,
            f"pull_drift_max{suffix}": float(max(r["drift"] for r in res)),
            f"pull_stiffness_err_max{suffix}": float(np.abs(k / kf - 1).max())}


def _fem_directions(case, ref_solve, P):
    """The FEM reference under the direction pulls (one reference solve of a copy of the
    case whose loads are the pulls), measured at the model's nodes."""
    import dataclasses
    from harness import anisotropy as an
    loads = tuple(an.pull_load(d, name=f"pull-{a}") for a, d in zip(ANGLES, an.directions_xy(ANGLES)))
    sub = dataclasses.replace(case, loads=loads)
    ref = ref_solve(sub)
    out = [an.measures(P, ref.displacement(P, l.name), d) for l, d in zip(loads, an.directions_xy(ANGLES))]
    return loads, out, float(max(ref.error_estimate.values()))


EXPERIMENTS = {"volume": _volume, "pull": _pull, "cantilever": _cantilever, "fibres": _fibres,
               "timing": _timing, "run": _plain, "fem": _fem}
