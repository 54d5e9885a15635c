"""Simulated annealing: incremental G against full re-solves (dense-inverse and
sparse-Woodbury engines, thousands of accepted steps), seeded reproducibility, and
improvement on recoverable problems."""

import numpy as np
import pytest

from harness.linalg.sparse import single_thread_blas
from harness.optimize import optimize
from harness.optimize.incremental import IncrementalG
from harness.optimize.synthetic import recoverable_problem


@pytest.fixture(autouse=True)
def _one_blas_thread():
    """Dense BLAS threads oversubscribe the shared cores (and optimize() uses one)."""
    with single_thread_blas():
        yield


def random_walk(prob, mode, n, check_every, refactor_every=48, seed=0):
    eng = IncrementalG(prob, prob.k0, mode=mode, refactor_every=refactor_every)
    rng = np.random.default_rng(seed)
    errs = []
    springs = rng.integers(prob.n_springs, size=n + 40)
    for it in range(n):
        e = int(springs[it])
        kn = eng.k[e] * np.exp(0.3 * rng.uniform(-1, 1))
        eng.upcoming = springs[it + 1 : it + 33]
        Gn = eng.propose(e, kn)
        if it % check_every == 0:
            k2 = eng.k.copy()
            k2[e] = kn
            errs.append(abs(Gn / prob.G(k2) - 1))
        eng.accept()  # every proposal accepted: worst case for drift
    errs.append(abs(eng.G() / prob.G(eng.k) - 1))
    return eng, max(errs)


