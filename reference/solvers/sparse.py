"""Linear solves of the constrained stiffness A x = b (symmetric positive definite, dofs
interleaved ``dim * node + component``): the project's multifrontal sparse Cholesky,
pyamg smoothed aggregation with the rigid-body modes as near-null space (preconditioner
of CG), Jacobi-preconditioned CG, or SuperLU (kept for checking).

A well-posed solve always finishes. Every step works on the equilibrated system
D^-1/2 A D^-1/2 (unit diagonal: nothing depends on the units of A, b or the
coordinates) and is accepted only when the true residual ||b - A x|| <= rtol ||b|| for
every right-hand side (rtol = RTOL, or the double-precision floor of an ill-conditioned
system, see FLOOR); otherwise the plan's next step is tried: ``amg`` -> ``amg-strong``
(energy-minimising prolongation, two smoothing sweeps, more iterations) -> ``cholesky``
(-> ``superlu`` without coordinates). The iterative steps stop early once their
convergence rate cannot reach RTOL within their iteration budget. A singular or
non-finite system is one ModelError line.

Which step comes first is reference/solvers/plan.py's choice (every crossover is there).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from harness.errors import ModelError
from harness.linalg.multifrontal import MultifrontalCholesky, Symbolic
from harness.linalg.sparse import seeded_numpy
from harness.registry import SOLVERS
from reference.solvers import tensorpre
from reference.solvers.dofcoords import coords_from_modes
from reference.solvers.krylov import pcg as _pcg
from reference.solvers.krylov import sa_hierarchy
from reference.solvers.plan import SYMBOLIC_MAX, System, choose_plan
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
# after a failed iterative step, 'amg-strong' is skipped when the Cholesky's work (its
# symbolic estimate's Gflop plus CHOLESKY_OVERHEAD_GFLOP) is below twice the work the failed
# steps did, and otherwise gets that work as its budget, as long as the factor fits in
# FALLBACK_GBYTES. The work is counted, never timed (the same choice on a busy machine): a
# step's iterations (plus SETUP_ITERATIONS for its preconditioner) times A's nonzeros times
# its cost per nonzero and iteration, in Gflop of the Cholesky's that take the same CPU time
# (one core, a 42k-dof P2 bar: the Cholesky ~0.1 s per Gflop; a CG iteration with an AMG
# V-cycle 22 ns per nonzero, with the strong one 36 ns, the setup ~8 iterations; the
# two-level ~23 ns per nonzero and load, plan.py; Jacobi and the tensor preconditioner
# taken as a few matrix products)
GFLOP_PER_NONZERO = {
    "amg": 2.2e-7,
    "amg-strong": 3.6e-7,
    "two-level": 2.3e-7,
    "cg": 3e-8,
    "tensor": 1e-7,
}
SETUP_ITERATIONS = 8
CHOLESKY_OVERHEAD_GFLOP = 10.0
FALLBACK_GBYTES = 6.0
# fast-diagonalisation PCG (reference/solvers/tensorpre.py): 100-300 iterations measured
TENSOR_MAXITER = 2000
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
    solver: str = "auto",
    near_null: np.ndarray | None = None,
    *,
    coords: np.ndarray | None = None,
    records: list | None = None,
    coarse: sp.spmatrix | None = None,
    tensor=None,
) -> np.ndarray:
    """Solve A x = b (b (n,) or (n, m), all columns share one factorisation or one AMG
    hierarchy) for symmetric positive definite A; returns x shaped like b.

    ``solver`` (a name of ``harness.registry.SOLVERS``): 'auto' (the plan of
    reference/solvers/plan.py: by the Cholesky's estimated cost), 'direct' = 'cholesky'
    (multifrontal; needs ``coords`` (n, dim) of the free dofs' locations, or recovers them
    from ``near_null``, else SuperLU), 'superlu', 'amg' (with ``near_null`` (n, 3|6)
    rigid-body modes of the free dofs) or 'cg'. An iterative step that does not reach
    :data:`RTOL` falls back to a stronger AMG and then to the Cholesky. ``records``, when
    given, gets the solve's :class:`~reference.solvers.record.SolveRecord` (the step that
    solved it, the residual, the tolerance it was accepted at (see :data:`FLOOR`), the
    steps before it).

    ``coarse`` (n, nc): the P1/Q1 fields of a P2/Q2 system's mesh in its free dofs
    (reference/solvers/twolevel.py ``prolongation``, rows of the free dofs); with it (and
    ``coords``) 'two-level' (CG, Gauss-Seidel and an exact P1 solve) replaces 'amg' as
    the iterative step of 'auto' and can be asked for by name.

    ``tensor``: z = P r, the fast-diagonalisation preconditioner of a Q2 system on a
    tensor mesh (reference/solvers/tensorpre.py); with it 'tensor' (and 'auto' from
    ``plan.TENSOR_MIN`` dofs) first tries CG with it, then falls back as 'auto' would
    without it. (A material of one elastic tensor never gets here on a tensor mesh:
    reference/solvers/tensorsolve.py solves it without assembling A.)"""
    run = _Run(time.perf_counter(), records, coarse=coarse, tensor=tensor)
    if solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r} (one of {', '.join(SOLVERS)})")
    A = sp.csr_matrix(A, dtype=float)
    b = np.asarray(b, float)
    n = A.shape[0]
    b2 = b.reshape(n, -1)
    if not (np.all(np.isfinite(A.data)) and np.all(np.isfinite(b2))):
        raise _singular()
    d = A.diagonal()
    if n == 0:
        return run.done(np.zeros_like(b), "cholesky")
    if not np.all(d > 0):
        raise _singular()
    eq = _Equilibrated.of(A, b2, d)
    if not eq.live.any():
        return run.done(np.zeros_like(b), "cholesky" if solver in ("auto", "direct") else solver)
    steps = _steps(eq, run, solver, near_null, coords)
    if near_null is not None:
        run.Bs = np.asarray(near_null, float).reshape(n, -1) * np.sqrt(d)[:, None]
    return _try_steps(steps, eq, run).reshape(b.shape)


def _steps(eq: _Equilibrated, run: _Run, solver: str, near_null, coords) -> tuple[str, ...]:
    """The plan's steps (reference/solvers/plan.py), and in ``run`` what they use: the
    dimension, the free dofs' coordinates (read off the modes if not given), the Cholesky's
    symbolic factorisation if the plan needs its estimate."""
    run.dim = (
        near_null.shape[1] // 3 + 1
        if near_null is not None and near_null.shape[1] in (3, 6)
        else (coords.shape[1] if coords is not None else 3)
    )
    if coords is None and solver in ("auto", "direct", "cholesky", "amg", "cg"):
        coords = coords_from_modes(eq.As, near_null)
    run.coords = coords
    system = System(
        eq.A.shape[0],
        run.dim,
        solver,
        coords=coords is not None,
        coarse=run.coarse is not None,
        tensor=run.tensor is not None,
        nnz=eq.A.nnz,
    )
    plan = choose_plan(system)
    if plan.needs_estimate:  # the Cholesky's cost from its symbolic factorisation (reused)
        run.sym = _symbolic(eq.As, coords)
        run.estimate = _estimate(run.sym)
        plan = choose_plan(replace(system, estimate=run.estimate))
    return plan.steps


@dataclass
class _Equilibrated:
    """A x = b as As y = S b with S = D^-1/2 (unit diagonal), x = S y: nothing depends on
    the units of A, b or the coordinates. ``live``: the nonzero columns of b."""

    A: sp.csr_matrix
    b2: np.ndarray
    s: np.ndarray
    As: sp.csr_matrix
    bs: np.ndarray
    bnorm: np.ndarray
    live: np.ndarray
    normA: float  # ||A||_inf >= ||A||_2 (symmetric)

    @classmethod
    def of(cls, A, b2, d) -> _Equilibrated:
        s = 1.0 / np.sqrt(d)
        bnorm = np.linalg.norm(b2, axis=0)
        normA = float(np.max(abs(A) @ np.ones(A.shape[0])))
        return cls(A, b2, s, equilibrated(A, s), b2 * s[:, None], bnorm, bnorm > 0, normA)

    def unscaled(self, y: np.ndarray) -> np.ndarray:
        """x = S y on the live columns, zero on the others."""
        xs = np.zeros_like(self.b2)
        xs[:, self.live] = y * self.s[:, None]
        return xs

    def residual(self, xs) -> tuple[float, float, float]:
        """(max ||b - A x|| / ||b||, the largest ratio of a column's residual to its
        tolerance, the tolerance of the worst column) over the nonzero columns."""
        live, bnorm = self.live, self.bnorm[self.live]
        r = np.linalg.norm(self.b2[:, live] - self.A @ xs[:, live], axis=0) / bnorm
        tol = accepted_rtol(self.normA, np.linalg.norm(xs[:, live], axis=0), bnorm)
        if not np.all(np.isfinite(r)):
            return np.inf, np.inf, RTOL
        return float(r.max()), float(np.max(r / tol)), float(tol[np.argmax(r / tol)])


@dataclass
class _Run:
    """One solve's state beside its system: when it started, where its record goes, what
    the steps may use (the dimension, the free dofs' ``coords``, the scaled rigid-body
    modes ``Bs``, the P1/Q1 subspace ``coarse``, the preconditioner ``tensor``), the
    Cholesky's symbolic factorisation and estimate once made, the failed steps and their
    work (Gflop, counted: see :data:`GFLOP_PER_NONZERO`)."""

    t0: float
    records: list | None
    dim: int = 3
    coords: np.ndarray | None = None
    Bs: np.ndarray | None = None
    coarse: sp.spmatrix | None = None
    tensor: object = None
    sym: Symbolic | None = None
    estimate: dict | None = None
    fallbacks: list = field(default_factory=list)
    spent: float = 0.0

    def done(self, x, step: str, residual=0.0, rtol=RTOL, iterations=0):
        """``x``, its SolveRecord appended to the caller's list."""
        if self.records is not None:
            seconds = time.perf_counter() - self.t0
            rec = (step, residual, rtol, iterations, seconds, tuple(self.fallbacks))
            self.records.append(SolveRecord(*rec, self.estimate))
        return x


