"""The FEM reference on whole cases: point location against scikit-fem's probes, P2 edge and
corner constraints, a free rigid motion, the shear references' convergence and the cache,
the reference command and stage, polygon and mesh-file bodies, the iterative solvers, the
mass matrix and plane strain."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import skfem

import reference
from harness.case.loadsets import stretch_closed_form
from harness.case.reader import load_case
from harness.errors import ModelError
from reference.fem import Discretisation
from tests.reference.refcases import ROOT, make_case, rect_case, rel_err

pytestmark = pytest.mark.usefixtures("own_cache")


# -- point location -------------------------------------------------------------------------


@pytest.mark.parametrize("cell,dim", [("tri", 2), ("tet", 3), ("quad", 2)])
def test_locator_agrees_with_scikit_fem_probes(tmp_path, cell, dim):
    case = rect_case(
        tmp_path, cell, "P2", dim=dim, loads=f'set = "basic{dim}d"', divisions=3 if dim == 2 else 2
    )
    sol = reference.solve(case, cache=False)
    lo, hi = case.body.bbox()
    rng = np.random.default_rng(4)
    x = rng.uniform(lo, hi, (300, dim))
    x[:40, 0] = lo[0]  # on the boundary
    x[40:60, 1] = hi[1]
    load = sol.loads[-1]  # a shear: not a linear field
    U = sol.nodal(load)
    mine = sol.displacement(x, load)
    theirs = np.column_stack([sol.basis.probes(x.T) @ U[:, c] for c in range(dim)])
    assert np.abs(mine - theirs).max() <= 1e-12 * np.abs(theirs).max()
    matrix = sol.locator.matrix(sol.basis, x) @ U  # the same sampling as one sparse matrix
    assert np.abs(matrix - theirs).max() <= 1e-12 * np.abs(theirs).max()
    elem, _ = sol.locator.locate(x[60:])
    finder = sol.mesh.element_finder()(*x[60:].T)
    assert np.mean(elem == finder) > 0.99  # interior points: the same element
    # slightly outside (1e-9 of the size) evaluates like the boundary point
    y = x[:40].copy()
    y[:, 0] -= 1e-9 * np.linalg.norm(hi - lo)
    assert np.abs(sol.displacement(y, load) - mine[:40]).max() <= 1e-6 * np.abs(mine).max()
    with pytest.raises(ModelError, match="outside"):
        sol.displacement(np.array([hi + 0.5 * (hi - lo)]), load)


# -- constraints ------------------------------------------------------------------------------


def test_p2_edge_and_corner_constraints(tmp_path):
    case = rect_case(tmp_path, "tet", "P2", dim=3, loads='set = "basic3d"', divisions=2)
    from harness.case.parts import part_predicate
    from reference.mesh import base_mesh

    d = Discretisation(base_mesh(case), "tet", "P2")
    bbox = case.body.bbox()
    n_edge = 2  # cells along y (the shortest side, 2 divisions) on the x0z0 edge
    edge = d.part_dofs(part_predicate("x0z0", bbox), (0, 1, 2))
    assert len(edge) == 3 * (2 * n_edge + 1)  # vertices and mid-edge nodes
    corner = d.part_dofs(part_predicate("x0y0z0", bbox), (1,))
    assert len(corner) == 1 and d.doflocs[:, corner[0] // 3] == pytest.approx(bbox[0])


def test_free_rigid_motion_is_an_error_naming_the_load(tmp_path):
    case = make_case(
        tmp_path,
        """
