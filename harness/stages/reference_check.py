"""Stage "reference": solve the FEM reference of every case with loads and verify it.

One row per load case: the dofs of the final mesh, the reference's own error estimate,
the largest displacement and, where a closed form exists (a homogeneous isotropic
rectangle/box under a standard stretch, in plane strain with E/(1-nu^2), nu/(1-nu); or a
homogeneous fibre
material under stretch-x, reference/analytic.py), the relative error
against it at the mesh vertices. Cases tagged "modal" also get the first natural
frequency with each load case's constraints (f1_hz), and those tagged "cantilever"
(a rectangle/box clamped at x0) its ratio to Euler-Bernoulli (f1_eb_ratio)."""

from __future__ import annotations

import numpy as np

from harness.case.elasticity import element_stiffness
from harness.case.loadsets import stretch_closed_form

NAME = "reference"


def applies(case) -> bool:
    return bool(case.loads)


def closed_form_error(case, sol, load) -> float:
    """max |u - u_exact| / max |u_exact| at the vertices, NaN without a closed form."""
    m = case.material
    standard = case.load_set in ("basic2d", "basic3d") and load.name.startswith("stretch-")
    homogeneous = m.fibre is None and not m.regions
    p = sol.mesh.p.T
    if (
        standard
        and load.name == "stretch-x"
        and m.fibre is not None
        and not m.regions
        and m.fibre.field is None
        and case.body.shape in ("rectangle", "box")
    ):
        # homogeneous anisotropic: uniform stress, strain from the rotated compliance
        from reference.analytic import uniform_stress_displacement

        S = np.linalg.inv(element_stiffness(m, p[:1])[0])
        exact = uniform_stress_displacement(S, load.tractions[0].vector[0], 0, p, case.body.origin)
    elif standard and homogeneous and case.body.shape in ("rectangle", "box"):
        E, nu = m.E, m.nu
        if case.dim == 2 and m.plane == "strain":  # plane strain = plane stress with E', nu'
            E, nu = E / (1 - nu**2), nu / (1 - nu)
        exact = stretch_closed_form(load, p, E, nu, case.body.origin)
    else:
        return float("nan")
    u = sol.vertex_displacement(load.name)
    return float(np.linalg.norm(u - exact, axis=1).max() / np.linalg.norm(exact, axis=1).max())


def run(case, ctx) -> list[dict]:
    import reference

    ctx.status("FEM reference")
    sol = reference.solve(case, status=ctx.status)
    rows = []
    for load in case.loads:
        est = float(sol.error_estimate[load.name])
        # NaN (one level) too
        row = dict(
            case=case.name,
            model="FEM",
            load=load.name,
            n_dofs=sol.n_dofs,
            error_estimate=est,
            u_max=sol.u_max(load.name),
            ref_tol=case.reference.tol,
            ref_method=case.reference.method,
            closed_form_error=closed_form_error(case, sol, load),
            cached=sol.from_cache,
            status="ok" if est < case.reference.tol else "ref-coarse",
        )
        if "modal" in case.tags:
            ctx.status(f"FEM modes ({load.name})")
            row["f1_hz"] = float(sol.frequencies(load=load.name)[0])
            if "cantilever" in case.tags and case.body.shape in ("rectangle", "box"):
                row["f1_eb_ratio"] = row["f1_hz"] / euler_bernoulli(case)
        rows.append(row)
    return rows


def euler_bernoulli(case) -> float:
    """First bending frequency of the body as a beam along x clamped at x0 (the
    smallest cross-section dimension bends; unit thickness in 2-D)."""
    from reference.analytic import cantilever_frequency

    L, *cross = case.body.size
    h = min(cross)
    width = 1.0 if case.dim == 2 else max(cross)
    return cantilever_frequency(
        case.material.E, case.material.density, L, width * h**3 / 12, width * h
    )