def _try_steps(steps: tuple[str, ...], eq: _Equilibrated, run: _Run) -> np.ndarray:
    """The first step whose solution is accepted (a direct one after one step of iterative
    refinement); a failed iterative step is a Fallback of the record."""
    for step in steps:
        t1, budget = time.perf_counter(), None
        if step == "amg-strong" and steps[-1] == "cholesky":
            skip, budget = _strong_budget(eq, run)
            if skip:
                continue
        try:
            y, its, why, f = STEPS[step](eq, run, step, budget)
        except ModelError:
            raise _singular() from None
        xs = eq.unscaled(y)
        res, ratio, tol = eq.residual(xs) if np.all(np.isfinite(xs)) else (np.inf, np.inf, RTOL)
        direct = step in ("cholesky", "superlu")
        if direct and np.isfinite(res) and res > RTOL / 100:
            # one step of iterative refinement with the same factor
            xs2, live, s = xs.copy(), eq.live, eq.s[:, None]
            xs2[:, live] += f((eq.b2[:, live] - eq.A @ xs[:, live]) * s) * s
            res2 = eq.residual(xs2)
            if res2[0] < res:
                xs, (res, ratio, tol) = xs2, res2
        f = None
        if ratio <= 1 or (direct and res <= DIRECT_RTOL):
            return run.done(xs, step, res, tol, its)
        if direct:
            raise _singular()
        reason = why or f"residual above {tol:.1e}"
        run.fallbacks.append(Fallback(step, res, reason, time.perf_counter() - t1))
        run.spent += work(step, its, eq.As.nnz, int(eq.live.sum()))
    return run.done(np.zeros_like(eq.b2), "none")  # not reached: a plan ends with a direct step


