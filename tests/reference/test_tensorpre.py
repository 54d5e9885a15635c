"""reference/solvers/tensorpre.py (the fast-diagonalisation preconditioner of the graded boxes'
Q2 systems) against independent truths: with whole planes fixed and an orthotropic material the
preconditioner is exactly the inverse of the per-component diagonal blocks of the
stiffness scikit-fem assembles (a sparse direct solve of those blocks here); with
point constraints it stays symmetric positive definite (dense eigenvalues); solves
through it match the Cholesky's, and a failed CG falls back."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse.linalg as spla
import skfem

from harness.case.elasticity import isotropic_compliance
from reference.fem import Discretisation
from reference.graded.meshes import graded_axes, tensor_mesh
from reference.lattice import Lattice
from reference.problem import solve_system
from reference.solvers import plan, sparse, tensorpre


def _orthotropic(dim: int) -> np.ndarray:
    """A positive definite Voigt stiffness with axis-aligned symmetry (no normal-shear
    coupling), all diagonal moduli different."""
    if dim == 2:
        return np.array([[30.0, 8.0, 0.0], [8.0, 20.0, 0.0], [0.0, 0.0, 5.0]])
    C = np.zeros((6, 6))
    C[:3, :3] = [[30.0, 9.0, 7.0], [9.0, 22.0, 6.0], [7.0, 6.0, 18.0]]
    C[3:, 3:] = np.diag([4.0, 5.0, 6.5])
    return C


def _box(size, n, cell):
    mesh = tensor_mesh(graded_axes(np.zeros(len(size)), np.asarray(size, float), n))
    return Discretisation(mesh, cell, "P2")


def test_lattice_recognises_q2_tensor_meshes_only():
    d = _box((3.0, 1.0, 1.0), 2, "hex")
    lat = Lattice.q2(d.doflocs)
    axes, index = lat.axes, lat.index
    ijk = np.unravel_index(index, [len(x) for x in axes])  # x slowest
    for a in range(3):
        np.testing.assert_allclose(axes[a][ijk[a]], d.doflocs[a], atol=1e-12)
    mesh = d.mesh
    p = mesh.p.copy()
    inner = np.flatnonzero(
        np.all((p > 1e-9) & (p < mesh.p.max(axis=1, keepdims=True) - 1e-9), axis=0)
    )[0]
    p[:, inner] += 0.01  # one vertex off the lattice
    assert Lattice.q2(Discretisation(skfem.MeshHex(p, mesh.t), "hex", "P2").doflocs) is None


@pytest.mark.parametrize("cell", ["hex", "quad"])
def test_whole_planes_fixed_give_the_exact_block_inverse(cell):
    """Component 0 clamped on x = 0, component 1 also on y = 0 (a roller), the last
    component of 3-D free on both y faces: P equals inverse(blockdiag K) to rounding."""
    dim = 3 if cell == "hex" else 2
    d = _box((3.0, 1.0, 0.8)[:dim], 2, cell)
    C = np.tile(_orthotropic(dim), (d.nelems, 1, 1))
    K = d.stiffness(C).tocsr()
    x = d.doflocs
    fixed = np.unique(
        np.concatenate(
            [
                d.part_dofs(lambda p: p[0] < 1e-9, range(dim)),
                d.part_dofs(lambda p: p[1] < 1e-9, [1]),
            ]
        )
    )
    free = np.setdiff1d(np.arange(d.ndof), fixed)
    A = K[free][:, free]
    comp = free % dim
    blocks = A.multiply(comp[:, None] == comp[None, :]).tocsc()
    P = tensorpre.preconditioner(x, free, C)
    r = np.random.default_rng(1).standard_normal((len(free), 3))
    for j in range(3):
        exact = spla.spsolve(blocks, r[:, j])
        np.testing.assert_allclose(P(r[:, j]), exact, rtol=0, atol=1e-10 * np.abs(exact).max())


def test_point_constraints_keep_it_symmetric_positive_definite():
    """Face z = 0 clamped and two corner points of the top fixed (in x; in x and y): the
    points are masked out of the blocks, P stays symmetric positive definite (dense
    eigenvalues). A stretch's constraints (a roller face, corner points) leave two
    components without a whole fixed plane: no preconditioner."""
    d = _box((2.0, 1.0, 1.0), 1, "hex")
    C = np.tile(np.linalg.inv(isotropic_compliance(100.0, 0.45)), (d.nelems, 1, 1))
    top = lambda p: (p[0] < 1e-9) & (p[1] < 1e-9) & (p[2] > 1 - 1e-9)  # noqa: E731
    top2 = lambda p: (p[0] > 2 - 1e-9) & (p[1] < 1e-9) & (p[2] > 1 - 1e-9)  # noqa: E731
    fixed = np.unique(
        np.concatenate(
            [
                d.part_dofs(lambda p: p[2] < 1e-9, range(3)),
                d.part_dofs(top, [0]),
                d.part_dofs(top2, [0, 1]),
            ]
        )
    )
    free = np.setdiff1d(np.arange(d.ndof), fixed)
    P = tensorpre.preconditioner(d.doflocs, free, C)
    Pd = np.column_stack([P(e) for e in np.eye(len(free))])
    np.testing.assert_allclose(Pd, Pd.T, atol=1e-12 * np.abs(Pd).max())
    assert np.linalg.eigvalsh(0.5 * (Pd + Pd.T)).min() > 0
    corner = lambda p: (p[0] < 1e-9) & (p[1] < 1e-9) & (p[2] < 1e-9)  # noqa: E731
    stretch = np.unique(
        np.concatenate([d.part_dofs(lambda p: p[0] < 1e-9, [0]), d.part_dofs(corner, [1, 2])])
    )
    assert tensorpre.preconditioner(d.doflocs, np.setdiff1d(np.arange(d.ndof), stretch), C) is None


def _shear_problem(nu=0.49, n=2, regions=False):
    d = _box((4.0, 1.0, 1.0), n, "hex")
    C = np.tile(np.linalg.inv(isotropic_compliance(1e3, nu)), (d.nelems, 1, 1))
    if regions:  # a stiffer half: the preconditioner sees the mean moduli only
        C[d.centroids()[:, 0] > 2.0] *= 2.0
    K = d.stiffness(C)
    fixed = d.part_dofs(lambda p: p[2] < 1e-9, range(3))
    F = {
        "shear": d.traction_load(d.part_facets(lambda p: p[2] > 1 - 1e-9), (1.0, 0.0, 0.0)),
        "sag": d.body_load(np.tile([0.0, -1.0, -2.0], (d.nelems, 1))),
    }
    return d, C, K, F, {n: fixed for n in F}


@pytest.mark.parametrize("regions", [False, True])
def test_tensor_solves_match_the_cholesky(regions):
    d, C, K, F, fx = _shear_problem(regions=regions)
    info: list = []
    U = solve_system(K, F, fx, "tensor", d, records=info, C=C)
    V = solve_system(K, F, fx, "cholesky", d)
    assert info[0].method == "tensor" and not info[0].fallbacks
    assert info[0].matrix_free == (not regions)  # one tensor: K never assembled
    for n in F:
        assert np.abs(U[n] - V[n]).max() <= 1e-8 * np.abs(V[n]).max()


@pytest.mark.parametrize("how", ["budget", "contrast"])
def test_a_failed_tensor_cg_falls_back(monkeypatch, how):
    """Three iterations allowed; or moduli jumping 20x along the bar at nu = 0.49
    (measured: the mean moduli's CG stalls above the tolerance)."""
    if how == "budget":
        monkeypatch.setattr(sparse, "TENSOR_MAXITER", 3)
    d, C, K, F, fx = _shear_problem(nu=0.3 if how == "budget" else 0.49)
    if how == "contrast":
        C[d.centroids()[:, 0] > 2.0] *= 20.0
        K = d.stiffness(C)
    info: list = []
    U = solve_system(K, F, fx, "tensor", d, records=info, C=C)
    V = solve_system(K, F, fx, "cholesky", d)
    assert info[0].fallbacks[0].method == "tensor" and info[0].method != "tensor"
    for n in F:
        assert np.abs(U[n] - V[n]).max() <= 1e-8 * np.abs(V[n]).max()


@pytest.mark.parametrize("regions", [False, True])
@pytest.mark.parametrize("smallest", [0, 10**9])
def test_auto_takes_it_from_its_smallest_size(monkeypatch, smallest, regions):
    """One tensor: the matrix-free CG from plan.MATRIX_FREE_MIN; two: the assembled one
    from plan.TENSOR_MIN."""
    monkeypatch.setattr(plan, "TENSOR_MIN", {3: smallest})
    monkeypatch.setattr(plan, "MATRIX_FREE_MIN", {3: smallest})
    d, C, K, F, fx = _shear_problem(regions=regions)
    info: list = []
    U = solve_system(K, F, fx, "auto", d, records=info, C=C)
    V = solve_system(K, F, fx, "cholesky", d)
    assert (info[0].method == "tensor") == (smallest == 0)
    assert info[0].matrix_free == (smallest == 0 and not regions)
    for n in F:
        assert np.abs(U[n] - V[n]).max() <= 1e-8 * np.abs(V[n]).max()


def test_a_drifted_cg_is_restarted_from_the_true_residual(monkeypatch):
    """The first CG returns a solution off by 1e-6 while reporting success (a recursive
    residual that drifted from the true one): the restart from the true residual brings
    it to the tolerance, and the solve stays 'tensor'."""
    real, calls = sparse._pcg, []

    def drifting(A, b, M, rtol, maxiter, window=20, budget=False):
        x, k, why = real(A, b, M, rtol, maxiter, window, budget)
        calls.append(rtol)
        return (x * (1 + 1e-6) if len(calls) == 1 else x), k, why

    monkeypatch.setattr(sparse, "_pcg", drifting)
    d, C, K, F, fx = _shear_problem(nu=0.3)
    info: list = []
    U = solve_system(
        K, {"shear": F["shear"]}, {"shear": fx["shear"]}, "tensor", d, records=info, C=C
    )
    V = solve_system(K, {"shear": F["shear"]}, {"shear": fx["shear"]}, "cholesky", d)
    assert info[0].method == "tensor" and not info[0].fallbacks and len(calls) >= 2
    assert np.abs(U["shear"] - V["shear"]).max() <= 1e-8 * np.abs(V["shear"]).max()
