"""Stage "reference": solve the FEM reference of every case with loads and verify it.

One row per load case: the dofs of the final mesh, the reference's own error estimate,
the largest displacement and, where a closed form exists (a homogeneous isotropic
rectangle/box under a standard stretch, plane stress in 2-D), the relative error
against it at the mesh vertices."""

from __future__ import annotations

import numpy as np

NAME = "reference"


def applies(case) -> bool:
    return bool(case.loads)


def closed_form_error(case, sol, load) -> float:
    """max |u - u_exact| / max |u_exact| at the vertices, NaN without a closed form."""
    from harness.loadsets import stretch_closed_form
    m = case.material
    standard = case.load_set in ("basic2d", "basic3d") and load.name.startswith("stretch-")
    homogeneous = m.fibre is None and not m.regions and (case.dim == 3 or m.plane == "stress")
    if not (standard and homogeneous and case.body.shape in ("rectangle", "box")):
        return float("nan")
    p = sol.mesh.p.T
    exact = stretch_closed_form(load, p, m.E, m.nu, case.body.origin)
    u = sol.vertex_displacement(load.name)
    return float(np.linalg.norm(u - exact, axis=1).max() / np.linalg.norm(exact, axis=1).max())


def run(case, ctx) -> list[dict]:
    import reference
    ctx.status("FEM reference")
    sol = reference.solve(case, status=ctx.status)
    rows = []
    for load in case.loads:
        rows.append(dict(case=case.name, model="FEM", load=load.name, n_dofs=sol.n_dofs,
                         error_estimate=sol.error_estimate[load.name], u_max=sol.u_max(load.name),
                         closed_form_error=closed_form_error(case, sol, load),
                         cached=sol.from_cache))
    return rows