def work(step: str, iterations: int, nnz: int, columns: int) -> float:
    """The work (Gflop, :data:`GFLOP_PER_NONZERO`) of an iterative ``step`` that ran
    ``iterations`` on ``columns`` right-hand sides of a matrix of ``nnz`` nonzeros."""
    per = GFLOP_PER_NONZERO.get(step, 0.0)
    return (iterations + SETUP_ITERATIONS) * nnz * per * max(columns, 1)


def _strong_budget(eq: _Equilibrated, run: _Run) -> tuple[bool, int | None]:
    """(skip, iterations over all columns) of 'amg-strong' before the Cholesky it falls back
    to: a stronger AMG only while it can beat that Cholesky (:data:`GFLOP_PER_NONZERO`)."""
    if run.sym is None and eq.A.shape[0] <= SYMBOLIC_MAX[run.dim]:
        run.sym = _symbolic(eq.As, run.coords)
        run.estimate = _estimate(run.sym)
    if run.sym is not None and run.estimate["gbytes"] <= FALLBACK_GBYTES:
        chol = run.estimate["gflop"] + CHOLESKY_OVERHEAD_GFLOP
        its = chol / (eq.As.nnz * GFLOP_PER_NONZERO["amg-strong"]) - SETUP_ITERATIONS
        return chol < 2 * run.spent, max(int(its), 0)
    return False, None


