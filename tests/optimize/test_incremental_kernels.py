"""The fast paths of the incremental SA engine against independent computations: the
compiled proposal/accept kernels against their plain-Python source, the compiled
multi-right-hand-side substitution against LAPACK and a dense solve, and a long chain
(thousands of accepts) on the compiled sparse path against full re-solves."""

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from harness.linalg.sparse import single_thread_blas
from harness.optimize import incremental as inc
from harness.optimize.incremental import IncrementalG
from harness.optimize.synthetic import recoverable_problem


@pytest.fixture(autouse=True)
def _one_blas_thread():
    with single_thread_blas():
        yield


def walk(eng, prob, n, seed, accept_p=0.85, check=()):
    rng = np.random.default_rng(seed)
    springs = rng.integers(prob.n_springs, size=n + 80)
    out = []
    for it in range(n):
        e = int(springs[it])
        eng.upcoming = springs[it + 1 : it + 70]
        kn = eng.k[e] * np.exp(0.3 * rng.uniform(-1, 1))
        Gn = eng.propose(e, kn)
        if it in check:
            k2 = eng.k.copy()
            k2[e] = kn
            out.append(abs(Gn / prob.G(k2) - 1))
        if rng.random() < accept_p:
            eng.accept()
        else:
            eng.reject()
    out.append(abs(eng.G() / prob.G(eng.k) - 1))
    return max(out)


def test_compiled_kernels_equal_their_python_source(monkeypatch):
    """Same chain with the numba kernels and with the plain functions they compile."""
    prob, _ = recoverable_problem((6, 5), sigma=0.3, seed=4)
    fast = IncrementalG(prob, prob.k0, mode="sparse", refactor_every=20, batch=16)
    monkeypatch.setattr(inc, "_kernels", lambda: (inc._propose, inc._accept))
    slow = IncrementalG(prob, prob.k0, mode="sparse", refactor_every=20, batch=16)
    assert slow._kp is inc._propose and fast._kp is not inc._propose
    rng = np.random.default_rng(0)
    springs = rng.integers(prob.n_springs, size=200)
    for it in range(150):
        e = int(springs[it])
        kn = fast.k[e] * np.exp(0.3 * rng.uniform(-1, 1))
        for eng in (fast, slow):
            eng.upcoming = springs[it + 1 : it + 20]
        a, b = fast.propose(e, kn), slow.propose(e, kn)
        assert a == pytest.approx(b, rel=1e-12)
        if rng.random() < 0.8:
            fast.accept()
            slow.accept()
        else:
            fast.reject()
            slow.reject()
    assert fast.n_rebase >= 4 and fast.G() == pytest.approx(slow.G(), rel=1e-12)


@pytest.mark.parametrize("shape", [(30, 30), (7, 7, 7)])
def test_compiled_substitution_matches_lapack_and_direct(shape):
    from harness.linalg.multifrontal import MultifrontalCholesky, Symbolic

    prob, _ = recoverable_problem(shape, sigma=0.3, seed=1)
    ls = prob.load_sets()[0]
    K = ls.stiffness(prob.k0 * np.exp(np.random.default_rng(0).normal(0, 0.5, prob.n_springs)))
    fac = MultifrontalCholesky(K, Symbolic(K, ls.coords, leaf=32))
    R = np.random.default_rng(1).normal(size=(K.shape[0], 40))
    lapack = fac._solve(R)  # before the compiled path, which frees the LAPACK path's blocks
    X = fac.solve(R)  # compiled path (>= SUBST_MIN columns)
    assert np.allclose(X, lapack, rtol=1e-10, atol=1e-12 * np.abs(X).max())
    direct = spla.spsolve(K.tocsc(), R[:, :3])
    assert np.allclose(X[:, :3], direct, rtol=1e-8, atol=1e-10 * np.abs(direct).max())


def test_long_chain_on_the_compiled_sparse_path_stays_exact():
    """~2,500 accepts through the multifrontal + compiled-kernel path, automatic
    renewal interval, checked against full re-solves along the way."""
    prob, _ = recoverable_problem((22, 22), sigma=0.3, seed=2)
    eng = IncrementalG(prob, prob.k0, mode="sparse")
    assert eng.sets[0].fac.__class__.__name__ == "MultifrontalCholesky"
    err = walk(eng, prob, 3000, seed=5, check=range(0, 3000, 500))
    assert eng.n_rebase >= 3000 * 0.85 // eng.cap - 1
    assert err < 1e-9


def test_auto_interval_respects_bounds_and_memory(monkeypatch):
    """The automatic interval lies in [AUTO_MIN, AUTO_MAX], shrinks to AUTO_MIN when the
    held basis would not fit the memory budget, and dense engines keep DENSE_INTERVAL."""
    prob, _ = recoverable_problem((22, 22), seed=0)
    m = IncrementalG(prob, prob.k0, mode="sparse").cap
    assert inc.AUTO_MIN <= m <= inc.AUTO_MAX
    monkeypatch.setattr(inc, "AUTO_MEMORY", 1e5)
    assert IncrementalG(prob, prob.k0, mode="sparse").cap == inc.AUTO_MIN
    assert IncrementalG(prob, prob.k0, mode="dense").cap == inc.DENSE_INTERVAL


@pytest.mark.parametrize("mode", ["dense", "sparse"])
def test_loads_sharing_K_with_different_weights(mode):
    """Two loads on the same free dofs but with different dof weights: one factorisation,
    two stacked Gram sets; G still matches the full re-solve."""
    from dataclasses import replace

    from harness.optimize.problem import FitProblem

    base, _ = recoverable_problem((5, 4), sigma=0.3, seed=6)
    b0 = base.blocks[0]
    other = replace(
        b0,
        name="heavier",
        w=b0.w * np.linspace(0.5, 3.0, len(b0.w)),
        f=-0.5 * b0.f,
        u_ref=-0.4 * b0.u_ref,
    )
    prob = FitProblem(
        (b0, other) + base.blocks[1:], base.k0, coords=(base.coords[0],) + base.coords
    )
    eng = IncrementalG(prob, prob.k0, mode=mode, refactor_every=30, batch=16)
    assert len(prob.load_sets()) == len(base.load_sets()) and eng.S == len(prob.load_sets()) + 1
    assert walk(eng, prob, 300, seed=3, check=range(0, 300, 60)) < 1e-9
