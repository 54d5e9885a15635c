"""The linear2d / linear3d load sets (equilibrated linear stress states on the whole
boundary, harness/case/linear_states.py) on curved gmsh meshes: their closed form
against real P2 solves, equilibrium and independence, the springs' nodal forces against
an independent P1 assembly, the reference's closed-form shortcut, the case file."""

import textwrap

import numpy as np
import pytest
import skfem

from harness.case.elasticity import isotropic_compliance, plane
from harness.case.linear_states import divergence, gradient_states, linear_closed_form
from harness.case.loadsets import ANCHORS, family, stress_field, stress_tensor
from harness.case.reader import load_case
from harness.io.meshfile import read_mesh
from harness.registry import LOAD_SETS
from reference.fem import Discretisation
from tests import meshes

gmsh = pytest.importorskip("gmsh")

S_MAG, E, NU = 100.0, 1e5, 0.45
FAMILIES = {
    3: {"constant": 6, "bending": 6, "torsion": 3, "shear-gradient": 6, "gravity": 3},
    2: {"constant": 3, "bending": 2, "shear-gradient": 2, "gravity": 2},
}


@pytest.fixture(scope="module")
def bodies(tmp_path_factory):
    d = tmp_path_factory.mktemp("linear")
    return {
        "cylinder": meshes.cylinder(d),
        "ellipsoid": meshes.ellipsoid(d),
        "ellipse": meshes.ellipse(d),
    }


def write_case(tmp_path, body: str, dim: int, element="P2", name="c.toml"):
    p = tmp_path / name
    p.write_text(
        textwrap.dedent(f"""
        name = "lin"
        dim = {dim}
        [body]
        {body}
        [material]
        E = {E}
        nu = {NU}
        density = 1000.0
        [loads]
        set = "linear{dim}d"
        magnitude = {S_MAG}
        [reference]
        max_refine = 0
        element = "{element}"
        """)
    )
    return load_case(p)


def mesh_case(tmp_path, mesh, dim, element="P2"):
    return write_case(tmp_path, f'shape = "mesh"\nfile = "{mesh}"', dim, element)


def compliance(dim):
    S = isotropic_compliance(E, NU)
    return S if dim == 3 else np.linalg.inv(plane(np.linalg.inv(S)[None], "stress")[0])


def anchors_of(case):
    return np.array([case.body.parts[a][0] for a in ANCHORS[: case.dim]])


def by_hand_stress(load, x):
    """sigma(x) (..., dim, dim) from the load's fields, written out apart from stress_field."""
    sig = stress_tensor(load.stress) + 0 * x[..., :1, None]
    if load.stress_gradient is not None:
        xi = (x - np.array(load.frame.centroid)) / load.frame.size
        for k, g in enumerate(load.stress_gradient):
            sig = sig + xi[..., k, None, None] * stress_tensor(g)
    return sig


@pytest.mark.parametrize("name,dim", [("cylinder", 3), ("ellipsoid", 3), ("ellipse", 2)])
def test_p2_solves_meet_the_closed_form_on_curved_meshes(tmp_path, bodies, name, dim, monkeypatch):
    """Every state of the set, solved by P2 on a curved mesh (the shortcut switched off),
    equals the quadratic closed form to rounding: what the shortcut relies on."""
    import reference.problem
    from reference.mesh import base_mesh

    case = mesh_case(tmp_path, bodies[name], dim)
    monkeypatch.setattr(reference.problem, "homogeneous_field", lambda *a: None)
    d = Discretisation(base_mesh(case), case.reference.cell, "P2")
    info = []
    U = reference.problem.solve_mesh(case, d.mesh, records=info, disc=d)
    assert sum(len(r.loads) for r in info) == len(case.loads)  # all solved, none taken as exact
    x = d.doflocs.T
    errors = {}
    for load in case.loads:
        want = linear_closed_form(load, x, compliance(dim), anchors_of(case))
        errors[load.name] = np.abs(U[load.name].reshape(-1, dim) - want).max() / np.abs(want).max()
    print(name, d.ndof, "dofs: largest relative error", max(errors.values()))
    assert max(errors.values()) <= 1e-10, errors


