"""The log-k prior of the gradient fits: its value and gradient against a sum
and central differences written here (per spring and grouped), the whole objective's
gradient with it, and recoverability: on a problem with known constants the prior's fit
tends to the truth as its weight goes to 0 (the minimiser moves by O(weight))."""

import numpy as np
import pytest

from harness.errors import SpringbenchError
from harness.linalg.sparse import single_thread_blas
from harness.optimize import optimize
from harness.optimize.gradient import Objective, prior_term
from harness.optimize.synthetic import recoverable_problem


@pytest.fixture(autouse=True)
def _one_blas_thread():
    with single_thread_blas():
        yield


def central(fun, x, h=1e-6):
    g = np.zeros(len(x))
    for i in range(len(x)):
        xp, xm = x.copy(), x.copy()
        xp[i] += h
        xm[i] -= h
        g[i] = (fun(xp) - fun(xm)) / (2 * h)
    return g


@pytest.mark.parametrize("grouped", [False, True])
def test_prior_value_and_gradient(grouped):
    prob, _ = recoverable_problem((4, 3), seed=2, grouped=grouped)
    rng = np.random.default_rng(1)
    x = 0.3 * rng.standard_normal(prob.n_params)
    a = 0.7
    xe = x if prob.groups is None else x[prob.groups]
    mean_sq = sum(v * v for v in xe) / prob.n_springs  # the definition, spring by spring
    val, g = prior_term(prob, x, a)
    assert val == pytest.approx(a * mean_sq, rel=1e-12)
    gx = g if prob.groups is None else np.bincount(prob.groups, weights=g, minlength=prob.n_params)
    assert np.allclose(gx, central(lambda y: prior_term(prob, y, a)[0], x), rtol=1e-6, atol=1e-10)


@pytest.mark.parametrize("grouped", [False, True])
def test_objective_with_prior_gradient_matches_finite_differences(grouped):
    prob, _ = recoverable_problem((4, 4), seed=3, grouped=grouped)
    rng = np.random.default_rng(4)
    x = 0.2 * rng.standard_normal(prob.n_params)
    obj, plain = Objective(prob, prior=0.5), Objective(prob)
    phi, g = obj(x)
    assert phi == pytest.approx(plain(x, grad=False) + prior_term(prob, x, 0.5)[0], rel=1e-12)
    idx = rng.choice(prob.n_params, min(10, prob.n_params), replace=False)
    ref = central(lambda y: obj(y, grad=False), x, h=1e-5)
    assert np.allclose(g[idx], ref[idx], rtol=1e-5, atol=1e-8 * np.max(np.abs(ref)))


def test_prior_fit_recovers_the_truth_as_the_weight_goes_to_zero():
    prob, k_true = recoverable_problem((5, 5), sigma=0.3, seed=1)
    errors = []
    for a in (1e-2, 1e-4, 1e-6):
        res = optimize(prob, "lbfgs", {"prior": a}, seed=0)
        errors.append(np.max(np.abs(np.log(res.k / k_true))))
        assert res.info["prior"] == a
    assert errors[0] > errors[1] > errors[2]  # the bias shrinks with the weight ...
    assert errors[2] < 1e-3  # ... to the truth
    assert errors[0] > 1e-3  # and a real weight does pull (the test can fail)


def test_prior_pulls_towards_the_start():
    """With a large weight the constants stay near k0 and G stays near G(k0)."""
    prob, k_true = recoverable_problem((5, 5), sigma=0.3, seed=1)
    free = optimize(prob, "lbfgs", {}, seed=0)
    held = optimize(prob, "lbfgs", {"prior": 1e3}, seed=0)
    dev = lambda k: np.sqrt(np.mean(np.log(k / prob.k0) ** 2))  # noqa: E731
    assert dev(held.k) < 0.05 * dev(free.k)
    assert held.G_final > 0.5 * held.G_initial


def test_prior_is_an_option_of_lbfgs_and_nelder_mead_only():
    prob, _ = recoverable_problem((3, 3), seed=0, grouped=True)
    assert optimize(prob, "nelder-mead", {"prior": 0.1, "maxiter": 50}, seed=0).info["prior"] == 0.1
    with pytest.raises(SpringbenchError, match="prior"):
        optimize(prob, "gauss-newton", {"prior": 0.1}, seed=0)
    with pytest.raises(SpringbenchError, match="prior"):
        optimize(prob, "lbfgs", {"prior": -1.0}, seed=0)
