"""Adjoint gradient of G^2 and the eigen-sensitivity gradient of the frequency term,
both against central finite differences; frequency fit recovers known constants."""

import numpy as np
import pytest
import scipy.sparse as sp

from harness.linalg.sparse import single_thread_blas
from harness.optimize import FitProblem, optimize
from harness.optimize.gradient import freq_term_and_grad, frequencies, value_and_grad
from harness.optimize.synthetic import basic_loads, grid_network, recoverable_problem, solve_network


@pytest.fixture(autouse=True)
def _one_blas_thread():
    """Dense BLAS threads oversubscribe the shared cores (and optimize() uses one)."""
    with single_thread_blas():
        yield


def fd(fun, k, idx, h=1e-4):
    out = []
    for e in idx:
        kp, km = k.copy(), k.copy()
        kp[e] *= 1 + h
        km[e] *= 1 - h
        out.append((fun(kp) - fun(km)) / (2 * h * k[e]))
    return np.array(out)


@pytest.mark.parametrize("shape", [(5, 4), (3, 3, 3), (24, 24)])
def test_adjoint_gradient_matches_finite_differences(shape):
    prob, _ = recoverable_problem(shape, seed=5)
    rng = np.random.default_rng(0)
    k = prob.k0 * np.exp(0.2 * rng.standard_normal(prob.n_springs))
    _, g = value_and_grad(prob, k)
    idx = rng.choice(prob.n_springs, 12, replace=False)
    ref = fd(lambda kk: value_and_grad(prob, kk, grad=False)[0], k, idx)
    assert np.allclose(g[idx], ref, rtol=1e-5, atol=1e-7 * np.max(np.abs(ref)))


def modal_problem(weight=1.0, seed=0):
    pts, spr, groups = grid_network((4, 4))
    names, frees, forces = basic_loads(pts)
    rng = np.random.default_rng(seed)
    k0 = np.ones(len(spr))
    k_true = k0 * np.exp(0.3 * rng.standard_normal(len(spr)))
    u_ref = solve_network(pts, spr, k_true, frees, forces)
    masses = rng.uniform(0.5, 1.5, len(pts))
    clamp = frees[2]  # shear-x: edge y = y0 clamped
    tmp = FitProblem.from_network(
        pts,
        spr,
        k_true,
        frees,
        forces,
        u_ref,
        np.ones(pts.size),
        names,
        masses=masses,
        freq_target=np.ones(4),
        modal_free=clamp,
    )
    target = frequencies(tmp, k_true)
    prob = FitProblem.from_network(
        pts,
        spr,
        k0,
        frees,
        forces,
        u_ref,
        np.ones(pts.size),
        names,
        masses=masses,
        freq_target=target,
        freq_weight=weight,
        modal_free=clamp,
    )
    return prob, k_true


def test_frequencies_match_dense_generalised_eigenproblem():
    import scipy.linalg as sla

    prob, k_true = modal_problem()
    mt = prob.modal
    K = (mt.B @ sp.diags(k_true) @ mt.B.T).toarray()
    mu = sla.eigh(K, np.diag(mt.m), eigvals_only=True)[:4]
    assert np.allclose(frequencies(prob, k_true), np.sqrt(mu) / (2 * np.pi), rtol=1e-10)


def test_frequency_gradient_matches_finite_differences():
    prob, _ = modal_problem()
    rng = np.random.default_rng(1)
    k = prob.k0 * np.exp(0.2 * rng.standard_normal(prob.n_springs))
    _, g = freq_term_and_grad(prob, k)
    idx = rng.choice(prob.n_springs, 12, replace=False)
    ref = fd(lambda kk: freq_term_and_grad(prob, kk)[0], k, idx)
    assert np.allclose(g[idx], ref, rtol=1e-5, atol=1e-8 * np.max(np.abs(ref)))


def test_lbfgs_with_frequency_term_fits_both():
    prob, k_true = modal_problem(weight=1.0)
    res = optimize(prob, "lbfgs", {}, seed=0)
    assert res.G_final / res.G_initial < 1e-6
    assert np.max(np.abs(res.info["freq_rel_error"])) < 1e-6


