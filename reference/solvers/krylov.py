"""Krylov pieces of the sparse solve (reference/solvers/sparse.py): preconditioned CG on
one column, and pyamg's smoothed-aggregation hierarchies its AMG steps precondition with."""

from __future__ import annotations

import numpy as np


def sa_hierarchy(As, Bs, strong: bool):
    """pyamg's smoothed-aggregation hierarchy of As (near-null space Bs): its default, or
    the strong setup (symmetric Gauss-Seidel, energy-minimising prolongation).
    Seed numpy's global random state around it (harness/linalg/sparse.py seeded_numpy)."""
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


def pcg(A, b, M, rtol, maxiter, window=20, budget=False):
    """Preconditioned CG to ||b - A x|| <= rtol ||b|| (recursive residual; the caller
    checks the true one). Gives up when the iterations run out or the rate of the last
    ``window`` iterations cannot reach rtol within them (``budget``: maxiter is what the
    Cholesky would cost, and the reason says so). Returns (x, iterations, reason)."""
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
            if more > maxiter - k and budget:
                return (
                    x,
                    k,
                    f"too slow ({k} iterations, ~{more:.0f} more cost more than the Cholesky)",
                )
            if more > maxiter - k:
                return x, k, f"too slow (rate {rate:.3f} per iteration at {k} iterations)"
        z = r if M is None else M @ r
        rz_new = r @ z
        if not rz_new > 0:
            return x, k, "breakdown (the preconditioner is not positive definite)"
        p = z + (rz_new / rz) * p
        rz = rz_new
    return x, maxiter, f"no convergence in {maxiter} iterations"
