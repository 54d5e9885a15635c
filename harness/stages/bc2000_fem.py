"""The bc2000 ``fem`` experiment: static G of MS / MT0 / MT against the FEM reference,
calibration of their constants, held-out loads and modes, and the undesired anisotropy
of direction pulls (harness/stages/bc2000.py)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

from harness.case.parts import classify_nodes
from harness.errors import CaseError, SpringbenchError
from harness.mechanics import anisotropy as an
from harness.models.anisotropic import build_anisotropic
from harness.scoring import case_weights, g_arrays, ref_columns, ref_status, reference_displacements
from harness.stages import bc2000_linear as linear
from harness.stages.bc2000_build import _cells, _label, _meshes, build, lumped_masses
from harness.stages.bc2000_modes import heldout_modes


def fem(case, ctx, model, dyn):
    """Static G of MS / MT0 / MT against the FEM reference under the case's loads (small:
    the models are linearised at rest), first with the case's constants scaled by the best
    single factor, then calibrated (all constants, least squares); also the anisotropy
    measures: the six clamped face pulls and the direction pulls (harness.mechanics.anisotropy) of
    the calibrated model beside the FEM's. Rows per model: G_initial/G_final (+
    normalised), ``G_ref`` / ``ref_error_max`` (the reference's own error at the same nodes;
    status "ref-coarse" above 10 % of the final normalised G or when the reference missed
    its tol), the fitted constants, the pull columns; anisotropy.csv per direction. Loads
    held out (``[loads] heldout``) are neither scaled to nor fitted: ``G_heldout``
    (``_initial``: with the scaled constants), ``G_ref_heldout``, ``ref_error_heldout``."""
    from reference import solve as reference_solve

    s = _setup(case, ctx, dyn, reference_solve)
    aniso = []
    _fem_pulls(case, ctx, reference_solve, s, aniso)
    rows = [_model_row(case, ctx, model, dyn, s, name, aniso) for name in model["models"]]
    pd.DataFrame(aniso).to_csv(ctx.file("anisotropy.csv"), index=False)
    return rows


@dataclasses.dataclass
class _Fem:
    """What every model's row is scored against: the mesh, the loads (fitted and held out),
    the FEM reference at the nodes with its columns, and the FEM under the direction pulls."""

    path: object
    mesh: object
    ref: object
    loads: linear.Loads
    classes: np.ndarray
    weights: object
    w: np.ndarray
    u_ref: np.ndarray
    fit: list
    held: list
    fitted: linear.Loads
    refcols: dict
    bbox: tuple = ()
    pull_loads: tuple = ()
    fem_dir: list = dataclasses.field(default_factory=list)
    fem_cols: dict = dataclasses.field(default_factory=dict)

    @property
    def P(self) -> np.ndarray:
        return self.mesh.points

    def held_names(self) -> list:
        return [self.loads.names[i] for i in self.held]

    def heldout(self, u) -> float:
        """Normalised G of the displacements ``u`` (all loads) on the held-out loads."""
        return g_arrays(
            self.u_ref[self.held], u[self.held], self.classes, self.weights, self.held_names()
        ).G_norm

    def mesh_columns(self, name, zm) -> dict:
        """The leading columns of a model's row: model, mesh and its size, mechanisms."""
        return {
            "model": name,
            "mesh": _label(self.path, self.mesh),
            "n_nodes": len(self.P),
            "n_elements": len(_cells(self.mesh)),
            "mechanisms": zm,
        }


def _setup(case, ctx, dyn, reference_solve) -> _Fem:
    """The mesh, the FEM reference and the case's loads at the mesh's nodes, split into the
    fitted and the held-out loads, with the reference's columns of both."""
    path, mesh = _meshes(case, dyn)[0]
    P = mesh.points
    ctx.status("FEM reference")
    ref = reference_solve(case)
    # gravity: rho V
    loads = linear.case_loads(P, case, lumped_masses(P, _cells(mesh), case.material.density))
    classes = classify_nodes(P, case.body.bbox())
    weights = case_weights(case)
    u_ref = reference_displacements(ref, P, loads.names)
    w = np.asarray(weights)[classes]
    fit = [loads.names.index(n) for n in case.fit_loads]  # held-out loads: scored, never fitted
    held = [loads.names.index(n) for n in case.heldout]
    fitted = linear.Loads([loads.names[i] for i in fit], loads.free[fit], loads.forces[fit])
    # same nodes, loads, weights as G
    refcols = ref_columns(ref, P, fitted.names, u_ref[fit], classes, weights)
    s = _Fem(path, mesh, ref, loads, classes, weights, w, u_ref, fit, held, fitted, refcols)
    if held:
        hc = ref_columns(ref, P, s.held_names(), u_ref[held], classes, weights)
        refcols.update(G_ref_heldout=hc["G_ref"], ref_error_heldout=hc["ref_error_max"])
    return s


