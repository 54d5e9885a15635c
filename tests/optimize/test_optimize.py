"""FitProblem and the optimiser registry, against independent dense computations and
recoverable problems (reference = displacements of known perturbed constants, best G = 0)."""

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp

from harness.errors import SpringbenchError
from harness.linalg.sparse import Factor, nested_dissection, single_thread_blas
from harness.optimize import OPTIMIZERS, FitProblem, optimize
from harness.optimize.synthetic import basic_loads, grid_network, recoverable_problem


@pytest.fixture(autouse=True)
def _one_blas_thread():
    """Dense BLAS threads oversubscribe the shared cores (and optimize() uses one)."""
    with single_thread_blas():
        yield


def dense_incidence(points, springs):
    """b_e (ndof, e) written out spring by spring: the unit direction at node j, minus it
    at node i (dof = dim * node + component), so b_e . u is the elongation of spring e."""
    n, dim = points.shape
    Bd = np.zeros((n * dim, len(springs)))
    for e, (i, j) in enumerate(springs):
        d = points[j] - points[i]
        d = d / np.linalg.norm(d)
        Bd[j * dim : (j + 1) * dim, e] = d
        Bd[i * dim : (i + 1) * dim, e] = -d
    return Bd


def dense_G(points, springs, k, frees, forces, u_ref, w):
    """Independent G: K = sum_e k_e b_e b_e^T in a dense matrix, numpy solve."""
    n, dim = points.shape
    Bd = dense_incidence(points, springs)
    K = (Bd * k) @ Bd.T
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
    u_ref = rng.normal(size=forces.shape)  # arbitrary reference: constrained dofs count too
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
    assert np.max(np.abs(res.k / k_true - 1)) < 1e-5  # all constants identifiable here
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
        FitProblem.from_network(
            pts, spr, -np.ones(len(spr)), frees, forces, forces, np.ones(pts.size), names
        )
    with pytest.raises(SpringbenchError, match="names"):
        FitProblem.from_network(
            pts, spr, np.ones(len(spr)), frees, forces, forces, np.ones(pts.size), names[:2]
        )


@pytest.mark.parametrize("shape, big", [((34, 34), None), ((9, 9, 9), None), ((9, 9, 9), 1)])
def test_multifrontal_cholesky_matches_direct_solve(shape, big, monkeypatch):
    """Against SuperLU; ``big`` = 1: every front takes the threaded path (BLAS threads
    restored inside the single-thread block), which must give the same factor."""
    import scipy.sparse.linalg as spla

    from harness.linalg import multifrontal
    from harness.linalg.multifrontal import MultifrontalCholesky, Symbolic

    if big is not None:
        monkeypatch.setattr(multifrontal, "BIG_FRONT", big)
    prob, _ = recoverable_problem(shape, seed=3)
    for s in prob.load_sets()[:2]:
        k = prob.k0 * np.random.default_rng(0).uniform(0.5, 2, prob.n_springs)
        K = s.stiffness(k)
        F = MultifrontalCholesky(K, Symbolic(K, s.coords, leaf=40))
        rhs = np.random.default_rng(1).normal(size=(K.shape[0], 3))
        ref = spla.splu(K.tocsc()).solve(rhs)
        assert np.allclose(F.solve(rhs), ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())
        assert np.allclose(F.solve(rhs[:, 0]), ref[:, 0], rtol=1e-9, atol=1e-12 * np.abs(ref).max())


# --- equilibrium gap (equation error) ------------------------------------------------------
def dense_equation_error(points, springs, k0, frees, forces, u_ref, w):
    """Independent A, b of the equilibrium gap: for each load, the free rows of
    sum_e x_e k0_e b_e (b_e . u*) - f, built spring by spring in dense arrays, each load's
    rows weighted by sqrt(w) / rms(f) (the documented weighting)."""
    Bd = dense_incidence(points, springs)
    rows, rhs = [], []
    for free, f, u in zip(frees, forces, u_ref):
        u0 = np.where(free, u, 0.0)  # the model's u is 0 on constrained dofs
        Bu = Bd.T @ u0  # spring elongations of u*
        sw = np.sqrt(w[free]) / np.sqrt(np.mean(f[free] ** 2))
        rows.append(sw[:, None] * (Bd[free] * (k0 * Bu)[None, :]))
        rhs.append(sw * f[free])
    return np.vstack(rows), np.concatenate(rhs)