@pytest.mark.parametrize(
    "mode,shape,n",
    [
        ("dense", (5, 5), 3000),
        ("sparse", (5, 5), 2000),
        ("dense", (3, 3, 3), 2000),
        ("sparse", (16, 16), 600),
        ("sparse", (34, 34), 300),
    ],
)
def test_incremental_G_matches_full_resolve(mode, shape, n):
    prob, _ = recoverable_problem(shape, seed=1)
    eng, err = random_walk(prob, mode, n, check_every=n // 6)
    assert eng.mode == mode and eng.n_rebase >= n // 64 - 1
    assert err < 1e-9


@pytest.mark.parametrize("mode", ["dense", "sparse"])
def test_incremental_automatic_renewal_stays_exact(mode):
    prob, _ = recoverable_problem((6, 6), seed=9)
    eng, err = random_walk(prob, mode, 1500, check_every=250, refactor_every="auto")
    assert eng.n_rebase >= 1500 // 256 - 1 and err < 1e-9


def test_incremental_without_rebase_woodbury_alone():
    """A long Woodbury chain (no renewal within 60 accepts) stays exact too."""
    prob, _ = recoverable_problem((4, 4), seed=2)
    eng, err = random_walk(prob, "sparse", 60, check_every=7, refactor_every=64)
    assert eng.n_rebase == 0 and err < 1e-9


def test_sa_is_seeded_and_reproducible():
    prob, _ = recoverable_problem((4, 4), seed=3)
    a = optimize(prob, "sa", {"max_steps": 1500}, seed=7)
    b = optimize(prob, "sa", {"max_steps": 1500}, seed=7)
    c = optimize(prob, "sa", {"max_steps": 1500}, seed=8)
    assert np.array_equal(a.k, b.k) and np.array_equal(a.trace, b.trace)
    assert not np.array_equal(a.k, c.k)


def test_sa_incremental_follows_the_refactor_chain():
    """Same seed, same draws: the fast and the paper's engine take the same decisions."""
    prob, _ = recoverable_problem((4, 4), seed=4)
    a = optimize(prob, "sa", {"max_steps": 600}, seed=1)
    b = optimize(prob, "sa-refactor", {"max_steps": 600}, seed=1)
    assert a.accepted == b.accepted
    assert np.allclose(a.k, b.k, rtol=1e-12)


def test_sa_improves_a_recoverable_problem():
    prob, k_true = recoverable_problem((5, 5), sigma=0.3, seed=5)
    res = optimize(prob, "sa", {"max_steps": 8000}, seed=0)
    assert res.G_final < 0.25 * res.G_initial
    assert res.G_final == pytest.approx(res.info["G_best_tracked"], rel=1e-9)
    err0 = np.mean(np.abs(np.log(prob.k0 / k_true)))
    err1 = np.mean(np.abs(np.log(res.k / k_true)))
    assert err1 < 0.7 * err0  # the constants move toward the truth
    assert np.all(np.diff(res.trace[:, 0]) >= 0)


def test_sa_grouped_recovers_group_constants():
    prob, k_true = recoverable_problem((4, 4), sigma=0.3, seed=6, grouped=True)
    res = optimize(prob, "sa", {"max_steps": 1500, "factor": 0.1}, seed=0)
    assert res.G_final < 0.05 * res.G_initial
    assert np.max(np.abs(res.k / k_true - 1)) < 0.05


def test_sa_budget_and_paper_defaults():
    prob, _ = recoverable_problem((3, 3), seed=7)
    e = prob.n_springs
    res = optimize(prob, "sa", {"max_steps": 100}, seed=0)
    assert res.n_steps == 100 and res.info["stop"] == "max_steps"
    assert (res.info["nlimit"], res.info["glimit"], res.info["temperatures"]) == (2 * e, e, 2 * e)
    res = optimize(prob, "sa", {"temperatures": 3, "nlimit": 5, "glimit": 100}, seed=0)
    assert res.n_steps == 3 * 6  # Fig. 6: repeat ... until k > nlimit


def test_two_chains_keep_the_best_and_share_chain_zero():
    prob, _ = recoverable_problem((3, 3), seed=8)
    one = optimize(prob, "sa", {"max_steps": 300}, seed=11)
    two = optimize(prob, "sa", {"max_steps": 300, "chains": 2}, seed=11)
    assert two.info["chains"] == 2 and two.info["chain_seeds"][0] == 11
    assert two.info["chain_G_final"][0] == pytest.approx(one.G_final, rel=1e-12)
    assert two.G_final == min(two.info["chain_G_final"])


@pytest.mark.parametrize("mode", ["dense", "sparse"])
def test_accepting_an_unchanged_constant_keeps_G_exact(mode):
    """A proposal clipped at a bound does not change k; accepting it is a no-op that
    leaves the incremental state exact and computes no 1/0 in the Woodbury core."""
    import warnings

    prob, _ = recoverable_problem((6, 6), sigma=0.3, seed=3)
    eng = IncrementalG(prob, prob.k0, mode=mode, refactor_every=48)
    rng = np.random.default_rng(1)
    warnings.simplefilter("error", RuntimeWarning)
    for it in range(120):
        e = int(rng.integers(prob.n_springs))
        kn = eng.k[e] if it % 7 == 0 else eng.k[e] * np.exp(0.3 * rng.uniform(-1, 1))
        eng.propose(e, kn)
        eng.accept()
    assert np.isfinite(eng.G())
    assert abs(eng.G() / prob.G(eng.k) - 1) < 1e-9


@pytest.mark.parametrize(
    "options, field",
    [
        ({"temperatures": "x"}, "optimizer.options.temperatures"),
        ({"r": "fast"}, "optimizer.options.r"),
        ({"nlimit": -1}, "optimizer.options.nlimit"),
        ({"engine": "gpu"}, "optimizer.options.engine"),
        ({"refactor_every": 0}, "optimizer.options.refactor_every"),
        ({"r": 1.5}, "optimizer.options"),
    ],
)
def test_bad_sa_options_are_one_line_errors(options, field):
    """Wrong types or values are a SpringbenchError naming the option, not a traceback."""
    from harness.errors import SpringbenchError
    from harness.optimize.annealing import check_options

    with pytest.raises(SpringbenchError) as err:
        check_options(options)
    assert str(err.value).startswith(f"{field}: ") and "\n" not in str(err.value)
