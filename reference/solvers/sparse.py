"""Linear solves of the constrained stiffness A x = b (symmetric positive definite, dofs
interleaved ``dim * node + component``): the project's multifrontal sparse Cholesky,
pyamg smoothed aggregation with the rigid-body modes as near-null space (preconditioner
of CG), Jacobi-preconditioned CG, or SuperLU (kept for checking).

A well-posed solve always finishes. Every method works on the equilibrated system
D^-1/2 A D^-1/2 (unit diagonal: nothing depends on the units of A, b or the
coordinates) and is accepted only when the true residual ||b - A x|| <= rtol ||b|| for
every right-hand side (rtol = RTOL, or the double-precision floor of an ill-conditioned
system, see FLOOR); otherwise the next method is tried: ``amg`` -> ``amg-strong``
(energy-minimising prolongation, two smoothing sweeps, more iterations) -> ``cholesky``
(-> ``superlu`` without coordinates). The iterative methods stop early once their
convergence rate cannot reach RTOL within their iteration budget. A singular or
non-finite system is one ModelError line.

Crossovers (``springbench bench reference`` measures them in one process,
results/bench/reference.csv; the measurements behind these numbers are in CHANGELOG.md):
the Cholesky wins up to ~300 Gflop (the 70k-dof cube: 23.5 s vs 25.9 s) and
always in 2-D and on thin or nearly incompressible bodies (where AMG needs its strong
setup); 'auto' therefore builds the Cholesky's symbolic factorisation (1-4 s at
50-150k dofs, reused by the factorisation) and factorises when it predicts <= 300 Gflop
and <= 2.5 GB, else starts with AMG (a 150k-dof 3-D cube: AMG, 0.9 GB). Without
coordinates SuperLU is the direct method, up to 15k dofs in 3-D (150k in 2-D). P2/Q2
systems handed their P1/Q1 subspace (reference/solvers/twolevel.py) take 'two-level' where 'auto'
would take AMG (the 50k-tet cylinder of ``bench calibrate``: 23 iterations, a third of
AMG's CPU time).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from harness.errors import ModelError
from harness.linalg.multifrontal import MultifrontalCholesky, Symbolic
from reference.solvers import tensorpre
from reference.solvers.plan import METHODS, SYMBOLIC_MAX, System, choose_plan
from reference.solvers.record import Fallback, SolveRecord

# relative residual an accepted solve reaches, ||b - A x|| <= RTOL ||b||: the direct
# solves (with one step of refinement) reach 1e-14..1e-12 on well-conditioned systems
# (nu = 0.3 cubes) and ~1e-9 on a 10:1 bar with nu = 0.49; the solution error
# (<= cond * residual relative in the worst case, far less for smooth loads) stays well
# below any discretisation error
RTOL = 1e-10
# ... unless double precision cannot reach it: the residual of an exact solution rounded
# to doubles is up to ~eps ||A|| ||x||, so a column is accepted at
# max(RTOL, FLOOR eps ||A||_inf ||x|| / ||b||), at most DIRECT_RTOL (nu = 0.49, 10:1
# bar, cond 4e7: the direct solves reach 6e-10, and eps ||A||_inf ||x|| / ||b|| = 5.6e-9;
# all three are invariant under A -> a A, b -> c b, i.e. under any choice of units)
FLOOR = 1.0
# the weakest residual a direct solve is accepted with (a worse one means singular)
DIRECT_RTOL = 1e-6
AMG_MAXITER = 300
STRONG_MAXITER = 1000
CG_MAXITER = 20_000
# after a failed AMG, 'amg-strong' is skipped when the Cholesky's estimated time
# (SECONDS_PER_GFLOP per Gflop of its symbolic estimate, measured 0.09-0.1 s on one
# core) is below twice the CPU time already spent, and otherwise gets that time as its
# budget, as long as the factor fits in FALLBACK_GBYTES
SECONDS_PER_GFLOP = 0.1
CHOLESKY_OVERHEAD = 1.0
FALLBACK_GBYTES = 6.0
TENSOR_MAXITER = (
    2000  # fast-diagonalisation PCG (reference/solvers/tensorpre.py): 100-300 iterations measured
)
TWO_LEVEL_MAXITER = 300


def equilibrated(A: sp.spmatrix, s: np.ndarray) -> sp.csr_matrix:
    """S A S with S = diag(s), as CSR (A's entries scaled in a copy, no products)."""
    A = sp.csr_matrix(A, copy=True)
    rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    A.data *= s[rows] * s[A.indices]
    return A


def accepted_rtol(normA: float, xnorm: np.ndarray, bnorm: np.ndarray) -> np.ndarray:
    """The relative residual each column is accepted at (see :data:`FLOOR`)."""
    return np.clip(FLOOR * np.finfo(float).eps * normA * xnorm / bnorm, RTOL, DIRECT_RTOL)


def _singular() -> ModelError:
    return ModelError("the stiffness matrix is singular", fix="check the constraints")


def solve(
    A: sp.spmatrix,
    b: np.ndarray,
    method: str = "auto",
    near_null: np.ndarray | None = None,
    *,
    coords: np.ndarray | None = None,
    records: list | None = None,
    coarse: sp.spmatrix | None = None,
    tensor=None,
) -> np.ndarray:
    """Solve A x = b (b (n,) or (n, m), all columns share one factorisation or one AMG
    hierarchy) for symmetric positive definite A; returns x shaped like b.

    ``method``: 'auto' (the plan of reference/solvers/plan.py: by the Cholesky's
    estimated cost), 'direct' = 'cholesky' (multifrontal; needs ``coords`` (n, dim) of the
    free dofs' locations, or recovers them from ``near_null``, else SuperLU), 'superlu',
    'amg' (with ``near_null`` (n, 3|6) rigid-body modes of the free dofs) or 'cg'. An
    iterative method that does not reach :data:`RTOL` falls back to a stronger AMG and
    then to the Cholesky. ``records``, when given, gets the solve's
    :class:`~reference.solvers.record.SolveRecord` (what solved it, the residual, the
    tolerance it was accepted at (see :data:`FLOOR`), the attempts before it).

    ``coarse`` (n, nc): the P1/Q1 fields of a P2/Q2 system's mesh in its free dofs
    (reference/solvers/twolevel.py ``prolongation``, rows of the free dofs); with it (and
    ``coords``) 'two-level' (CG, Gauss-Seidel and an exact P1 solve) replaces 'amg' as
    the iterative method of 'auto' and can be asked for by name.

    ``tensor``: z = P r, the fast-diagonalisation preconditioner of a Q2 system on a
    tensor mesh (reference/solvers/tensorpre.py); with it 'tensor' (and 'auto' from
    ``plan.TENSOR_MIN`` dofs) first tries CG with it, then falls back as 'auto' would
    without it. (A material of one elastic tensor never gets here on a tensor mesh:
    reference/solvers/tensorsolve.py solves it without assembling A.)"""
    t0 = time.perf_counter()
    if method not in METHODS:
        raise ValueError(f"unknown solver method {method!r} (one of {', '.join(METHODS)})")
    A = sp.csr_matrix(A, dtype=float)
    b = np.asarray(b, float)
    n = A.shape[0]
    b2 = b.reshape(n, -1)
    fallbacks: list[Fallback] = []
    estimate = None

    def done(x, method, residual=0.0, rtol=RTOL, iterations=0):
        if records is not None:
            records.append(
                SolveRecord(
                    method,
                    residual,
                    rtol,
                    iterations,
                    time.perf_counter() - t0,
                    tuple(fallbacks),
                    estimate,
                )
            )
        return x

    if not (np.all(np.isfinite(A.data)) and np.all(np.isfinite(b2))):
        raise _singular()
    d = A.diagonal()
    if n == 0:
        return done(np.zeros_like(b), "cholesky")
    if not np.all(d > 0):
        raise _singular()
    # equilibration: As = S A S, S = D^-1/2; A x = b  <=>  As y = S b, x = S y
    s = 1.0 / np.sqrt(d)
    As = equilibrated(A, s)
    bs = b2 * s[:, None]
    bnorm = np.linalg.norm(b2, axis=0)
    live = bnorm > 0
    x = np.zeros_like(b2)

    normA = float(np.max(abs(A) @ np.ones(n)))  # ||A||_inf >= ||A||_2 (symmetric)

    def residual(xs):
        """(max ||b - A x|| / ||b||, the largest ratio of a column's residual to its
        tolerance, the tolerance of the worst column) over the nonzero columns."""
        r = np.linalg.norm(b2[:, live] - A @ xs[:, live], axis=0) / bnorm[live]
        tol = accepted_rtol(normA, np.linalg.norm(xs[:, live], axis=0), bnorm[live])
        if not np.all(np.isfinite(r)):
            return np.inf, np.inf, RTOL
        return float(r.max()), float(np.max(r / tol)), float(tol[np.argmax(r / tol)])

    if not live.any():
        return done(x.reshape(b.shape), "cholesky" if method in ("auto", "direct") else method)
    dim = (
        near_null.shape[1] // 3 + 1
        if near_null is not None and near_null.shape[1] in (3, 6)
        else (coords.shape[1] if coords is not None else 3)
    )
    if coords is None and method in ("auto", "direct", "cholesky", "amg", "cg"):
        coords = _coords_from_modes(As, near_null)
    sym = None
    system = System(
        n,
        dim,
        method,
        coords=coords is not None,
        coarse=coarse is not None,
        tensor=tensor is not None,
        nnz=A.nnz,
    )
    plan = choose_plan(system)
    if plan.needs_estimate:  # the Cholesky's cost from its symbolic factorisation (reused)
        sym = _symbolic(As, coords)
        estimate = _estimate(sym)
        plan = choose_plan(dataclasses.replace(system, estimate=estimate))
    plan = list(plan.steps)
    Bs = (
        None
        if near_null is None
        else np.asarray(near_null, float).reshape(n, -1) * np.sqrt(d)[:, None]
    )
    spent = 0.0  # CPU seconds of the failed attempts
    for m in plan:
        t1, c1 = time.perf_counter(), time.process_time()
        budget = None
        if m == "amg-strong" and plan[-1] == "cholesky":
            # a stronger AMG only while it can beat the Cholesky it would fall back to
            if sym is None and n <= SYMBOLIC_MAX[dim]:
                sym = _symbolic(As, coords)
                estimate = _estimate(sym)
            if sym is not None and estimate["gbytes"] <= FALLBACK_GBYTES:
                chol = SECONDS_PER_GFLOP * estimate["gflop"] + CHOLESKY_OVERHEAD
                if chol < 2 * spent:
                    continue
                budget = chol
        try:
            if m in ("cholesky", "superlu"):
                if m == "cholesky" and sym is None:
                    sym = _symbolic(As, coords)
                f = _factor(As, m, sym)
                y, its, why = f(bs[:, live]), 0, ""
            elif m == "two-level":
                y, its, why = _two_level(As, bs[:, live], s, coarse, coords, Bs, normA, bnorm[live])
            elif m == "tensor":
                y, its, why = tensorpre.cg(As, bs[:, live], s, tensor, _pcg, RTOL, TENSOR_MAXITER)
            else:
                y, its, why = _iterative(As, bs[:, live], m, Bs, budget)
        except ModelError:
            raise _singular() from None
        xs = np.zeros_like(b2)
        xs[:, live] = y * s[:, None]
        res, ratio, tol = residual(xs) if np.all(np.isfinite(xs)) else (np.inf, np.inf, RTOL)
        if m in ("cholesky", "superlu") and np.isfinite(res) and res > RTOL / 100:
            # one step of iterative refinement with the same factor
            xs2 = xs.copy()
            xs2[:, live] += f((b2[:, live] - A @ xs[:, live]) * s[:, None]) * s[:, None]
            res2 = residual(xs2)
            if res2[0] < res:
                xs, (res, ratio, tol) = xs2, res2
        f = None
        if ratio <= 1 or (m in ("cholesky", "superlu") and res <= DIRECT_RTOL):
            return done(xs.reshape(b.shape), m, res, tol, its)
        if m in ("cholesky", "superlu"):
            raise _singular()
        fallbacks.append(
            Fallback(m, res, why or f"residual above {tol:.1e}", time.perf_counter() - t1)
        )
        spent += time.process_time() - c1
    return done(x.reshape(b.shape), "none")  # not reached: the plan ends with a direct solve


# -- direct ------------------------------------------------------------------------------


def _symbolic(As, coords):
    return Symbolic(As, coords)


def _estimate(sym) -> dict:
    """Work (Gflop) and peak memory (GB) of the multifrontal Cholesky (``Symbolic.estimate``)."""
    return sym.estimate()


def _factor(As, method, sym):
    """Factorise As (Cholesky on the Symbolic ``sym``); returns the solve function for
    (n, m) right-hand sides."""
    if method == "cholesky":
        f = MultifrontalCholesky(As, sym)
        return lambda r: f.solve(np.ascontiguousarray(r)).reshape(r.shape)
    try:
        lu = spla.splu(As.tocsc(), permc_spec="COLAMD")
    except RuntimeError:  # exactly singular
        raise _singular() from None
    u = np.abs(lu.U.diagonal())
    if not np.all(np.isfinite(u)) or u.min() < 1e-14 * u.max():
        raise _singular()
    return lambda r: lu.solve(np.ascontiguousarray(r)).reshape(r.shape)


INVERSE_GBYTES = (
    6.0  # memory the shift-invert Cholesky may take (beyond it: the two-level CG below)
)
INVERSE_RTOL = 1e-11  # relative residual of each shift-invert solve by the two-level CG


def inverse(A: sp.spmatrix, coords: np.ndarray, coarse: sp.spmatrix | None = None):
    """A solve function r -> A^-1 r: the shift-invert operator of the modal solves. The
    multifrontal Cholesky when its symbolic estimate fits in INVERSE_GBYTES; else, given
    the P1/Q1 subspace ``coarse`` of a P2/Q2 system, CG with the two-level preconditioner
    (reference/solvers/twolevel.py, set up once) to INVERSE_RTOL; else None (eigsh's own SuperLU:
    over 10 minutes on a 108k-dof Q2 box, past 12 GB on a 152k-dof one)."""
    As = sp.csr_matrix(A)
    sym = _symbolic(As, coords)
    if _estimate(sym)["gbytes"] <= INVERSE_GBYTES:
        try:
            return _factor(As, "cholesky", sym)
        except ModelError:  # not positive definite: leave it to eigsh's own factorisation
            return None
    return None if coarse is None else _two_level_inverse(As, coords, coarse)


def _two_level_inverse(As, coords, coarse):
    from reference.solvers import twolevel

    s = 1.0 / np.sqrt(As.diagonal())
    Ass = equilibrated(As, s)
    M = twolevel.TwoLevel(Ass, s, coarse, coords)

    def solve(r):
        r = np.asarray(r, float)
        r2 = r.reshape(len(s), -1)
        bn = np.linalg.norm(r2, axis=0)
        y, _, why = twolevel.pcg(
            Ass, s[:, None] * r2, M, 1.0 / s, lambda Y: INVERSE_RTOL * bn, TWO_LEVEL_MAXITER
        )
        if why:
            raise ModelError(
                f"the modal solve's shift-invert CG failed: {why}",
                field="reference.modes",
                fix="fewer reference levels (max_refine) or modes = 0",
            )
        return (s[:, None] * y).reshape(r.shape)

    return solve


def _coords_from_modes(A, near_null):
    """Locations of the free dofs (up to scale and shift: enough for the nested
    dissection) read off the rigid-body modes ``Discretisation.rigid_modes`` builds:
    translations first (column c is 1 on the dofs of component c), then rotations, which
    hold the coordinates (2-D: [-y, x]; 3-D: [-y, x, 0], [0, -z, y], [-z, 0, x]). A
    coordinate a dof's modes do not carry is the mean over its graph neighbours that
    carry it. None if the modes do not look like that."""
    if near_null is None:
        return None
    R = np.asarray(near_null, float)
    n = R.shape[0]
    if R.ndim != 2 or R.shape[1] not in (3, 6):
        return None
    dim = 2 if R.shape[1] == 3 else 3
    T = R[:, :dim]
    if not (np.all((T == 0) | (T == 1)) and np.all(T.sum(axis=1) == 1)):
        return None
    comp = np.argmax(T, axis=1)
    X = np.zeros((n, dim))
    known = np.zeros((n, dim), bool)
    # (mode column, component, coordinate, sign): mode value = sign * coordinate
    table = (
        [(2, 0, 1, -1), (2, 1, 0, 1)]
        if dim == 2
        else [(3, 0, 1, -1), (3, 1, 0, 1), (4, 1, 2, -1), (4, 2, 1, 1), (5, 0, 2, -1), (5, 2, 0, 1)]
    )
    for col, c, j, sign in table:
        on = comp == c
        X[on, j] = sign * R[on, col]
        known[on, j] = True
    G = sp.csr_matrix((np.ones(A.nnz), A.indices, A.indptr), shape=A.shape)
    for _ in range(3):
        if known.all():
            break
        num, cnt = G @ (X * known), G @ known.astype(float)
        fill = ~known & (cnt > 0)
        X[fill] = num[fill] / cnt[fill]
        known |= fill
    return X


# -- iterative ---------------------------------------------------------------------------


def _two_level(As, bs, s, coarse, coords, Bs, normA, bnorm):
    """reference/solvers/twolevel.py's CG on every column at once, each to the residual
    ``solve`` accepts (RTOL, or the floor of the column's solution, halved for margin)."""
    from reference.solvers import twolevel

    try:
        M = twolevel.TwoLevel(As, s, coarse, coords, Bs)
    except Exception as exc:  # noqa: BLE001 - a failed setup is a failed attempt
        return np.full_like(bs, np.nan), 0, f"two-level setup failed: {exc}"

    def target(Y):
        xn = np.linalg.norm(Y * s[:, None], axis=0)
        return (
            0.5
            * np.clip(FLOOR * np.finfo(float).eps * normA * xn / bnorm, RTOL, DIRECT_RTOL)
            * bnorm
        )

    return twolevel.pcg(As, bs, M, 1.0 / s, target, TWO_LEVEL_MAXITER)


def _hierarchy(As, Bs, strong: bool):
    import pyamg

    if not strong:
        return pyamg.smoothed_aggregation_solver(As, B=Bs, symmetry="hermitian")
    smoother = ("gauss_seidel", {"sweep": "symmetric", "iterations": 2})
    return pyamg.smoothed_aggregation_solver(
        As,
        B=Bs,
        symmetry="hermitian",
        strength=("symmetric", {"theta": 0.0}),
        smooth=("energy", {"krylov": "cg", "maxiter": 4, "degree": 2, "weighting": "local"}),
        improve_candidates=[("gauss_seidel", {"sweep": "symmetric", "iterations": 4})] * 2 + [None],
        presmoother=smoother,
        postsmoother=smoother,
        max_coarse=500,
    )


def _iterative(As, bs, method, Bs, budget=None):
    """CG preconditioned by one AMG V-cycle ('amg', 'amg-strong') or Jacobi ('cg'; the
    diagonal of As is 1) on every column; (y, most iterations, reason of a failure).
    ``budget``: CPU seconds (setup included) after which it is not worth continuing."""
    c0 = time.process_time()
    if method == "cg":
        M, maxiter = None, min(20 * As.shape[0], CG_MAXITER)
    else:
        try:
            ml = _hierarchy(As, Bs, method == "amg-strong")
        except Exception as exc:  # noqa: BLE001 - a failed setup is a failed attempt
            return np.full_like(bs, np.nan), 0, f"AMG setup failed: {exc}"
        M = ml.aspreconditioner(cycle="V")
        maxiter = AMG_MAXITER if method == "amg" else STRONG_MAXITER
    Y, its, why = np.zeros_like(bs), 0, ""
    for j in range(bs.shape[1]):
        left = None if budget is None else budget - (time.process_time() - c0)
        Y[:, j], k, w = _pcg(As, bs[:, j], M, RTOL / 4, maxiter, 20 if M is not None else 200, left)
        its, why = max(its, k), why or w
    return Y, its, why


def _pcg(A, b, M, rtol, maxiter, window=20, seconds=None):
    """Preconditioned CG to ||b - A x|| <= rtol ||b|| (recursive residual; the caller
    checks the true one). Gives up when the iteration budget runs out or the rate of the
    last ``window`` iterations cannot reach rtol within it (or within ``seconds`` CPU).
    Returns (x, iterations, reason)."""
    c0 = time.process_time()
    x = np.zeros_like(b)
    r = b.copy()
    nb = np.linalg.norm(b)
    z = r if M is None else M @ r
    p = z.copy()
    rz = r @ z
    hist = [1.0]
    if not rz > 0:
        return x, 0, "breakdown (the preconditioner is not positive definite)"
    for k in range(1, maxiter + 1):
        Ap = A @ p
        pAp = p @ Ap
        if not np.isfinite(pAp) or pAp <= 0:
            return x, k, "breakdown (the matrix or the preconditioner is not positive definite)"
        a = rz / pAp
        x += a * p
        r -= a * Ap
        rel = np.linalg.norm(r) / nb
        hist.append(rel)
        if rel <= rtol:
            return x, k, ""
        if k >= 2 * window and k % 10 == 0:  # rate of the best residual over the window
            rate = (min(hist[-window:]) / min(hist[:-window])) ** (1 / window)
            more = np.log(rtol / rel) / np.log(rate) if rate < 1 else np.inf
            if more > maxiter - k:
                return x, k, f"too slow (rate {rate:.3f} per iteration at {k} iterations)"
            if seconds is not None and more * (time.process_time() - c0) / k > seconds - (
                time.process_time() - c0
            ):
                return (
                    x,
                    k,
                    f"too slow ({k} iterations, ~{more:.0f} more would take longer than the "
                    "Cholesky)",
                )
        z = r if M is None else M @ r
        rz_new = r @ z
        if not rz_new > 0:
            return x, k, "breakdown (the preconditioner is not positive definite)"
        p = z + (rz_new / rz) * p
        rz = rz_new
    return x, maxiter, f"no convergence in {maxiter} iterations"
