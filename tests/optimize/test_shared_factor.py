"""One factorisation for load sets that hold different dofs of one network
(harness/linalg/shared.py), the stiffness map, the multifrontal assembly and the
nested-dissection separators: each against what is computed independently (SuperLU on the
set's own matrix, a dense B diag(k) B^T, the graph's edges), and the fit's objective and
gradient with shared sets against the sets apart and against finite differences."""

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from harness.linalg.multifrontal import MultifrontalCholesky, Symbolic
from harness.linalg.shared import SharedSets, best_group
from harness.linalg.sparse import single_thread_blas
from harness.linalg.stiffness import restriction, stiffness_map
from harness.optimize.evaluation import value_and_grad
from harness.optimize.gradient import Objective
from harness.optimize.synthetic import recoverable_problem
from tests.optimize.test_gradient import fd


@pytest.fixture(autouse=True)
def _one_blas_thread():
    with single_thread_blas():
        yield


def grid(shape=(8, 8, 8), seed=5):
    """A 3-D grid network's problem under the basic loads (three roller sets and three
    clamped faces, six different sets of free dofs), its sets sharing factorisations."""
    prob, _ = recoverable_problem(shape, seed=seed)
    assert len(prob.load_sets()) == 6 and not prob.shared
    return dataclasses.replace(prob, shared=True)


def test_a_shared_factorisation_solves_each_set_as_its_own_matrix():
    prob = grid()
    sets = prob.load_sets()
    shared = SharedSets([s.B for s in sets], [s.dofs for s in sets], [s.coords for s in sets])
    assert 0 < shared.n_held < len(shared.union)
    k = prob.k0 * np.random.default_rng(0).uniform(0.5, 2.0, prob.n_springs)
    rhs = [np.random.default_rng(i).normal(size=(s.B.shape[0], 2)) for i, s in enumerate(sets)]
    for s, r, x in zip(sets, rhs, shared.factor(k).solve(rhs)):
        ref = spla.splu(s.stiffness(k).tocsc()).solve(r)
        assert np.allclose(x, ref, rtol=1e-9, atol=1e-11 * np.abs(ref).max())


def test_value_and_grad_of_shared_sets_equals_the_sets_apart_and_finite_differences():
    prob = grid()
    parts = prob.solve_parts()
    assert any(shared is not None for _, shared in parts)  # the test covers the shared path
    assert sorted(i for idx, _ in parts for i in idx) == list(range(len(prob.load_sets())))
    k = prob.k0 * np.exp(0.2 * np.random.default_rng(1).standard_normal(prob.n_springs))
    G2, g = value_and_grad(prob, k)
    apart = dataclasses.replace(prob, shared=False)
    assert all(shared is None for _, shared in apart.solve_parts())
    G2a, ga = value_and_grad(apart, k)
    assert G2 == pytest.approx(G2a, rel=1e-11)
    assert np.allclose(g, ga, rtol=1e-8, atol=1e-10 * np.abs(ga).max())
    idx = np.random.default_rng(2).choice(prob.n_springs, 10, replace=False)
    ref = fd(lambda kk: value_and_grad(prob, kk, grad=False)[0], k, idx)
    assert np.allclose(g[idx], ref, rtol=1e-5, atol=1e-7 * np.max(np.abs(ref)))


def test_best_group_shares_only_where_it_saves_flops():
    prob = grid()
    sets = prob.load_sets()
    alone = [s.symbolic().estimate()["gflop"] for s in sets]
    found = best_group(
        [s.B for s in sets],
        [s.dofs for s in sets],
        [s.coords for s in sets],
        alone,
        [s.name for s in sets],
    )
    assert found is not None
    group, shared = found
    assert len(set(group)) == len(group) >= 2
    assert shared.estimate() < sum(alone[i] for i in group)


def test_stiffness_map_is_the_dense_product():
    """Columns with two to forty nonzeros (springs, and node-volume-like columns)."""
    rng = np.random.default_rng(3)
    n, cols = 60, []
    for nnz in rng.integers(2, 40, 50):
        c = np.zeros(n)
        c[rng.choice(n, nnz, replace=False)] = rng.normal(size=nnz)
        cols.append(c)
    Bd = np.array(cols).T
    k = rng.uniform(0.5, 2.0, Bd.shape[1])
    pattern, P = stiffness_map(sp.csc_matrix(Bd))
    K = pattern.copy()
    K.data = P @ k
    assert np.allclose(K.toarray(), (Bd * k) @ Bd.T, rtol=1e-12, atol=1e-12)


def test_multifrontal_reads_a_csc_matrix_on_its_pattern_as_its_csr():
    prob = grid((6, 6, 6))
    s = prob.load_sets()[0]
    K = s.stiffness(prob.k0 * 1.3)  # csc
    sym = Symbolic(K, s.coords, leaf=40)
    rhs = np.random.default_rng(4).normal(size=(K.shape[0], 3))
    a = MultifrontalCholesky(K, sym).solve(rhs)
    b = MultifrontalCholesky(K.tocsr(), sym).solve(rhs)
    assert np.array_equal(a, b)
    ref = spla.splu(K).solve(rhs)
    assert np.allclose(a, ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())