name = "t"
dim = 2
[body]
shape = "rectangle"
size = [1.0, 1.0]
[material]
E = 1.0
nu = 0.3
[[loads.case]]
name = "wobbly"
constraint = [{ part = "x0y0", components = ["all"] }]
traction = [{ part = "x1", vector = [1.0, 0.0] }]
[reference]
max_refine = 0
""",
    )
    with pytest.raises(ModelError, match="wobbly.*1 rigid"):
        reference.solve(case, cache=False)


# -- convergence of the shear references, cache ------------------------------------------------


@pytest.mark.slow
def test_basic2d_shears_mesh_converged():
    case = load_case(ROOT / "cases/verification/plate_stress_tri.toml", "full")
    sol = reference.solve(case, cache=False)
    for name in ("shear-x", "shear-y"):
        assert sol.error_estimate[name] < case.reference.tol, sol.history
    # the estimate shrinks level by level (the refinement converges, not stalls)
    est = [h["shear-x"] for h in sol.history[1:]]
    assert all(b < 0.5 * a for a, b in zip(est, est[1:])), sol.history


def test_cache_roundtrip_and_key(tmp_path):
    from reference.cache import case_key

    case = rect_case(tmp_path, "tri", "P2", divisions=2, max_refine=1)
    a = reference.solve(case)
    b = reference.solve(case)
    assert not a.from_cache and b.from_cache
    for load in a.loads:
        np.testing.assert_array_equal(a.nodal(load), b.nodal(load))
    assert a.error_estimate == b.error_estimate and a.n_dofs == b.n_dofs
    assert list((tmp_path / "cache" / "reference").glob("*.npz"))
    other = dataclasses.replace(
        case, material=dataclasses.replace(case.material, E=case.material.E * 1.01)
    )
    renamed = dataclasses.replace(case, name="renamed", description="x")
    assert case_key(other) != case_key(case)
    assert case_key(renamed) == case_key(case)
    # the loads the levels drive to tol are part of the solution asked for
    first = case.loads[0].name
    assert case_key(dataclasses.replace(case, heldout=(first,))) != case_key(case)
    assert case_key(dataclasses.replace(case, validation=(first,))) != case_key(case)
    c = reference.solve(other)
    assert not c.from_cache
    np.testing.assert_allclose(
        c.nodal("stretch-x") * 1.01, a.nodal("stretch-x"), rtol=1e-9, atol=1e-15
    )


# -- command and stage ---------------------------------------------------------------------


def test_reference_command_writes_points(tmp_path):
    from harness.cli import main

    case_path = tmp_path / "c.toml"
    rect_case(tmp_path, "tri", "P2", divisions=2, max_refine=0)
    lo = np.array([0.3, -1.2])
    pts = np.array([[0.3, -1.2], [1.0, -1.0], [2.8, -0.4]])
    (tmp_path / "p.csv").write_text("x,y\n" + "\n".join(f"{a},{b}" for a, b in pts))
    out = tmp_path / "u.csv"
    assert (
        main(["reference", str(case_path), "--points", str(tmp_path / "p.csv"), "--out", str(out)])
        == 0
    )
    import pandas as pd

    df = pd.read_csv(out)
    assert list(df.columns) == ["load", "x", "y", "ux", "uy"] and len(df) == 3 * 4
    case = load_case(case_path)
    sx = df[df.load == "stretch-x"]
    exact = stretch_closed_form(case.loads[0], pts, case.material.E, case.material.nu, lo)
    np.testing.assert_allclose(sx[["ux", "uy"]].to_numpy(), exact, rtol=1e-9, atol=1e-12)
    (tmp_path / "bad.csv").write_text("a,b\n1,2\n")
    assert (
        main(
            ["reference", str(case_path), "--points", str(tmp_path / "bad.csv"), "--out", str(out)]
        )
        == 2
    )


def test_stage_rows(tmp_path):
    from harness.stages import StageContext
    from harness.stages import reference_check as stage

    case = rect_case(tmp_path, "tri", "P2", divisions=2, max_refine=1)
    assert stage.applies(case)
    rows = stage.run(case, StageContext(out_dir=tmp_path))
    assert [r["load"] for r in rows] == ["stretch-x", "stretch-y", "shear-x", "shear-y"]
    assert all(r["model"] == "FEM" and r["n_dofs"] > 0 for r in rows)
    assert rows[0]["closed_form_error"] < 1e-10 and np.isnan(rows[2]["closed_form_error"])
    assert rows[0]["u_max"] == pytest.approx(
        np.hypot(2.5 * 2.5 / 3.7e3, 0.27 * 2.5 * 0.8 / 3.7e3), rel=1e-9
    )
    # a row whose estimate misses the case's tol (or has none) says so
    for r in rows:
        assert r["status"] == ("ok" if r["error_estimate"] < r["ref_tol"] else "ref-coarse")
    # one refinement: shear 1e-2
    assert rows[0]["status"] == "ok" and rows[2]["status"] == "ref-coarse"
    coarse = stage.run(
        rect_case(tmp_path, "tri", "P2", divisions=2, max_refine=0), StageContext(out_dir=tmp_path)
    )
    assert all(r["status"] == "ref-coarse" for r in coarse)  # one level: no estimate


# -- polygons ------------------------------------------------------------------------------


def test_polygon_rectangle_patch_and_l_shape_area(tmp_path):
    case = make_case(
        tmp_path,
        """
name = "t"
dim = 2
[body]
shape = "polygon"
vertices = [[0.3, -1.2], [2.8, -1.2], [2.8, -0.4], [0.3, -0.4]]
[material]
E = 3.7e3
nu = 0.27
[loads]
set = "basic2d"
[reference]
element = "P2"
divisions = 3
max_refine = 0
""",
    )
    sol = reference.solve(case, cache=False)
    for load in case.loads[:2]:
        exact = stretch_closed_form(load, sol.mesh.p.T, 3.7e3, 0.27, [0.3, -1.2])
        assert rel_err(sol.vertex_displacement(load.name), exact) <= 1e-10
    from reference.mesh import polygon_mesh

    L = [[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]]
    m = polygon_mesh(L, 6)
    x = m.p[:, m.t]
    e1, e2 = x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]
    area = 0.5 * np.abs(e1[0] * e2[1] - e1[1] * e2[0]).sum()
    assert area == pytest.approx(3.0, rel=1e-12)
    # one closed loop
    assert len(m.boundary_facets()) == len(np.unique(m.facets[:, m.boundary_facets()]))


def test_stage_fibre_closed_form_and_cantilever_columns(tmp_path):
    from harness.stages import StageContext
    from harness.stages import reference_check as stage

    extra = """
