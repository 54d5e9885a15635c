"""The estimate of a mesh too large to refine (reference/adaptive/coarse.py, adaptive.py's
COARSE levels): coarser meshes of the body, the user's system solved in their subspaces,
against independent fine solves (plain scikit-fem, the user's mesh refined)."""

import numpy as np
import pytest
import skfem

import reference
import reference.adaptive.adapt as adaptive
from reference.adaptive import coarse
from reference.fem import Discretisation
from reference.mesh import base_mesh
from tests.reference.test_adaptive import CANTILEVER, at_vertices, independent, mesh_case


def test_transfer_reproduces_the_coarse_polynomials_and_lies_in_the_fine_space():
    """P W: a quadratic field on the coarse mesh is the same quadratic at every fine dof
    (inside the coarse cells and extrapolated outside them)."""
    fine = skfem.MeshTri.init_circle(4)
    grid = coarse.grid_mesh(fine, 0.1)
    assert grid.p.shape[1] < 0.25 * fine.p.shape[1]
    cd, fd = Discretisation(grid, "tri", "P2"), Discretisation(fine, "tri", "P2")
    q = lambda x: np.stack([1 + x[0] - 2 * x[1] ** 2, x[0] * x[1]], axis=-1)  # noqa: E731
    u = coarse.transfer(cd, fd) @ q(cd.doflocs).ravel()
    assert np.allclose(u, q(fd.doflocs).ravel(), atol=1e-12)


@pytest.mark.parametrize("size", [0.03])
def test_coarse_levels_estimate_bounds_the_independent_error(tmp_path, monkeypatch, size):
    """A holed plate (gmsh, non-convex: the coarse grid's cells do not cover it) clamped at
    x = 0 and bent, the dof budget below its own dofs so it is not refined: its estimate
    comes from the coarse levels. Against the independent solve on the mesh refined twice
    (its own error checked against a third), its largest value bounds the largest error
    without a wild factor, and the per-point estimate (that bound, uniform) bounds the
    error at every vertex."""
    pytest.importorskip("gmsh")
    from tests import meshes

    monkeypatch.setattr(adaptive, "MAX_DOFS", {2: 1, 3: 1})
    case = mesh_case(
        tmp_path, meshes.holed_plate(tmp_path, size=size), 2, CANTILEVER, "max_refine = 1\n"
    )
    ref = reference.solve(case, cache=False)
    mesh = base_mesh(case)
    assert ref.level == 0 and ref.mesh.p.shape[1] == mesh.p.shape[1]  # not refined
    pts = mesh.p.T
    truth = [at_vertices(*independent(mesh.refined(r))[:2], len(pts)) for r in (2, 3)]
    u = ref.displacement(pts, "bend")
    err = np.linalg.norm(u - truth[0], axis=1)
    assert np.linalg.norm(truth[1] - truth[0], axis=1).max() < 0.2 * err.max()
    e = ref.error_estimate(pts, "bend")
    assert err.max() <= e.max() < 5 * err.max(), (e.max(), err.max())
    assert np.all(e >= err)
    assert ref.error_estimate["bend"] == pytest.approx(
        e.max() / np.linalg.norm(u, axis=1).max(), rel=1e-9
    )


def test_a_mesh_the_budget_refines_keeps_the_pointwise_estimate(tmp_path):
    """Below the budget the adaptive levels stay (no coarse levels, no uniform bound)."""
    m = skfem.MeshTri.init_sqsymmetric().refined(2)
    from tests.reference.test_adaptive import write_mesh

    case = mesh_case(
        tmp_path, write_mesh(tmp_path / "sq.vtu", m), 2, CANTILEVER, "max_refine = 1\n"
    )
    ref = reference.solve(case, cache=False)
    assert ref.level >= 1 and ref.changes is not None and ref.changes.uniform is None


def test_galerkin_levels_solved_by_the_two_level_method_equal_the_cholesky():
    """A coarse level's Galerkin system may be too large to factorise (a 200k-tet body's
    69k-dof level): the two-level CG on it, with the coarse mesh's own P1 fields as its
    subspace, gives the same fields as the Cholesky of the same system."""
    from harness.case.elasticity import element_stiffness
    from harness.case.reader import Material

    fine = skfem.MeshTet.init_tensor(
        *[np.linspace(0, s, n) for s, n in ((2.0, 9), (1.0, 5), (1.0, 5))]
    )
    grid = coarse.grid_mesh(fine, 0.3)
    d, cd = Discretisation(fine, "tet", "P2"), Discretisation(grid, "tet", "P2")
    K = d.stiffness(element_stiffness(Material(1.0, 0.45), d.centroids()))
    x = d.doflocs
    fixed = np.flatnonzero(np.repeat(x[0] < 1e-12, 3))
    F = np.zeros(d.ndof)
    # a tip load and a graded body load
    F[2::3] = -np.where(x[0] > 2 - 1e-12, 1.0, 0.0) - 0.1 * x[0]
    kw = dict(coarse=cd, fine=d)
    direct = coarse.galerkin_solve(K, {"a": F}, {"a": fixed}, "direct", **kw)["a"]
    info = []
    two = coarse.galerkin_solve(K, {"a": F}, {"a": fixed}, "two-level", records=info, **kw)["a"]
    assert info[0].method == "two-level"
    assert np.abs(two - direct).max() <= 1e-8 * np.abs(direct).max()
    assert np.abs(direct).max() > 0
