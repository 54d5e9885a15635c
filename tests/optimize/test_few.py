"""The fit of a few grouped constants (harness/optimize/few.py) against independent answers:
one group against a bounded scalar minimisation of G^2 solved here, two groups recovering
planted factors exactly and reaching Nelder-Mead's minimum on a reference no factors fit;
the same numbers spread over worker processes."""

import dataclasses
import math
import sys

import numpy as np
import pytest
from scipy.optimize import minimize, minimize_scalar

from harness.optimize import few
from harness.optimize.evaluation import spread
from harness.optimize.synthetic import recoverable_problem
from tests.optimize.test_select import problem


def _two_groups(prob, p, springs):
    """Groups by spring direction: 0 the horizontal springs, 1 every other one."""
    d = p[springs[:, 1]] - p[springs[:, 0]]
    return dataclasses.replace(prob, groups=(np.abs(d[:, 1]) > 1e-12).astype(int))


def test_one_group_is_the_best_global_factor_in_one_evaluation():
    rng = np.random.default_rng(3)
    n = len(problem(np.ones(1))[2])  # per-spring truth: no global factor fits it exactly
    prob, _, _ = problem(2.0 * np.exp(0.3 * rng.standard_normal(n)))
    prob = dataclasses.replace(prob, groups=np.zeros(prob.n_springs, int))
    out = few.few_fit(prob, {"maxiter": 10})
    num = minimize_scalar(
        lambda t: prob.G2(prob.k0 * t), bounds=(0.1, 10), method="bounded", options={"xatol": 1e-10}
    )
    assert out["info"]["stop"] == "exact" and out["info"]["evaluations"] == 1
    assert out["k"] / prob.k0 == pytest.approx(np.full(prob.n_springs, num.x), rel=1e-6)
    assert out["info"]["phi"] == pytest.approx(prob.G2(out["k"]) / prob.G2(prob.k0), rel=1e-9)
    assert 1e-3 < out["info"]["phi"] < 1  # a misfit remains: phi's normaliser matters
    # from another start: the same factor, phi still relative to the rule's G^2
    moved = few.few_fit(prob, {"maxiter": 10}, x0=np.array([0.3]))
    assert moved["k"] == pytest.approx(out["k"], rel=1e-9)
    assert moved["info"]["phi"] == pytest.approx(out["info"]["phi"], rel=1e-9)


def test_two_groups_recover_planted_factors():
    prob, p, springs = problem(np.ones(1))
    prob = _two_groups(prob, p, springs)
    truth = np.array([2.5, 0.4])
    u = prob.solve(prob.k_of(truth))
    prob = prob.with_reference(u)
    out = few.few_fit(prob, {"maxiter": 20})
    assert out["info"]["stop"] == "converged" and out["info"]["evaluations"] <= 12
    assert out["k"] / prob.k0 == pytest.approx(prob.k_of(truth) / prob.k0, rel=1e-5)


def test_two_groups_reach_the_minimum_of_a_direct_search():
    """Per-spring truth factors: no pair of group factors fits; Nelder-Mead on G^2 over the
    two log factors (hundreds of solves) finds the same minimum."""
    rng = np.random.default_rng(7)
    n = len(problem(np.ones(1))[2])
    prob, p, springs = problem(np.exp(0.4 * rng.standard_normal(n)))
    prob = _two_groups(prob, p, springs)
    out = few.few_fit(prob, {"maxiter": 20})
    res = minimize(
        lambda x: prob.G2(prob.k_of(np.exp(x))),
        np.zeros(2),
        method="Nelder-Mead",
        options={"xatol": 1e-9, "fatol": 1e-14, "maxiter": 2000},
    )
    assert prob.G2(out["k"]) == pytest.approx(res.fun, rel=1e-6)
    assert np.log(out["k"][[0, -1]] / prob.k0[[0, -1]]) == pytest.approx(
        res.x[prob.groups[[0, -1]]], abs=1e-3
    )
    assert out["info"]["evaluations"] <= 10


def test_the_bounds_hold_and_the_common_factor_stays_exact_within_them():
    prob, _, _ = problem(np.full(1, 5.0))
    prob = dataclasses.replace(prob, groups=np.zeros(prob.n_springs, int), bounds=(0.5, 2.0))
    out = few.few_fit(prob, {"maxiter": 5})
    assert out["k"] / prob.k0 == pytest.approx(np.full(prob.n_springs, 2.0), rel=1e-12)
    assert out["info"]["phi"] == pytest.approx(prob.G2(out["k"]) / prob.G2(prob.k0), rel=1e-9)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fork: Linux")
def test_a_spread_fit_is_the_callers_bit_for_bit():
    prob = dataclasses.replace(recoverable_problem((8, 8, 8), seed=5)[0], shared=True)
    assert len(prob.solve_parts()) >= 2
    rng = np.random.default_rng(0)
    prob = dataclasses.replace(prob, groups=rng.integers(0, 2, prob.n_springs))
    here = few.few_fit(prob, {"maxiter": 4})
    with spread(prob, 2):
        there = few.few_fit(prob, {"maxiter": 4})
    assert np.array_equal(here["k"], there["k"]) and here["info"] == there["info"]
    assert math.isfinite(here["info"]["phi"]) and here["info"]["phi"] < 1