[material.fibre]
E_fibre = 4000.0
E_cross = 900.0
azimuth_deg = 20.0
elevation_deg = 30.0
"""
    case = rect_case(
        tmp_path, "hex", "P1", dim=3, loads='set = "basic3d"', extra=extra, divisions=1
    )
    rows = stage.run(case, StageContext(out_dir=tmp_path))
    assert rows[0]["closed_form_error"] < 1e-10 and np.isnan(rows[1]["closed_form_error"])
    case = load_case(ROOT / "cases/verification/cantilever_2d.toml")
    case = dataclasses.replace(case, reference=dataclasses.replace(case.reference, max_refine=0))
    rows = stage.run(case, StageContext(out_dir=tmp_path))
    assert all(abs(r["f1_eb_ratio"] - 1) < 0.02 for r in rows)


@pytest.mark.parametrize("method", ["amg", "cg"])
def test_iterative_solvers_match_direct(tmp_path, method):
    case = rect_case(tmp_path, "tet", "P2", dim=3, loads='set = "basic3d"', divisions=2)
    direct = reference.solve(case, cache=False)
    other = dataclasses.replace(case, reference=dataclasses.replace(case.reference, solver=method))
    it = reference.solve(other, cache=False)
    for load in ("shear-xy", "shear-zy"):
        a, b = direct.nodal(load), it.nodal(load)
        assert np.abs(a - b).max() <= 1e-8 * np.abs(a).max()


def test_mass_matrix_total_mass_with_region_density(tmp_path):
    from harness.case.elasticity import densities
    from reference.mesh import base_mesh

    extra = "[[material.regions]]\nbox = [[0.3, -1.2], [1.55, -0.4]]\nE = 200.0\ndensity = 5.0"
    case = rect_case(tmp_path, "quad", "P2", extra=extra + "\n", divisions=2)
    d = Discretisation(base_mesh(case), "quad", "P2")
    rho = densities(case.material, d.centroids())
    M = d.mass(rho)
    ones_x = np.zeros(d.ndof)
    ones_x[0::2] = 1  # a unit translation along x
    total = ones_x @ M @ ones_x
    assert total == pytest.approx(5.0 * 1.25 * 0.8 + 1.0 * 1.25 * 0.8, rel=1e-12)


@pytest.mark.parametrize("cell", ["tet", "hex"])
def test_mesh_file_body_patch(tmp_path, cell):
    """A body read from a mesh file (meshio VTU written here) reproduces the stretches."""
    import meshio

    M = skfem.MeshTet if cell == "tet" else skfem.MeshHex
    m = M.init_tensor(np.linspace(1, 2, 3), np.linspace(0, 0.5, 2), np.linspace(-1, 0, 3))
    from skfem.io.meshio import to_meshio

    out = to_meshio(m)
    if cell == "tet":  # scikit-fem's tensor tets mix orientations; files must not
        c = out.cells[0].data
        x = out.points[c]
        neg = (
            np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0])
            < 0
        )
        c[neg] = c[neg][:, [1, 0, 2, 3]]
    meshio.write(tmp_path / "body.vtu", out)
    case = make_case(
        tmp_path,
        f"""
name = "t"
dim = 3
[body]
shape = "mesh"
file = "body.vtu"
[material]
E = 10.0
nu = 0.2
[loads]
set = "basic3d"
[reference]
cell = "{cell}"
element = "P1"
max_refine = 0
""",
    )
    sol = reference.solve(case, cache=False)
    for load in case.loads[:3]:
        exact = stretch_closed_form(load, sol.mesh.p.T, 10.0, 0.2, [1, 0, -1])
        assert rel_err(sol.vertex_displacement(load.name), exact) <= 1e-10


def test_plane_strain_stretch_matches_effective_moduli(tmp_path):
    """Plane strain: the stretch is the plane-stress closed form with E/(1-nu^2), nu/(1-nu)."""
    from harness.stages import StageContext
    from harness.stages import reference_check as stage

    case = rect_case(tmp_path, "quad", "P2", E=70.0, nu=0.33)
    case = dataclasses.replace(case, material=dataclasses.replace(case.material, plane="strain"))
    sol = reference.solve(case, cache=False)
    E, nu = 70.0 / (1 - 0.33**2), 0.33 / (1 - 0.33)
    exact = stretch_closed_form(case.loads[1], sol.mesh.p.T, E, nu, case.body.origin)
    assert rel_err(sol.vertex_displacement("stretch-y"), exact) <= 1e-10
    rows = stage.run(case, StageContext(out_dir=tmp_path))
    assert rows[0]["closed_form_error"] < 1e-10