# -- direct ------------------------------------------------------------------------------


def _symbolic(As, coords):
    return Symbolic(As, coords)


def _estimate(sym) -> dict:
    """Work (Gflop) and peak memory (GB) of the multifrontal Cholesky (``Symbolic.estimate``)."""
    return sym.estimate()


def _factor(As, step, sym):
    """Factorise As (Cholesky on the Symbolic ``sym``); returns the solve function for
    (n, m) right-hand sides."""
    if step == "cholesky":
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


# memory the shift-invert Cholesky may take (beyond it: the two-level CG below)
INVERSE_GBYTES = 6.0
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


# -- iterative ---------------------------------------------------------------------------


def _two_level(eq: _Equilibrated, run: _Run, step: str, budget):
    """reference/solvers/twolevel.py's CG on every column at once, each to the residual
    ``solve`` accepts (RTOL, or the floor of the column's solution, halved for margin)."""
    from reference.solvers import twolevel

    bs, s, bnorm = eq.bs[:, eq.live], eq.s, eq.bnorm[eq.live]
    try:
        M = twolevel.TwoLevel(eq.As, s, run.coarse, run.coords, run.Bs)
    except Exception as exc:  # noqa: BLE001 - a failed setup is a failed attempt
        return np.full_like(bs, np.nan), 0, f"two-level setup failed: {exc}", None

    def target(Y):
        return 0.5 * accepted_rtol(eq.normA, np.linalg.norm(Y * s[:, None], axis=0), bnorm) * bnorm

    return (*twolevel.pcg(eq.As, bs, M, 1.0 / s, target, TWO_LEVEL_MAXITER), None)


def _hierarchy(As, Bs, strong: bool):
    """The smoothed-aggregation hierarchy (seeded: the same one every run)."""
    with seeded_numpy():
        return sa_hierarchy(As, Bs, strong)


def _iterative(eq: _Equilibrated, run: _Run, step: str, budget):
    """CG preconditioned by one AMG V-cycle ('amg', 'amg-strong') or Jacobi ('cg'; the
    diagonal of As is 1) on every column. ``budget``: iterations over all columns after
    which it is not worth continuing (None: the step's own maxiter per column)."""
    As, bs, Bs = eq.As, eq.bs[:, eq.live], run.Bs
    if step == "cg":
        M, maxiter = None, min(20 * As.shape[0], CG_MAXITER)
    else:
        try:
            ml = _hierarchy(As, Bs, step == "amg-strong")
        except Exception as exc:  # noqa: BLE001 - a failed setup is a failed attempt
            return np.full_like(bs, np.nan), 0, f"AMG setup failed: {exc}", None
        M = ml.aspreconditioner(cycle="V")
        maxiter = AMG_MAXITER if step == "amg" else STRONG_MAXITER
    Y, its, why = np.zeros_like(bs), 0, ""
    used = 0
    for j in range(bs.shape[1]):
        cap = maxiter if budget is None else max(min(maxiter, budget - used), 1)
        window = 20 if M is not None else 200
        Y[:, j], k, w = _pcg(As, bs[:, j], M, RTOL / 4, cap, window, cap < maxiter)
        its, why, used = max(its, k), why or w, used + k
    return Y, its, why, None


# -- the steps: (system, run, step, budget) -> (y, iterations, reason of a failure, the
# factor of a direct step or None) ------------------------------------------------------


def _direct_step(eq: _Equilibrated, run: _Run, step: str, budget):
    if step == "cholesky" and run.sym is None:
        run.sym = _symbolic(eq.As, run.coords)
    f = _factor(eq.As, step, run.sym)
    return f(eq.bs[:, eq.live]), 0, "", f


def _tensor_step(eq: _Equilibrated, run: _Run, step: str, budget):
    bs = eq.bs[:, eq.live]
    return (*tensorpre.cg(eq.As, bs, eq.s, run.tensor, _pcg, RTOL, TENSOR_MAXITER), None)


# every step a plan may name (reference/solvers/plan.py): how it is tried
STEPS = {
    "cholesky": _direct_step,
    "superlu": _direct_step,
    "amg": _iterative,
    "amg-strong": _iterative,
    "cg": _iterative,
    "two-level": _two_level,
    "tensor": _tensor_step,
}
