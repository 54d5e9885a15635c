"""FitProblem and the optimiser registry, against independent dense computations and
recoverable problems (reference = displacements of known perturbed constants, best G = 0)."""

import numpy as np
import pytest

from harness.errors import SpringbenchError
from harness.optimize import OPTIMIZERS, FitProblem, optimize
from harness.optimize.linalg import Factor, nested_dissection
from harness.optimize.synthetic import basic_loads, grid_network, recoverable_problem
from harness.optimize.linalg import single_thread_blas


@pytest.fixture(autouse=True)
def _one_blas_thread():
    """Dense BLAS threads oversubscribe the shared cores (and optimize() uses one)."""
    with single_thread_blas():
        yield


def dense_G(points, springs, k, frees, forces, u_ref, w):
    """Independent G: K assembled spring by spring in a dense matrix, numpy solve."""
    n, dim = points.shape
    K = np.zeros((n * dim, n * dim))
    for (i, j), ke in zip(springs, k):
        d = points[j] - points[i]
        d = d / np.linalg.norm(d)
        b = np.zeros(n * dim)
        b[j * dim:(j + 1) * dim] = d
        b[i * dim:(i + 1) * dim] = -d
        K += ke * np.outer(b, b)
    tot = 0.0
    for free, f, ur in zip(frees, forces, u_ref):
        u = np.zeros(n * dim)
        u[free] = np.linalg.solve(K[np.ix_(free, free)], f[free])
        tot += np.sum(w * (ur - u) ** 2)
    return np.sqrt(tot)


@pytest.mark.parametrize("shape", [(4, 3), (3, 3, 2)])
def test_G_matches_dense_solve(shape):
    pts, spr, _ = grid_network(shape)
    names, frees, forces = basic_loads(pts)
    rng = np.random.default_rng(3)
    k0 = rng.uniform(0.5, 2.0, len(spr))
    u_ref = rng.normal(size=forces.shape)          # arbitrary reference: constrained dofs count too
    w = rng.uniform(1, 3, pts.size)
    prob = FitProblem.from_network(pts, spr, k0, frees, forces, u_ref, w, names)
    k = rng.uniform(0.5, 2.0, len(spr))
    assert prob.G(k) == pytest.approx(dense_G(pts, spr, k, frees, forces, u_ref, w), rel=1e-10)


def test_nested_dissection_factor_matches_direct_solve():
    import scipy.sparse.linalg as spla
    prob, _ = recoverable_problem((34, 34))
    s = prob.load_sets()[0]
    assert s.perm is not None and np.array_equal(np.sort(s.perm), np.arange(s.B.shape[0]))
    k = prob.k0 * np.random.default_rng(0).uniform(0.5, 2, prob.n_springs)
    K = s.stiffness(k)
    x = Factor(K, s.perm).solve(s.F)
    assert np.allclose(x.ravel(), spla.spsolve(K.tocsc(), s.F).ravel(), rtol=1e-9, atol=1e-12)
    coords = np.random.default_rng(1).random((K.shape[0], 2))
    p = nested_dissection(K, coords)
    assert np.array_equal(np.sort(p), np.arange(K.shape[0]))


def test_lbfgs_recovers_constants():
    prob, k_true = recoverable_problem((5, 5), sigma=0.3, seed=1)
    res = optimize(prob, "lbfgs", {}, seed=0)
    assert res.G_final / res.G_initial <= 1e-8
    assert np.max(np.abs(res.k / k_true - 1)) < 1e-5        # all constants identifiable here
    assert res.G_final == pytest.approx(prob.G(res.k))


def test_lbfgs_recovers_constants_3d():
    prob, k_true = recoverable_problem((3, 3, 3), sigma=0.3, seed=2, diagonals="face")
    res = optimize(prob, "lbfgs", {}, seed=0)
    assert res.G_final / res.G_initial <= 1e-8


def test_gauss_newton_recovers_constants():
    prob, k_true = recoverable_problem((5, 5), sigma=0.3, seed=1)
    res = optimize(prob, "gauss-newton", {"target": 1e-9}, seed=0)
    assert res.G_final / res.G_initial <= 1e-8
    assert np.max(np.abs(res.k / k_true - 1)) < 1e-5


def test_nelder_mead_grouped_recovers_group_constants():
    prob, k_true = recoverable_problem((4, 4), sigma=0.4, seed=4, grouped=True)
    res = optimize(prob, "nelder-mead", {}, seed=0)
    assert res.G_final / res.G_initial < 1e-6
    assert np.max(np.abs(res.k / k_true - 1)) < 1e-5


def test_none_and_registry():
    prob, _ = recoverable_problem((3, 3))
    assert {"sa", "sa-refactor", "lbfgs", "nelder-mead", "none"} <= set(OPTIMIZERS)
    res = optimize(prob, "none", {}, seed=0)
    assert res.G_final == res.G_initial and np.array_equal(res.k, prob.k0)
    with pytest.raises(SpringbenchError, match="unknown optimizer"):
        optimize(prob, "simplex", {}, 0)
    with pytest.raises(SpringbenchError, match="unknown simulated-annealing option"):
        optimize(prob, "sa", {"temperature": 3}, 0)
    with pytest.raises(SpringbenchError, match="unknown lbfgs option"):
        optimize(prob, "lbfgs", {"iters": 3}, 0)


def test_bad_problem_input_is_one_line_error():
    pts, spr, _ = grid_network((3, 3))
    names, frees, forces = basic_loads(pts)
    with pytest.raises(SpringbenchError, match="k0"):
        FitProblem.from_network(pts, spr, -np.ones(len(spr)), frees, forces, forces, np.ones(pts.size), names)
    with pytest.raises(SpringbenchError, match="names"):
        FitProblem.from_network(pts, spr, np.ones(len(spr)), frees, forces, forces, np.ones(pts.size), names[:2])


@pytest.mark.parametrize("shape", [(34, 34), (9, 9, 9)])
def test_multifrontal_cholesky_matches_direct_solve(shape):
    import scipy.sparse.linalg as spla
    from harness.optimize.multifrontal import MultifrontalCholesky, Symbolic
    prob, _ = recoverable_problem(shape, seed=3)
    for s in prob.load_sets()[:2]:
        k = prob.k0 * np.random.default_rng(0).uniform(0.5, 2, prob.n_springs)
        K = s.stiffness(k)
        F = MultifrontalCholesky(K, Symbolic(K, s.coords, leaf=40))
        rhs = np.random.default_rng(1).normal(size=(K.shape[0], 3))
        ref = spla.splu(K.tocsc()).solve(rhs)
        assert np.allclose(F.solve(rhs), ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())
        assert np.allclose(F.solve(rhs[:, 0]), ref[:, 0], rtol=1e-9, atol=1e-12 * np.abs(ref).max())
