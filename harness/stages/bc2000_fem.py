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
    from harness.stages import bc2000_linear as linear
    from reference import solve as reference_solve

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
    if held:
        hc = ref_columns(ref, P, [loads.names[i] for i in held], u_ref[held], classes, weights)
        refcols.update(G_ref_heldout=hc["G_ref"], ref_error_heldout=hc["ref_error_max"])

    def heldout(u):
        return g_arrays(
            u_ref[held], u[held], classes, weights, [loads.names[i] for i in held]
        ).G_norm

    rows, aniso = [], []
    ctx.status("FEM direction pulls")
    bbox = (P.min(axis=0), P.max(axis=0))
    try:  # before the FEM solves: the mesh must reach the corners
        an.pull_arrays(P, bbox, an.pull_load((1.0, 0.0, 0.0)))
    except SpringbenchError as exc:
        raise CaseError(exc.message, file=str(case.path), field="body.file", fix=exc.fix) from None
    pull_loads, fem_dir, fem_dir_err = _fem_directions(case, reference_solve, P)
    kf = [r["stiffness"] for r in fem_dir]
    for a, r in zip(ANGLES, fem_dir):
        aniso.append(
            {
                "angle": a,
                "model": "FEM",
                "stiffness": r["stiffness"],
                "drift": r["drift"],
                "stiffness_fem": r["stiffness"],
            }
        )
    fem_cols = {
        "pull_stiffness_spread_fem": an.spread(kf)[0],
        "pull_drift_max_fem": max(r["drift"] for r in fem_dir),
        "pull_ref_error_estimate": fem_dir_err,
        "ref_error_estimate": float(max(ref.error_estimate.values())),
    }
    for name in model["models"]:
        ctx.status(f"{name}: stiffness")
        m = build(name, model, mesh, 1.0, material=case.material)
        Ks = linear.unit_stiffnesses(m)
        theta = linear.current_parameters(m)
        K0 = sum(t * K for t, K in zip(theta, Ks))
        zm = linear.zero_modes(K0, loads)
        if zm > 0:  # a mechanism (hexa MS under rollers, hourglass modes of MT0 on hexes)
            rows.append(
                {
                    "model": name,
                    "mesh": _label(path, mesh),
                    "n_nodes": len(P),
                    "n_elements": len(_cells(mesh)),
                    "mechanisms": zm,
                    "note": f"{zm} zero-energy modes under the case's constraints: no "
                    "static answer",
                }
            )
            continue
        u = linear.solve(K0, loads)
        c = float(
            np.einsum("p,lpd,lpd->", w, u_ref[fit], u[fit])
            / np.einsum("p,lpd,lpd->", w, u[fit], u[fit])
        )
        theta0 = theta / c  # best single scale (on the fitted loads)
        s0 = g_arrays(u_ref[fit], u[fit] * c, classes, weights, fitted.names)
        row = {
            "model": name,
            "mesh": _label(path, mesh),
            "n_nodes": len(P),
            "n_elements": len(_cells(mesh)),
            "mechanisms": zm,
            "G_initial": s0.G,
            "G_norm_initial": s0.G_norm,
            **fem_cols,
        }
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
        row.update(
            refcols,
            **heldout_modes(
                ref,
                case,
                lumped_masses(P, _cells(mesh), case.material.density),
                loads,
                Ks,
                theta0,
                theta1,
            ),
        )
        row["status"] = ref_status(
            row["G_ref"], row.get("G_norm_final", row["G_norm_initial"]), refcols.get("ref_met_tol")
        )
        if held and ref_status(row["G_ref_heldout"], row["G_heldout"], None) != "ok":
            row["status"] = "ref-coarse"

        # undesired anisotropy (1): the six clamped face pulls, fibre along the pull
        def K_of(d, name=name, theta1=theta1):
            mm = (
                m
                if name == "MS"
                else build(name, dict(model, direction=tuple(d), fibre_field=None), mesh, 1.0)
            )
            return sum(t * K for t, K in zip(theta1, linear.unit_stiffnesses(mm)))

        pulls = linear.face_pull(P, K_of)
        k = np.array([r["stiffness"] for r in pulls])
        row.update(
            {
                "stiffness_spread": float((k.max() - k.min()) / k.mean()),
                "drift_max": float(max(r["drift"] for r in pulls)),
            }
        )
        # (2): uniaxial stress along directions in the x-y plane (harness.mechanics.anisotropy)
        K1 = sum(t * K for t, K in zip(theta1, Ks))
        row.update(_direction_columns(name, K1, P, bbox, pull_loads, fem_dir, aniso, ""))
        # frame turned with the pull: the mesh's share
        if name != "MS" and case.material.fibre is None:
            Kr = [
                sum(
                    t * K
                    for t, K in zip(
                        theta1, linear.unit_stiffnesses(_turned(m, name, model, mesh, ang))
                    )
                )
                for ang in ANGLES
            ]
            row.update(_direction_columns(name, Kr, P, bbox, pull_loads, fem_dir, aniso, "_mesh"))
        rows.append(row)
    pd.DataFrame(aniso).to_csv(ctx.file("anisotropy.csv"), index=False)
    return rows


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