@pytest.mark.parametrize("shape", [(4, 3), (3, 3, 2)])
def test_equilibrium_gap_matches_dense_lstsq(shape):
    from harness.optimize.equilibrium import equilibrium_gap_factors

    pts, spr, _ = grid_network(shape)
    names, frees, forces = basic_loads(pts)
    rng = np.random.default_rng(7)
    k0 = rng.uniform(0.5, 2.0, len(spr))
    k_true = k0 * rng.uniform(0.7, 1.4, len(spr))
    from harness.optimize.synthetic import solve_network

    u_ref = solve_network(pts, spr, k_true, frees, forces)
    # not representable: a real least squares
    u_ref = u_ref * (1 + 0.02 * rng.standard_normal(u_ref.shape))
    w = rng.uniform(1, 3, pts.size)
    prob = FitProblem.from_network(pts, spr, k0, frees, forces, u_ref, w, names, bounds=(1e-6, 1e6))
    A, b = dense_equation_error(pts, spr, k0, frees, forces, u_ref, w)
    seen = np.linalg.norm(A, axis=0) > 0
    ref = np.ones(len(k0))
    ref[seen] = np.linalg.lstsq(A[:, seen], b, rcond=None)[0]
    assert np.linalg.matrix_rank(A[:, seen]) == seen.sum()  # identifiable: a unique answer
    x, info = equilibrium_gap_factors(prob, {"reg": 1e-14, "rtol": 1e-13})
    assert info["eg_clipped"] == 0 and np.all(ref > 0)
    assert np.allclose(x, ref, rtol=1e-6, atol=1e-8)


@pytest.mark.parametrize("shape,grouped", [((12, 10), False), ((4, 4, 3), False), ((6, 6), True)])
def test_equilibrium_gap_recovers_identifiable_constants(shape, grouped):
    prob, k_true = recoverable_problem(shape, sigma=0.3, seed=11, grouped=grouped, diagonals="face")
    res = optimize(prob, "equilibrium-gap", {}, seed=0)
    assert res.G_final / res.G_initial <= 1e-7
    assert res.G_final == pytest.approx(prob.G(res.k), rel=1e-9, abs=1e-12 * res.G_initial)
    # springs some load stretches and that touch a free dof (else the equation error has no
    # column for them), from an independent solve and dense incidence
    from harness.optimize.synthetic import solve_network

    pts, spr, _ = grid_network(shape, diagonals="face")
    _, frees, forces = basic_loads(pts, s=float(np.prod(shape)) ** (1 / len(shape)))
    Bd = dense_incidence(pts, spr)
    U = solve_network(pts, spr, k_true, frees, forces)
    seen = np.zeros(len(spr), bool)
    for free, u in zip(frees, U):
        seen |= (np.abs(Bd.T @ u) > 1e-12 * np.abs(u).max()) & (np.abs(Bd[free]).sum(0) > 0)
    assert seen.sum() > 0.5 * len(spr)
    x = res.k / prob.k0
    xt = k_true / prob.k0
    if grouped:
        n = np.bincount(prob.groups)
        x, xt, seen = (
            np.bincount(prob.groups, x) / n,
            np.bincount(prob.groups, xt) / n,
            np.bincount(prob.groups, seen) > 0,
        )
    assert np.max(np.abs(x[seen] / xt[seen] - 1)) < 1e-6
    assert np.allclose(x[~seen], 1.0)  # unseen: left at k0


def test_init_equilibrium_gap_then_output_error_refines_a_noisy_reference():
    """With a reference the network cannot reproduce, the equation-error estimate is not
    the minimum of G: gauss-newton and lbfgs started from it must lower G further, and never
    end above it or above the pure runs' starting G."""
    prob, k_true = recoverable_problem((6, 6), sigma=0.3, seed=3)
    rng = np.random.default_rng(5)
    noisy = prob.with_reference(
        [b.u_ref * (1 + 0.003 * rng.standard_normal(b.u_ref.shape)) for b in prob.blocks]
    )
    eg = optimize(noisy, "equilibrium-gap", {}, seed=0)
    assert eg.G_final < eg.G_initial
    for method in ("gauss-newton", "lbfgs"):
        res = optimize(noisy, method, {"init": "equilibrium-gap", "maxiter": 60}, seed=0)
        assert res.info["init"] == "equilibrium-gap"
        assert res.G_initial == pytest.approx(eg.G_initial)  # G0 stays G(k0)
        assert res.G_final < 0.99 * eg.G_final
        assert res.G_final == pytest.approx(noisy.G(res.k), rel=1e-9)
    with pytest.raises(SpringbenchError, match="init"):
        optimize(noisy, "lbfgs", {"init": "sa"}, seed=0)
    with pytest.raises(SpringbenchError, match="unknown equilibrium-gap option"):
        optimize(noisy, "equilibrium-gap", {"target": 1e-3}, seed=0)