@pytest.mark.parametrize("dim", [2, 3])
def test_states_are_equilibrated_independent_and_scaled(tmp_path, bodies, dim):
    """div sigma + b = 0 for every state (central differences of stress_field: exact for
    a linear field), the gradient states span 15 (2-D: 4) dimensions, with the gravity
    states all 18 (6) coefficients; the families count as the docstring says; the peak
    stress on the body is of the order of the magnitude."""
    case = mesh_case(tmp_path, bodies["cylinder" if dim == 3 else "ellipse"], dim)
    counts = {}
    for load in case.loads:
        counts[family(load)] = counts.get(family(load), 0) + 1
    assert counts == FAMILIES[dim]
    L = case.loads[-1].frame.size
    h = 0.1 * L
    x0 = np.asarray(case.loads[-1].frame.centroid) + 0.3 * L
    pts = read_mesh(case.body.file).points
    for load in case.loads:
        div = sum(
            (stress_field(load, x0 + h * e) - stress_field(load, x0 - h * e))[:, j] / (2 * h)
            for j, e in enumerate(np.eye(dim))
        )
        b = np.zeros(dim) if load.body_force is None else np.asarray(load.body_force)
        assert np.abs(div + b).max() <= 1e-12 * S_MAG / L, load.name
        assert (load.family == "gravity") == np.any(b)
        peak = np.abs(stress_field(load, pts)).max()
        assert 0.1 * S_MAG <= peak <= S_MAG, load.name
    G = np.array([g.ravel() for _, fam, g in gradient_states(dim) if fam != "gravity"])
    assert len(G) == np.linalg.matrix_rank(G) == {3: 15, 2: 4}[dim]
    assert all(
        np.abs(divergence(g, 1.0)).max() == 0
        for _, fam, g in gradient_states(dim)
        if fam != "gravity"
    )
    allg = np.array([g.ravel() for _, _, g in gradient_states(dim)])
    assert np.linalg.matrix_rank(allg) == G.shape[1] == {3: 18, 2: 6}[dim]


def p1_facet_load(mesh, dim, load):
    """The P1 load vector (n, dim) of sigma(x) . n on the whole boundary, by scikit-fem's
    facet assembly with the stress written out by hand (by_hand_stress)."""
    elem = skfem.ElementTriP1() if dim == 2 else skfem.ElementTetP1()
    fb = skfem.FacetBasis(mesh, skfem.ElementVector(elem), intorder=3)

    def form(v, w):
        x = np.moveaxis(np.asarray(w.x), 0, -1)
        sig = np.moveaxis(by_hand_stress(load, x), (-2, -1), (0, 1))
        return sum(v[i] * sum(sig[i, j] * w.n[j] for j in range(dim)) for i in range(dim))

    return skfem.asm(skfem.LinearForm(form), fb).reshape(-1, dim)


@pytest.mark.parametrize("name,dim", [("cylinder", 3), ("ellipse", 2)])
def test_nodal_forces_are_the_p1_load_and_balance_the_body(tmp_path, bodies, name, dim):
    """statics.stress_forces of every state equals (1e-12) the P1 load vector of the same
    traction assembled by scikit-fem and by reference.fem's P1 Discretisation; a pure
    traction state has no resultant and no moment; a gravity state's traction resultant
    balances its body force over the volume."""
    from harness.mechanics.statics import stress_forces
    from reference.problem import load_stress

    case = mesh_case(tmp_path, bodies[name], dim)
    m = read_mesh(bodies[name])
    cells = m.cells["tetra" if dim == 3 else "triangle"]
    sk = (skfem.MeshTri if dim == 2 else skfem.MeshTet)(m.points.T, cells.T)
    d1 = Discretisation(sk, "tri" if dim == 2 else "tet", "P1")
    p = m.points[cells]
    vol = np.abs(np.linalg.det(p[:, 1:] - p[:, :1])).sum() / (2 if dim == 2 else 6)
    for load in case.loads:
        f = stress_forces(m.points, case, load)
        scale = np.abs(f).sum()
        F = p1_facet_load(sk, dim, load)
        np.testing.assert_allclose(f, F, rtol=0, atol=1e-12 * np.abs(F).max(), err_msg=load.name)
        np.testing.assert_allclose(
            f.ravel(),
            d1.stress_load(load_stress(load)),
            rtol=0,
            atol=1e-12 * np.abs(F).max(),
            err_msg=load.name,
        )
        b = np.zeros(dim) if load.body_force is None else np.asarray(load.body_force)
        assert np.abs(f.sum(axis=0) + vol * b).max() <= 1e-12 * scale, load.name
        if dim == 3 and load.body_force is None:
            assert (
                np.abs(np.cross(m.points, f).sum(axis=0)).max()
                <= 1e-12 * scale * np.abs(m.points).max()
            )
        elif dim == 2 and load.body_force is None:
            torque = m.points[:, 0] * f[:, 1] - m.points[:, 1] * f[:, 0]
            assert abs(torque.sum()) <= 1e-12 * scale * np.abs(m.points).max()