def _fem_pulls(case, ctx, reference_solve, s: _Fem, aniso: list) -> None:
    """The FEM under the direction pulls and the FEM's columns shared by every model's row
    (both stored in ``s``); its rows of anisotropy.csv appended to ``aniso``."""
    ctx.status("FEM direction pulls")
    s.bbox = (s.P.min(axis=0), s.P.max(axis=0))
    try:  # before the FEM solves: the mesh must reach the corners
        an.pull_arrays(s.P, s.bbox, an.pull_load((1.0, 0.0, 0.0)))
    except SpringbenchError as exc:
        raise CaseError(exc.message, file=str(case.path), field="body.file", fix=exc.fix) from None
    s.pull_loads, s.fem_dir, fem_dir_err = _fem_directions(case, reference_solve, s.P)
    kf = [r["stiffness"] for r in s.fem_dir]
    for a, r in zip(ANGLES, s.fem_dir):
        aniso.append(
            {
                "angle": a,
                "model": "FEM",
                "stiffness": r["stiffness"],
                "drift": r["drift"],
                "stiffness_fem": r["stiffness"],
            }
        )
    s.fem_cols = {
        "pull_stiffness_spread_fem": an.spread(kf)[0],
        "pull_drift_max_fem": max(r["drift"] for r in s.fem_dir),
        "pull_ref_error_estimate": fem_dir_err,
        "ref_error_estimate": float(max(s.ref.error_estimate.values())),
    }


def _combined(theta, Ks):
    """The stiffness sum_i theta_i Ks[i]."""
    return sum(t * K for t, K in zip(theta, Ks))


def _model_row(case, ctx, model, dyn, s: _Fem, name, aniso: list) -> dict:
    """One model's row: G before and after calibration, the reference's columns, the held-out
    modes, the status and the pull columns (its direction rows appended to ``aniso``); a
    mechanism (zero-energy modes under the constraints) has a row with a note only."""
    ctx.status(f"{name}: stiffness")
    m = build(name, model, s.mesh, 1.0, material=case.material)
    Ks = linear.unit_stiffnesses(m)
    theta = linear.current_parameters(m)
    K0 = _combined(theta, Ks)
    zm = linear.zero_modes(K0, s.loads)
    if zm > 0:  # a mechanism (hexa MS under rollers, hourglass modes of MT0 on hexes)
        return {
            **s.mesh_columns(name, zm),
            "note": f"{zm} zero-energy modes under the case's constraints: no static answer",
        }
    row = s.mesh_columns(name, zm)
    theta0, theta1 = _g_columns(ctx, dyn, s, name, m, Ks, theta, K0, row)
    masses = lumped_masses(s.P, _cells(s.mesh), case.material.density)
    row.update(s.refcols, **heldout_modes(s.ref, case, masses, s.loads, Ks, theta0, theta1))
    row["status"] = ref_status(
        row["G_ref"], row.get("G_norm_final", row["G_norm_initial"]), s.refcols.get("ref_met_tol")
    )
    if s.held and ref_status(row["G_ref_heldout"], row["G_heldout"], None) != "ok":
        row["status"] = "ref-coarse"
    row.update(_face_pull_columns(m, name, model, s.mesh, theta1))
    # (2): uniaxial stress along directions in the x-y plane (harness.mechanics.anisotropy)
    K1 = _combined(theta1, Ks)
    row.update(_direction_columns(name, K1, s.P, s.bbox, s.pull_loads, s.fem_dir, aniso, ""))
    # frame turned with the pull: the mesh's share
    if name != "MS" and case.material.fibre is None:
        Kr = [
            _combined(theta1, linear.unit_stiffnesses(_turned(m, name, model, s.mesh, ang)))
            for ang in ANGLES
        ]
        row.update(
            _direction_columns(name, Kr, s.P, s.bbox, s.pull_loads, s.fem_dir, aniso, "_mesh")
        )
    return row