def test_gauss_newton_stops_converged_at_the_noise_floor():
    """On a noisy reference the best G is unknown but at most G(k_true), the fit of the true
    constants (more parameters than the noise's degrees of freedom can only fit part of it):
    gauss-newton must end below that floor and say "converged" long before maxiter; with
    ftol = 0 it runs on (until maxiter or until no step descends) and gains less than 1e-6
    relative after the converged stop."""
    from harness.optimize.synthetic import noisy

    prob, k_true = recoverable_problem((12, 12), sigma=0.1, seed=2, diagonals="face")
    p = noisy(prob, 1e-4, seed=7)
    floor = p.G(k_true)
    res = optimize(p, "gauss-newton", {"init": "equilibrium-gap", "maxiter": 200}, seed=0)
    assert res.info["stop"] == "converged" and res.info["iterations"] < 100
    assert res.G_final < floor
    longer = optimize(
        p,
        "gauss-newton",
        {"init": "equilibrium-gap", "maxiter": res.info["iterations"] + 15, "ftol": 0.0},
        seed=0,
    )
    # ran on (to maxiter or to no-descent)
    assert longer.info["iterations"] > res.info["iterations"]
    assert longer.G_final >= res.G_final * (1 - 1e-6)


def test_with_reference_equals_a_fresh_problem():
    pts, spr, _ = grid_network((5, 4))
    names, frees, forces = basic_loads(pts)
    rng = np.random.default_rng(2)
    k0 = rng.uniform(0.5, 2.0, len(spr))
    u1, u2 = rng.normal(size=forces.shape), rng.normal(size=forces.shape)
    u2 = np.where(frees, u2, 0.0)
    w = np.ones(pts.size)
    p1 = FitProblem.from_network(pts, spr, k0, frees, forces, u1, w, names)
    p1.load_sets()
    p2 = p1.with_reference([u[f] for u, f in zip(u2, frees)])
    fresh = FitProblem.from_network(pts, spr, k0, frees, forces, u2, w, names)
    k = rng.uniform(0.5, 2.0, len(spr))
    assert p2.G(k) == pytest.approx(dense_G(pts, spr, k, frees, forces, u2, w), rel=1e-10)
    assert p2.G(k) == pytest.approx(fresh.G(k), rel=1e-12)
    # p1 untouched
    assert p1.G(k) == pytest.approx(dense_G(pts, spr, k, frees, forces, u1, w), rel=1e-10)
    with pytest.raises(SpringbenchError, match="references"):
        p1.with_reference([u2[0][frees[0]]])


def test_a_start_worse_than_k0_is_rejected():
    """Equation error amplifies displacement noise (it differences neighbouring nodes): with
    5 % noise the equilibrium-gap estimate is worse than k0, so the optimisers it starts
    must fall back to k0 and still end below G(k0)."""
    prob, _ = recoverable_problem((6, 6), sigma=0.3, seed=3)
    rng = np.random.default_rng(5)
    noisy = prob.with_reference(
        [b.u_ref * (1 + 0.05 * rng.standard_normal(b.u_ref.shape)) for b in prob.blocks]
    )
    eg = optimize(noisy, "equilibrium-gap", {}, seed=0)
    assert eg.info["stop"] == "worse than k0" and np.array_equal(eg.k, noisy.k0)
    for method in ("gauss-newton", "lbfgs"):
        res = optimize(noisy, method, {"init": "equilibrium-gap", "maxiter": 30}, seed=0)
        assert res.info.get("init_rejected") is True
        assert res.G_final < 0.9 * res.G_initial


def test_per_matrix_values_are_made_once_and_dropped_with_their_matrix():
    import gc

    import scipy.sparse as sp

    from harness.optimize import permatrix as pm

    B = sp.random(30, 40, 0.2, format="csc", random_state=0)
    made = []
    for _ in range(3):
        assert pm.per_matrix(B, "x", lambda: made.append(1) or len(made)) == 1
    assert made == [1] and id(B) in pm._PER_MATRIX
    key = id(B)
    del B
    gc.collect()
    assert key not in pm._PER_MATRIX


def test_subsets_share_the_stiffness_map_and_match_a_fresh_problem():
    from harness.optimize import permatrix as pm
    from harness.optimize import select as sel

    prob, _ = recoverable_problem((34, 34))
    k = prob.k0 * np.random.default_rng(0).uniform(0.5, 2, prob.n_springs)
    whole = prob.G2(k)
    part = sel.subset(prob, [0])
    # fresh matrices, no network: nothing shared, each set's own map k -> K
    again = FitProblem(
        tuple(dataclasses.replace(b, B=b.B.copy(), network=None) for b in part.blocks),
        part.k0,
        None,
        part.bounds,
        None,
        part.coords,
    )
    assert (
        part.load_sets()[0].stiffness(k).data.tobytes()
        == again.load_sets()[0].stiffness(k).data.tobytes()
    )
    assert part.G2(k) == again.G2(k) and 0 < part.G2(k) <= whole
    shared = part.load_sets()[0].B
    # built once, shared: the network's one map, restricted to the set's dofs
    assert shared is prob.load_sets()[0].B and "gather" in pm._PER_MATRIX[id(shared)][1]
    network = part.blocks[0].network
    assert "kmap" in pm._PER_MATRIX[id(network)][1] and "kmap" not in pm._PER_MATRIX[id(shared)][1]