def test_nodal_forces_on_a_box_grid_are_the_bilinear_load(tmp_path):
    """On a box the faces are tiled by the grid's nodes (rectangles): the forces equal
    scikit-fem's Q1 facet assembly of the linear traction (exact for rectangles) and
    balance (no resultant, no moment)."""
    from harness.mechanics.statics import stress_forces

    case = write_case(
        tmp_path, 'shape = "box"\norigin = [0.5, -1.0, 2.0]\nsize = [2.0, 1.0, 1.5]', 3
    )
    assert {a for a in ANCHORS} <= set(case.body.parts) and all(
        l.stress is not None for l in case.loads
    )
    lo, hi = case.body.bbox()
    mesh = skfem.MeshHex.init_tensor(
        *[np.linspace(lo[a], hi[a], n) for a, n in enumerate((5, 3, 4))]
    )
    fb = skfem.FacetBasis(mesh, skfem.ElementVector(skfem.ElementHex1()), intorder=4)
    for load in case.loads:
        f = stress_forces(mesh.p.T, case, load)

        def form(v, w):
            sig = np.moveaxis(
                by_hand_stress(load, np.moveaxis(np.asarray(w.x), 0, -1)), (-2, -1), (0, 1)
            )
            return sum(v[i] * sum(sig[i, j] * w.n[j] for j in range(3)) for i in range(3))

        F = skfem.asm(skfem.LinearForm(form), fb).reshape(-1, 3)
        np.testing.assert_allclose(f, F, rtol=0, atol=1e-12 * np.abs(F).max(), err_msg=load.name)
        if load.body_force is None:
            assert np.abs(f.sum(axis=0)).max() <= 1e-12 * np.abs(f).sum()
            assert (
                np.abs(np.cross(mesh.p.T, f).sum(axis=0)).max()
                <= 1e-12 * np.abs(f).sum() * hi.max()
            )