def test_a_fit_from_k0_solves_k0_once_with_the_same_numbers(monkeypatch):
    """The objective of a fit that starts at k0 keeps G0's gradient for its first
    evaluation: one solve fewer, the same values bit for bit as a second solve."""
    from harness.optimize import gradient

    prob, _ = recoverable_problem((5, 4), seed=1)
    x0 = np.zeros(prob.n_params)
    fresh = Objective(prob)(x0)
    calls = []
    real = gradient.value_and_grad
    monkeypatch.setattr(
        gradient, "value_and_grad", lambda *a, **kw: calls.append(1) or real(*a, **kw)
    )
    obj = Objective(prob, from_k0=True)
    kept = obj(x0)
    assert len(calls) == 1
    assert kept[0] == fresh[0] and np.array_equal(kept[1], fresh[1])
    obj(x0)  # a later visit of k0 solves again
    assert len(calls) == 2


def test_every_separator_of_the_dissection_separates_its_children():
    """No edge joins the vertices under one child of a tree node to those under the other
    (the separator, the node's own vertices, takes every left vertex touching the right)."""
    from harness.linalg.sparse import dissection_tree

    prob = grid((7, 6, 5))
    s = prob.load_sets()[0]
    A = s.stiffness(prob.k0).tocsr()
    nodes = dissection_tree(A, s.coords, leaf=20)
    under = []
    for V, kids in nodes:  # postorder: the children's sets are known
        under.append(np.concatenate([V] + [under[c] for c in kids]))
        if len(kids) == 2:
            a, b = under[kids[0]], under[kids[1]]
            assert A[a][:, b].nnz == 0
    order = np.concatenate([V for V, _ in nodes])
    assert np.array_equal(np.sort(order), np.arange(A.shape[0]))


def _own(B, k):
    pattern, P = stiffness_map(B)
    K = pattern.copy()
    K.data = P @ k
    return K


def test_the_network_map_restricted_is_each_sets_own_map_bit_for_bit():
    """Every load set's K and every shared group's K taken from the network's one map k -> K
    (restriction) equal those of their own maps bit for bit, pattern and values: also with
    node-volume-like columns (tens of nonzeros) beside the springs; and the dense product."""
    prob = grid()
    sets = prob.load_sets()
    network = sets[0].network
    assert network is not None and all(s.network is network for s in sets)
    rng = np.random.default_rng(7)
    k = prob.k0 * rng.uniform(0.5, 2.0, prob.n_springs)
    for s in sets:
        K, own = s.stiffness(k), _own(s.B, k)
        assert np.array_equal(K.indptr, own.indptr) and np.array_equal(K.indices, own.indices)
        assert K.data.tobytes() == own.data.tobytes()
    whole = stiffness_map(network)
    args = ([s.B for s in sets], [s.dofs for s in sets], [s.coords for s in sets])
    parts = (lambda: whole[0], lambda k: whole[1] @ k)
    a, b = SharedSets(*args, whole=parts).stiffness(k), SharedSets(*args).stiffness(k)
    assert np.array_equal(a.indices, b.indices) and a.data.tobytes() == b.data.tobytes()
    n = network.shape[0]
    wide = sp.random(n, 30, density=0.3, random_state=8, format="csc")
    B2 = sp.hstack([network, wide]).tocsc()
    k2 = np.concatenate([k, rng.uniform(0.5, 2.0, 30)])
    pattern, P = stiffness_map(B2)
    for s in sets:
        sub, gather = restriction(pattern, s.dofs)
        K = sub.copy()
        K.data = (P @ k2)[gather]
        own = _own(B2[s.dofs], k2)
        assert np.array_equal(K.indices, own.indices) and K.data.tobytes() == own.data.tobytes()
        Bd = B2[s.dofs].toarray()
        assert np.allclose(K.toarray(), (Bd * k2) @ Bd.T, rtol=1e-12, atol=1e-12)


def test_a_factor_is_held_once_after_its_compiled_solve():
    """The first solve with many right-hand sides flattens the factor for the compiled
    substitution (every later solve takes that path): the blocks are freed as they are
    copied, so the factor is held once, not twice (at 200k tets ~3 GB each), and the
    solution is K's."""
    import tracemalloc

    from harness.linalg.multifrontal import _subst_kernel

    if _subst_kernel() is None:
        pytest.skip("numba not installed: the LAPACK path keeps its blocks")
    prob = grid((12, 12, 12))
    s = max(prob.load_sets(), key=lambda s: s.B.shape[0])
    K, sym = s.stiffness(prob.k0 * 1.3), s.symbolic()
    rhs = np.random.default_rng(9).normal(size=(K.shape[0], 10))
    tracemalloc.start()
    try:
        f = MultifrontalCholesky(K, sym)
        size = sum(x.nbytes for x in f.L11) + sum(x.nbytes for x in f.L21)
        before = tracemalloc.get_traced_memory()[0]
        x = f.solve(rhs)
        after = tracemalloc.get_traced_memory()[0] - x.nbytes
    finally:
        tracemalloc.stop()
    assert after - before < 0.2 * size, (after - before, size)
    ref = spla.splu(K.tocsc()).solve(rhs)
    assert np.allclose(x, ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())
    one = f.solve(rhs[:, 0])  # a later solve of one column: the compiled path, blocks gone
    assert f.L11 is None and np.allclose(one, x[:, 0], rtol=1e-12, atol=1e-14 * abs(x).max())