def test_static_only_methods_refuse_the_frequency_term():
    from harness.errors import SpringbenchError

    prob, _ = modal_problem(weight=1.0)
    for method in ("sa", "gauss-newton"):
        with pytest.raises(SpringbenchError, match="lbfgs"):
            optimize(prob, method, {"max_steps": 5} if method == "sa" else {}, seed=0)


def test_spring_tensions_match_dense_solve():
    """The lbfgs scaling's squared tensions sum_l (k_e b_e.u_l)^2, against a dense solve."""
    prob, _ = recoverable_problem((4, 3), seed=2)
    pts, spr, _ = grid_network((4, 3))
    names, frees, forces = basic_loads(pts, s=float(np.prod((4, 3))) ** 0.5)
    t2 = np.zeros(prob.n_springs)
    value_and_grad(prob, prob.k0, grad=False, tension2=t2)
    U = solve_network(pts, spr, prob.k0, frees, forces)
    d = pts[spr[:, 1]] - pts[spr[:, 0]]
    d /= np.linalg.norm(d, axis=1)[:, None]
    ref = np.zeros(len(spr))
    for u in U.reshape(len(U), -1, 2):
        ref += (prob.k0 * np.sum(d * (u[spr[:, 1]] - u[spr[:, 0]]), axis=1)) ** 2
    assert np.allclose(t2, ref, rtol=1e-9, atol=1e-12 * ref.max())


@pytest.mark.parametrize("scale", [0.0, 0.5])
def test_lbfgs_recovers_with_and_without_scaling(scale):
    prob, k_true = recoverable_problem((6, 5), sigma=0.3, seed=8)
    res = optimize(prob, "lbfgs", {"scale": scale}, seed=0)
    assert res.G_final / res.G_initial <= 1e-8
    assert np.max(np.abs(res.k / k_true - 1)) < 1e-5


def test_lbfgs_with_frequency_term_from_the_equilibrium_gap_start():
    prob, k_true = modal_problem(weight=1.0)
    res = optimize(prob, "lbfgs", {"init": "equilibrium-gap"}, seed=0)
    assert res.info["init"] == "equilibrium-gap"
    assert res.G_final / res.G_initial < 1e-6
    assert np.max(np.abs(res.info["freq_rel_error"])) < 1e-6
    from harness.errors import SpringbenchError

    with pytest.raises(SpringbenchError, match="lbfgs"):
        optimize(prob, "equilibrium-gap", {}, seed=0)  # static only: says which method can


@pytest.mark.parametrize(
    "method,options,match",
    [
        ("gauss-newton", {"maxiter": "forty"}, "maxiter = 'forty' is not a number >= 0"),
        ("gauss-newton", {"maxiter": -3}, "optimizer.options.maxiter"),
        ("lbfgs", {"init": 1}, "init = 1 is not a string"),
        ("lbfgs", {"max_seconds": True}, "not a number"),
        ("nelder-mead", {"xatol": float("nan")}, "xatol"),
        ("equilibrium-gap", {"rtol": "tight"}, "equilibrium-gap option rtol"),
    ],
)
def test_bad_option_values_are_one_line_errors(method, options, match):
    from harness.errors import SpringbenchError

    prob, _ = recoverable_problem((3, 3), grouped=method == "nelder-mead")
    with pytest.raises(SpringbenchError, match=match) as err:
        optimize(prob, method, options, seed=0)
    assert "\n" not in str(err.value)


def test_lbfgs_with_frequency_term_rejects_a_start_worse_than_k0():
    """With 5 % displacement noise the equilibrium-gap start is worse than k0 (equation
    error differences neighbouring nodes); with the frequency term too, lbfgs must compare
    Phi there with Phi(k0) = 1 + the frequency term at k0 and start from k0 instead."""
    from harness.optimize.gradient import Objective, freq_term_and_grad

    prob, _ = modal_problem(weight=1.0)
    rng = np.random.default_rng(5)
    noisy = prob.with_reference(
        [b.u_ref * (1 + 0.05 * rng.standard_normal(b.u_ref.shape)) for b in prob.blocks]
    )
    assert Objective(noisy).phi0 == pytest.approx(
        1.0 + freq_term_and_grad(noisy, noisy.k0)[0], rel=1e-12
    )
    res = optimize(noisy, "lbfgs", {"init": "equilibrium-gap", "maxiter": 30}, seed=0)
    assert res.info.get("init_rejected") is True
    assert res.G_final < 0.9 * res.G_initial