def _g_columns(ctx, dyn, s: _Fem, name, m, Ks, theta, K0, row: dict):
    """G of the model on the fitted loads with its constants scaled by the best single factor
    (``theta0``), then calibrated (``theta1``; ``theta0`` without calibration), and on the
    held-out loads; the columns go into ``row``. Returns (theta0, theta1)."""
    u = linear.solve(K0, s.loads)
    u_ref, fit, w = s.u_ref, s.fit, s.w
    c = float(
        np.einsum("p,lpd,lpd->", w, u_ref[fit], u[fit])
        / np.einsum("p,lpd,lpd->", w, u[fit], u[fit])
    )
    theta0 = theta / c  # best single scale (on the fitted loads)
    s0 = g_arrays(u_ref[fit], u[fit] * c, s.classes, s.weights, s.fitted.names)
    row.update({"G_initial": s0.G, "G_norm_initial": s0.G_norm, **s.fem_cols})
    if s.held:
        row["G_heldout_initial"] = row["G_heldout"] = s.heldout(u * c)
    names = linear.parameter_names(m)
    row.update({f"scaled_{k}": float(v) for k, v in zip(names, theta0)})
    if not dyn["calibrate"]:
        return theta0, theta0
    ctx.status(f"{name}: calibration")
    theta1, _, _ = linear.fit(Ks, theta0, u_ref[fit], s.fitted, w)
    u1 = linear.solve(_combined(theta1, Ks), s.loads)
    s1 = g_arrays(u_ref[fit], u1[fit], s.classes, s.weights, s.fitted.names)
    row.update({"G_final": s1.G, "G_norm_final": s1.G_norm})
    if s.held:
        row["G_heldout"] = s.heldout(u1)
    row.update({f"fit_{k}": float(v) for k, v in zip(names, theta1)})
    return theta0, theta1


def _face_pull_columns(m, name, model, mesh, theta1) -> dict:
    """Undesired anisotropy (1): the six clamped face pulls, the fibre along the pull;
    spread of the stiffness (range over mean) and the largest drift."""

    def K_of(d):
        mm = (
            m
            if name == "MS"
            else build(name, dict(model, direction=tuple(d), fibre_field=None), mesh, 1.0)
        )
        return _combined(theta1, linear.unit_stiffnesses(mm))

    pulls = linear.face_pull(mesh.points, K_of)
    k = np.array([r["stiffness"] for r in pulls])
    return {
        "stiffness_spread": float((k.max() - k.min()) / k.mean()),
        "drift_max": float(max(r["drift"] for r in pulls)),
    }


ANGLES = tuple(range(0, 180, 15))  # pull directions in the x-y plane (degrees from +x)


def _turned(m, name, model, mesh, angle_deg):
    """The element model with every element frame (x, y, z) turned by ``angle_deg`` about z:
    its fibre along the pull direction at that angle, whatever the mesh."""
    c, s = np.cos(np.deg2rad(angle_deg)), np.sin(np.deg2rad(angle_deg))
    F = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    return build_anisotropic(
        m.points,
        m.cells,
        frames=F,
        ks=m.ks,
        kvs=m.kvs,
        volume=(name == "MT"),
        rest_angle=model["rest_angle"],
        seed=model["seed"],
    )


def _direction_columns(name, K, P, bbox, loads, fem_dir, aniso, suffix) -> dict:
    """Columns of the direction pulls of one model (K one matrix, or one per direction):
    spread (max/min), coefficient of variation, largest drift, and the largest deviation of
    the stiffness per direction from the FEM's; rows of anisotropy.csv."""
    Ks = K if isinstance(K, list) else [K] * len(loads)
    res = []
    for ang, load, Kd in zip(ANGLES, loads, Ks):
        u = an.solve_model(Kd, P, bbox, [load])[0]
        res.append(an.measures(P, u, an.directions_xy([ang])[0]))
    k = np.array([r["stiffness"] for r in res])
    kf = np.array([r["stiffness"] for r in fem_dir])
    label = name + ("-turned" if suffix else "")
    for ang, r, f in zip(ANGLES, res, kf):
        aniso.append(
            {
                "angle": ang,
                "model": label,
                "stiffness": r["stiffness"],
                "drift": r["drift"],
                "stiffness_fem": f,
            }
        )
    mx, cv = an.spread(k)
    return {
        f"pull_stiffness_spread{suffix}": mx,
        f"pull_stiffness_cv{suffix}": cv,
        f"pull_drift_max{suffix}": float(max(r["drift"] for r in res)),
        f"pull_stiffness_err_max{suffix}": float(np.abs(k / kf - 1).max()),
    }


def _fem_directions(case, ref_solve, P):
    """The FEM reference under the direction pulls (one reference solve of a copy of the
    case whose loads are the pulls), measured at the model's nodes."""

    loads = tuple(
        an.pull_load(d, name=f"pull-{a}") for a, d in zip(ANGLES, an.directions_xy(ANGLES))
    )
    sub = dataclasses.replace(case, loads=loads)
    ref = ref_solve(sub)
    out = [
        an.measures(P, ref.displacement(P, l.name), d)
        for l, d in zip(loads, an.directions_xy(ANGLES))
    ]
    return loads, out, float(max(ref.error_estimate.values()))
