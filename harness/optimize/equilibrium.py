"""Equilibrium-gap (equation-error) identification of the spring constants
(Claire, Hild & Roux 2004, "A finite element formulation to identify damage fields: the
equilibrium gap method").

G measures the output error u_ref - K(k)^-1 f, which is nonlinear in k. With the reference
displacement u*_l known at every free dof, the equilibrium residual of the reference is
instead LINEAR in k:

    K(k) u*_l - f_l = B diag(B^T u*_l) k - f_l = A_l k - f_l      (on the free dofs of load l).

Minimising sum_l || S_l (A_l k - f_l) ||^2 (S_l: row weights sqrt(w) / rms(f_l), so every
load counts the same and the G weights still apply) is a sparse linear least-squares problem:
one CG solve of the normal equations with a Jacobi preconditioner (the normal matrix is a
local operator, far better conditioned than the Gauss-Newton matrix of G). A tiny
Tikhonov term pulls springs the loads do not see (zero columns) to k0. The solution is
clipped to the problem's bounds.

When the reference comes from a spring network with the same topology (zero residual)
this recovers the constants in one shot. For a FEM reference it is a different estimator
than min G (equation error, not output error); it is then a start point for gauss-newton
or lbfgs (their option ``init = "equilibrium-gap"``).
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from harness.errors import SpringbenchError
from harness.optimize.evaluation import value_and_grad
from harness.optimize.options import check_options, static_only
from harness.optimize.problem import FitProblem

EG_DEFAULTS = dict(
    rtol=1e-10,  # relative residual of CG on the normal equations
    maxiter=20000,  # CG iterations
    reg=1e-10,  # Tikhonov weight towards k0, relative to each column's squared norm
)


def equation_error_system(problem: FitProblem):
    """The weighted equation-error system A x = b over the parameters x = k/k0 (per spring,
    or per group in grouped mode): A (sum of free dofs over loads, n_params) csr, b."""
    rows, rhs = [], []
    for s in problem.load_sets():
        C = s.B.T @ s.Uref  # (e, L): spring elongations of u*
        for j in range(C.shape[1]):
            f = s.F[:, j]
            rms = float(np.sqrt(np.mean(f * f)))
            sw = np.sqrt(s.W[:, j]) / (rms if rms > 0 else 1.0)
            A = sp.csr_matrix(s.B @ sp.diags(C[:, j] * problem.k0)).multiply(sw[:, None])
            rows.append(sp.csr_matrix(A))
            rhs.append(sw * f)
    A = sp.vstack(rows).tocsr()
    if problem.groups is not None:
        A = (
            A
            @ sp.csr_matrix(
                (np.ones(problem.n_springs), (np.arange(problem.n_springs), problem.groups)),
                shape=(problem.n_springs, problem.n_params),
            )
        ).tocsr()
    return A, np.concatenate(rhs)


def equilibrium_gap_factors(problem: FitProblem, options: dict | None = None):
    """Parameters x = k/k0 (clipped to the bounds) minimising the equation error, and an
    info dict (CG iterations, relative residual, clipped count, seconds)."""
    opts = check_options(options or {}, EG_DEFAULTS, "equilibrium-gap")
    t0 = time.perf_counter()
    A, b = equation_error_system(problem)
    N = (A.T @ A).tocsr()
    d = N.diagonal()
    if not np.any(d > 0):
        raise SpringbenchError(
            "equilibrium-gap: the reference displacements stretch no spring",
            field="optimizer.method",
            fix="check the reference displacements or use lbfgs",
        )
    # every column gets some: zero columns -> k0
    reg = float(opts["reg"]) * (d + 1e-3 * float(np.mean(d)))
    N = (N + sp.diags(reg)).tocsr()
    rhs = A.T @ b + reg  # reg * (x - 1): prior x = 1
    its = [0]

    def cb(_):
        its[0] += 1

    M = sp.diags(1.0 / N.diagonal())
    x, _ = spla.cg(
        N,
        rhs,
        x0=np.ones(len(d)),
        rtol=float(opts["rtol"]),
        maxiter=int(opts["maxiter"]),
        M=M,
        callback=cb,
    )
    res = float(np.linalg.norm(N @ x - rhs) / max(np.linalg.norm(rhs), 1e-300))
    lo, hi = problem.bounds
    clipped = int(np.sum((x < lo) | (x > hi)))
    x = np.clip(x, lo, hi)
    gap = float(np.linalg.norm(A @ x - b) / max(np.linalg.norm(b), 1e-300))
    return x, dict(
        eg_cg_iterations=its[0],
        eg_residual=res,
        eg_clipped=clipped,
        eg_gap=gap,
        eg_seconds=time.perf_counter() - t0,
    )


def equilibrium_gap(problem: FitProblem, options: dict, seed: int = 0, status=None) -> dict:
    """The equilibrium-gap estimate as an optimiser (deterministic; G by full re-solves)."""
    static_only(problem, "equilibrium-gap")
    t0 = time.perf_counter()
    G0 = float(np.sqrt(value_and_grad(problem, problem.k0, grad=False)[0]))
    if status is not None:
        status("equilibrium-gap: solving the equation-error least squares")
    x, info = equilibrium_gap_factors(problem, options)
    k = problem.k_of(x)
    G = float(np.sqrt(value_and_grad(problem, k, grad=False)[0]))
    if G > G0:  # keep the best point seen, as every optimiser does
        k, G, info["stop"] = problem.k0.copy(), G0, "worse than k0"
    else:
        info["stop"] = "solved"
    info["iterations"] = 1
    return dict(
        k=k,
        G_initial=G0,
        G_final=G,
        trace=np.array([(0, G0), (1, G)]),
        seconds=time.perf_counter() - t0,
        n_steps=1,
        accepted=1,
        info=info,
    )
