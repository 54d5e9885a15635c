"""Why optimisers differ, measured at the constants they return: bounds hit, the rank
and conditioning of the weighted residual's Jacobian (dense, independent of the
optimisers' own code)."""

from __future__ import annotations

import math

import numpy as np

JACOBIAN_MAX = (
    4e6  # entries of the dense Jacobian the diagnostics may form (dense SVD: 1.4e6 entries
)
# took 0.9 s, 1.1e7 took 21 s on one core; Deussen cases are below 1e6)


def fit_diagnostics(problem, k) -> dict:
    """Why optimisers differ, measured at the constants k they return:

    - ``opt_at_bounds``: parameters at their bounds (L-BFGS-B stops there);
    - ``jac_rank``: identifiable directions, singular values of the weighted residual's
      Jacobian d(sqrt(w)(u_ref - u))/d log(parameter) above 1e-8 of the largest;
    - ``jac_cond_logk`` / ``jac_cond_k``: largest / smallest of those singular values,
      over log k (what lbfgs and gauss-newton use) and over k itself (plain gradient
      descent on k, as the paper tried); the Gauss-Newton Hessian's condition is the square.

    Dense numpy solves, independent of the optimisers' own code."""
    lo, hi = problem.bounds
    k = np.asarray(k, float)
    groups = problem.groups
    f = k / problem.k0
    kp = k
    if groups is not None:  # one factor (and one representative k) per group
        f = np.array([np.median(f[groups == g]) for g in range(problem.n_params)])
        kp = np.array([np.median(k[groups == g]) for g in range(problem.n_params)])
    out = {"opt_at_bounds": int(np.sum((f <= lo * (1 + 1e-6)) | (f >= hi * (1 - 1e-6))))}
    J = weighted_jacobian(problem, k)
    if J is None:
        return out
    for name, A in (("logk", J), ("k", J / kp[None, :])):
        s = np.linalg.svd(A, compute_uv=False)
        keep = s > 1e-8 * s[0] if len(s) and s[0] > 0 else np.zeros(len(s), bool)
        if name == "logk":
            out["jac_rank"] = int(keep.sum())
        out[f"jac_cond_{name}"] = float(s[0] / s[keep][-1]) if keep.any() else math.nan
    return out


def weighted_jacobian(problem, k):
    """J = d(sqrt(w) (u_ref - u)) / d log(parameter), all loads stacked (rows: free dofs
    per load; columns: springs, or groups in grouped mode); dense, None if too large.
    From K du = -b_e (b_e.u) dk_e: column e is sqrt(w) K^-1 b_e k_e (b_e.u)."""
    if sum(b.B.shape[0] for b in problem.blocks) * problem.n_springs > JACOBIAN_MAX:
        return None
    parts = []
    for b in problem.blocks:
        Bd = b.B.toarray()
        K = (Bd * k) @ Bd.T
        u = np.linalg.solve(K, b.f)
        parts.append(np.sqrt(b.w)[:, None] * np.linalg.solve(K, Bd * (k * (Bd.T @ u))))
    J = np.vstack(parts)
    return J if problem.groups is None else J @ np.eye(problem.n_params)[problem.groups]
