"""A benchmark pack from a case whose body is a mesh (harness/export/pack.py): per load
the held nodes and components, the nodal forces and the FEM's displacement with its
error estimate at every node of the mesh.

The forces are the ones springbench's own networks get (harness/mechanics/statics.py
``force_vector``): a traction's consistent load on the same boundary facets the FEM
integrates over (its sum is the traction's integral), a stress state's traction on the
whole boundary, gravity as the lumped masses (each simplex's rho V shared equally by its
vertices) times g, which for linear elements is the FEM's consistent body load.
The held components are the ones the FEM holds at those nodes (the same parts).
"""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np

from harness.errors import SpringbenchError
from harness.export.pack import Pack, PackLoad
from harness.mechanics import statics
from harness.scoring import reference_displacements, reference_error

JUDGED_TOL = 0.01  # a held-out load judges an engine when its FEM error estimate is below this


def _kind(load) -> str:
    parts = []
    if load.stress is not None:
        parts.append("stress" if load.stress_gradient is None else "linear-stress")
    if load.tractions:
        parts.append("traction")
    if load.gravity is not None or load.body_force is not None:
        parts.append("gravity" if load.gravity is not None else "body-force")
    return "+".join(parts) or "none"


def make_pack(case, status=lambda msg: None, meta: dict | None = None) -> Pack:
    """The Pack of every load of ``case`` (a mesh body), its FEM solved here."""
    import reference
    from harness.geometry import body_geometry
    from harness.models.masses import compute_masses

    if case.body.shape != "mesh":
        raise SpringbenchError(
            f"the body is a {case.body.shape}, not a mesh: a pack needs the mesh an engine loads",
            file=str(case.path) if case.path else None,
            field="body.shape",
            fix="give a mesh file (springbench pack MESH --E .. --nu ..) or a case with "
            "[body] shape = 'mesh'",
        )
    body = body_geometry(case)
    points = np.asarray(body.mesh_points, float)
    masses = compute_masses("lumped", points, body, case.material).masses
    nodes = SimpleNamespace(points=points, masses=masses)
    status("FEM reference")
    ref = reference.solve(case, status=status)
    names = [ld.name for ld in case.loads]
    u = reference_displacements(ref, points, names)
    err = reference_error(ref, points, names)
    loads = []
    for i, ld in enumerate(case.loads):
        held = statics.fixed_mask(points, case, ld)
        rows = np.flatnonzero(held.any(axis=1))
        g = None if ld.gravity is None else np.asarray(ld.gravity, float)
        loads.append(
            PackLoad(
                ld.name,
                "heldout" if ld.name in case.heldout else "fitted",
                rows,
                held[rows],
                statics.force_vector(nodes, case, ld),
                np.asarray(u[i], float),
                np.asarray(err[i], float),
                g,
                _kind(ld),
            )
        )
    cells = {k: np.asarray(v, int) for k, v in body.mesh_cells.items()}
    m = case.material
    plane = getattr(m, "plane", None) if case.dim == 2 else None
    return Pack(
        points,
        cells,
        float(m.E),
        float(m.nu),
        float(m.density),
        tuple(loads),
        plane,
        dict(meta or {}),
    )


def relative_error(ld: PackLoad) -> float:
    """A load's FEM relative error estimate: its largest nodal estimate over its largest |u|
    (the measure the reference's tol bounds); NaN when the FEM gives no estimate."""
    err = np.asarray(ld.u_fem_error, float)
    if not np.isfinite(err).any():
        return float("nan")
    emax = float(np.nanmax(err))
    umax = float(np.linalg.norm(ld.u_fem, axis=1).max())
    return 0.0 if emax == 0.0 else (emax / umax if umax > 0.0 else float("inf"))


def judged(pack: Pack, tol: float = JUDGED_TOL) -> tuple[Pack, list[str]]:
    """The pack with only the loads that judge an engine: held out, with a FEM error estimate
    <= tol or none (kept: nothing says it is coarse), and one note per load left out or
    kept unestimated; an error naming --loads if none is left."""
    kept, notes = [], []
    for ld in pack.loads:
        if ld.role != "heldout":
            continue
        rel = relative_error(ld)
        if rel != rel:
            notes.append(f"kept {ld.name}: its FEM error is not estimated (--max-refine 0?)")
        elif rel > tol:
            notes.append(
                f"left out {ld.name}: FEM error estimate {100 * rel:.3g} % > {100 * tol:g} % "
                "(--loads all keeps it)"
            )
            continue
        kept.append(ld)
    if not kept:
        raise SpringbenchError(
            f"no held-out load has a FEM error estimate <= {100 * tol:g} %",
            field="--loads",
            fix="--loads all, or a larger --max-refine",
        )
    return dataclasses.replace(pack, loads=tuple(kept)), notes