def test_the_symbolic_factorisation_needs_the_pattern_alone():
    """A load set's ordering and fronts come from B B^T's pattern (stiffness_pattern) without
    building the map k -> K: the same pattern as the map's, the same symbolic factorisation
    as from K itself, and the same solution bit for bit; the map is built only to factorise."""
    from harness.linalg.multifrontal import MultifrontalCholesky, Symbolic
    from harness.linalg.stiffness import stiffness_map, stiffness_pattern
    from harness.optimize import permatrix as pm
    from harness.optimize import problem as pr

    prob, _ = recoverable_problem((6, 6, 6))
    s = dataclasses.replace(prob.load_sets()[0])
    s.B = s.B.copy()  # a matrix nothing has factorised yet
    assert s.B.shape[0] > pr.DENSE_FACTOR_MAX
    pattern, _ = stiffness_map(s.B)
    alone = stiffness_pattern(s.B)
    assert np.array_equal(alone.indptr, pattern.indptr)
    assert np.array_equal(alone.indices, pattern.indices)
    sym = s.symbolic()
    assert "kmap" not in pm._PER_MATRIX[id(s.B)][1]  # no map for a symbolic alone
    k = prob.k0 * np.random.default_rng(1).uniform(0.5, 2, prob.n_springs)
    from_k = Symbolic(s.stiffness(prob.k0), s.coords)
    assert np.array_equal(sym.order, from_k.order)
    assert [len(n["U"]) for n in sym.nodes] == [len(n["U"]) for n in from_k.nodes]
    K = s.stiffness(k)
    a = MultifrontalCholesky(K, sym).solve(s.F)
    b = MultifrontalCholesky(K, from_k).solve(s.F)
    assert np.array_equal(a, b)
    dense = np.linalg.solve(K.toarray(), s.F)  # an independent solve
    assert np.allclose(a.reshape(dense.shape), dense, rtol=1e-9, atol=1e-12 * abs(dense).max())


@pytest.mark.parametrize("block", [1, 50, 10**9])
def test_the_stiffness_map_built_in_blocks_is_the_same_map(block, monkeypatch):
    """K.data = P k built over blocks of columns (bounded temporaries): the same P bit for
    bit whatever the block, and K = B diag(k) B^T against a dense product."""
    from harness.linalg import stiffness as st

    rng = np.random.default_rng(3)
    n, e = 60, 400
    rows = np.concatenate([rng.choice(n, 2 + j % 9, replace=False) for j in range(e)])
    cols = np.repeat(np.arange(e), [2 + j % 9 for j in range(e)])
    B = sp.csc_matrix((rng.standard_normal(len(rows)), (rows, cols)), shape=(n, e))
    _, whole = st.stiffness_map(B)
    monkeypatch.setattr(st, "PAIRS_PER_BLOCK", block)
    pattern, P = st.stiffness_map(B)
    for a in ("data", "indices", "indptr"):
        assert np.array_equal(getattr(P, a), getattr(whole, a))
    k = rng.uniform(0.5, 2.0, e)
    K = pattern.copy()
    K.data = P @ k
    dense = B.toarray() @ np.diag(k) @ B.toarray().T
    assert np.allclose(K.toarray(), dense, rtol=1e-13, atol=1e-13 * abs(dense).max())


def test_an_evaluation_holds_one_factorisation_at_a_time(monkeypatch):
    """G2, the gradient and the solves factorise load set after load set and drop each
    factorisation before the next (at 200k tets one is ~1-3 GB): when a factorisation
    starts, none of the earlier ones is alive."""
    import gc
    import weakref

    from harness.optimize import problem as pr
    from harness.optimize.evaluation import value_and_grad
    from harness.optimize.synthetic import recoverable_problem

    prob, _ = recoverable_problem((8, 8, 8), seed=5)
    assert len(prob.solve_parts()) >= 2
    alive, refs = [], []
    real = pr.LoadSet.factor

    def factor(self, k, kind="auto"):
        gc.collect()
        alive.append(sum(r() is not None for r in refs))
        f = real(self, k, kind)
        refs.append(weakref.ref(f))
        return f

    monkeypatch.setattr(pr.LoadSet, "factor", factor)
    value_and_grad(prob, prob.k0 * 1.2)
    prob.solve(prob.k0)
    assert len(alive) == 2 * len(prob.solve_parts()) and max(alive) == 0