def test_the_reference_takes_the_closed_form_on_p2_and_solves_on_p1(tmp_path, bodies):
    """P2 (one elastic tensor): every state is its closed form, without a solve, with a
    zero estimate; P1 cannot represent the quadratic fields, so the gradient states are
    solved (the constant ones stay exact). The residual estimator of the closed form on
    P2 is zero to rounding: its Neumann term reads the linear traction."""
    import reference
    from harness.case.elasticity import densities, element_stiffness
    from reference.adaptive.estimator import indicators
    from reference.mesh import base_mesh
    from reference.problem import fixed_dofs, solve_mesh

    case = mesh_case(tmp_path, bodies["ellipse"], 2)
    sol = reference.solve(case, cache=False)
    assert sol.solver == [] and all(v == 0.0 for v in sol.error_estimate.values())
    x = sol.disc.doflocs.T
    for load in case.loads:
        want = linear_closed_form(load, x, compliance(2), anchors_of(case))
        assert (
            np.abs(sol.nodal(load.name).reshape(-1, 2) - want).max() <= 1e-12 * np.abs(want).max()
        )
    d = sol.disc
    C = element_stiffness(case.material, d.centroids())
    bbox = (d.mesh.p.min(axis=1), d.mesh.p.max(axis=1))
    fixed = {l.name: fixed_dofs(d, case, l, bbox) for l in case.loads}
    U = {l.name: sol.nodal(l.name) for l in case.loads}
    eta = indicators(
        d, case, case.loads, U, C, densities(case.material, d.centroids()), bbox, fixed
    )
    energy = S_MAG**2 / E * 0.4 * 0.25 * np.pi
    assert max(e.sum() for e in eta.values()) <= 1e-20 * energy

    p1 = mesh_case(tmp_path, bodies["ellipse"], 2, element="P1")
    info = []
    U1 = solve_mesh(p1, base_mesh(p1), records=info)
    solved = {n for r in info for n in r.loads}
    assert solved == {l.name for l in p1.loads if l.stress_gradient is not None}
    d1 = Discretisation(base_mesh(p1), "tri", "P1")
    for load in p1.loads:
        want = linear_closed_form(load, d1.doflocs.T, compliance(2), anchors_of(p1))
        err = np.abs(U1[load.name].reshape(-1, 2) - want).max() / np.abs(want).max()
        assert (err <= 1e-12) if load.stress_gradient is None else (1e-4 < err < 0.2), (
            load.name,
            err,
        )
    eta1 = indicators(
        d1,
        p1,
        p1.loads,
        U1,
        element_stiffness(p1.material, d1.centroids()),
        densities(p1.material, d1.centroids()),
        bbox,
        {l.name: fixed_dofs(d1, p1, l, bbox) for l in p1.loads},
    )
    assert (
        min(eta1[l.name].sum() for l in p1.loads if l.stress_gradient is not None) > 1e-6 * energy
    )


def test_a_linear_case_file_loads(tmp_path, bodies):
    """set = "linear3d" on a mesh body: 24 states in order, each with its family, the
    anchors' minimal constraints and the frame (the volume centroid, by hand; the
    largest extent); linear2d on a polygon and a box, and the registry."""
    case = mesh_case(tmp_path, bodies["cylinder"], 3)
    names = [l.name for l in case.loads]
    assert names[:6] == ["sxx", "syy", "szz", "syz", "sxz", "sxy"] and len(names) == 24
    assert names[6:] == (
        ["bend-xy", "bend-xz", "bend-yx", "bend-yz", "bend-zx", "bend-zy"]
        + ["torsion-x", "torsion-y", "torsion-sym", "sgrad-xy", "sgrad-xz"]
        + ["sgrad-yx", "sgrad-yz", "sgrad-zx", "sgrad-zy", "gravity-x"]
        + ["gravity-y", "gravity-z"]
    )
    assert all(family(l) is not None for l in case.loads)
    assert all([len(c.components) for c in l.constraints] == [3, 2, 1] for l in case.loads)
    m = read_mesh(bodies["cylinder"])
    p = m.points[m.cells["tetra"]]
    v = (
        np.abs(
            np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0])
        )
        / 6
    )
    frame = case.loads[-1].frame
    np.testing.assert_allclose(
        frame.centroid, (v[:, None] * p.mean(axis=1)).sum(0) / v.sum(), atol=1e-12
    )
    assert frame.size == pytest.approx(0.5)
    poly = write_case(
        tmp_path, 'shape = "polygon"\nvertices = [[0, 0], [2, 0], [2, 1], [0, 3]]', 2, name="p.toml"
    )
    assert len(poly.loads) == 9 and poly.loads[-1].frame.size == 3.0
    # trapezoid, by hand
    np.testing.assert_allclose(poly.loads[-1].frame.centroid, [5 / 6, 13 / 12], rtol=1e-14)
    box = write_case(
        tmp_path, 'shape = "rectangle"\norigin = [1, 2]\nsize = [4, 2]', 2, name="b.toml"
    )
    assert box.loads[0].stress is not None and box.loads[-1].frame.centroid == (3.0, 3.0)
    assert LOAD_SETS.about["linear2d"] == 2 and LOAD_SETS.about["linear3d"] == 3
