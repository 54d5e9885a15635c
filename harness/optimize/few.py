"""The fit of a few grouped constants (one factor for all springs, one for a volume term's kv):
Gauss-Newton on the exact small Jacobian, with the common factor in closed form.

A group g's factor x_g = log(k_g / k0_g) moves u by du/dx_g = -K^-1 B diag(k 1_g) B^T u =
-y_g, and the groups' y sum to u (their dK/dx sum to K): one more solve per group beyond
the first, with the factorisation u was solved with, gives the residual, the Jacobian's
columns and their Gram matrix at once (a few numbers per load set: the same in the caller
and in a spread's workers, harness/optimize/evaluation.py). Scaling every constant by 1 / c
scales u by c, so the best common factor is closed form (c = <u_ref, u>_W / <u, u>_W) and
is applied at every evaluation without a solve: a single group ('scale') is fitted exactly
by one evaluation, two groups by a Levenberg-Marquardt step in the remaining direction per
evaluation (L-BFGS-B on the same constants stopped short of this optimum within the same
counts, docs/calibrate.md).

It stops after ``maxiter`` evaluations, or when an accepted step lowers G^2, or the next
step's linear model promises to, by less than FTOL of it: counts fixed before the run
(harness/optimize/select_counts.py predicts the work from them)."""

from __future__ import annotations

import math

import numpy as np

from harness.optimize.deadline import deadline as limit
from harness.optimize.evaluation import per_group
from harness.optimize.options import static_only
from harness.optimize.problem import FitProblem

FTOL = 1e-6  # converged: an accepted step lowers G^2 by less than this fraction of it ...
FLOOR = 1e-20  # ... or than this fraction of |u_ref|^2 (a relative misfit of 1e-10)
MU0 = 1e-6  # Levenberg-Marquardt's first damping, relative to the Gram matrix's diagonal


def group_moments(group: list, solve, k: np.ndarray, masks: np.ndarray) -> tuple:
    """(dd, du, uu, yd, yu, yy) of one group of load sets at k, with d = u_ref - u:
    <d, d>_W (with the constrained dofs' part), <d, u>_W, <u, u>_W and, per parameter group
    g with columns ``masks[g]``, y_g = K^-1 B diag(k masks[g]) B^T u: <y_g, d>_W, <y_g, u>_W
    and the Gram matrix <y_g, y_h>_W, summed over the loads (d itself, not u_ref, so
    that G^2 near a close fit keeps its digits)."""
    n = len(masks)
    dd = du = uu = 0.0
    yd, yu, yy = np.zeros(n), np.zeros(n), np.zeros((n, n))
    Us = solve([s.F for s in group])
    Ys = solve([_rhs(s, U, k, masks) for s, U in zip(group, Us)]) if n else [None] * len(group)
    for s, U, Y in zip(group, Us, Ys):
        D = s.Uref - U
        WU, WD = s.W * U, s.W * D
        dd += float(np.sum(D * WD)) + s.const
        du += float(np.sum(U * WD))
        uu += float(np.sum(U * WU))
        if Y is None:
            continue
        L = U.shape[1]
        cols = [Y[:, g * L : (g + 1) * L] for g in range(n)]
        for g in range(n):
            yd[g] += float(np.sum(cols[g] * WD))
            yu[g] += float(np.sum(cols[g] * WU))
            for h in range(g, n):
                yy[g, h] += float(np.sum(cols[g] * (s.W * cols[h])))
                yy[h, g] = yy[g, h]
    return dd, du, uu, yd, yu, yy


def _rhs(s, U: np.ndarray, k: np.ndarray, masks: np.ndarray) -> np.ndarray:
    """dK/dx_g U = B diag(k masks[g]) B^T U of each group g, side by side."""
    BtU = s.B.T @ U
    return np.hstack([s.B @ ((k * m)[:, None] * BtU) for m in masks])


def moments(problem: FitProblem, k: np.ndarray, masks: np.ndarray) -> tuple:
    """:func:`group_moments` summed over the problem's groups of load sets, in their order,
    the first parameter group's without solving for it: the groups' y sum to u (sum_g
    dK/dx_g = K), so y_0 = u - sum_{g>0} y_g (one group: no solve beyond u)."""
    parts = per_group(problem, k, group_moments, masks[1:])
    dd = du = uu = 0.0
    n = len(masks)
    yd, yu, yy = np.zeros(n - 1), np.zeros(n - 1), np.zeros((n - 1, n - 1))
    for a, b, c, d, e, f in parts:
        dd, du, uu = dd + a, du + b, uu + c
        yd, yu, yy = yd + d, yu + e, yy + f
    # y_0's moments: <u - sum y, .>
    Yd, Yu = np.concatenate([[du - yd.sum()], yd]), np.concatenate([[uu - yu.sum()], yu])
    cross = yu - yy.sum(axis=0)  # <y_0, y_h>, h > 0
    first = uu - 2 * yu.sum() + yy.sum()
    YY = np.block([[np.array([[first]]), cross[None, :]], [cross[:, None], yy]])
    return dd, du, uu, Yd, Yu, YY


def few_fit(problem: FitProblem, options: dict, x0=None, deadline=None) -> dict:
    """The grouped constants (problem.groups) fitted from x0 (log factors per group; None:
    the rule, 0) as the module doc says; ``options``: maxiter (evaluations, default 20);
    ``deadline`` (or the options' max_seconds) only aborts. Returns k and info (phi = G^2 /
    G^2 at k0, the stop, the evaluations), as the other fits of harness/optimize/select.py."""
    if problem.groups is None:
        raise ValueError("few_fit fits grouped constants (FitProblem.groups)")
    static_only(problem, "the scale candidates' fit")
    cap = limit(options, "the few-constants fit", deadline)
    n = problem.n_params
    masks = np.array([problem.groups == g for g in range(n)], float)
    lo, hi = (math.log(b) for b in problem.bounds)
    x = np.zeros(n) if x0 is None else np.asarray(x0, float).copy()
    at_rule = not np.any(x)  # then the first evaluation gives G^2 at k0
    best, mu, stop, evals, G0sq = None, MU0, "maxiter", 0, math.nan
    while evals < int(options.get("maxiter") or 20):
        cap.check()
        evals += 1
        dd, du, uu, yd, yu, yy = moments(problem, problem.k_of(np.exp(x)), masks)
        G0sq = dd if evals == 1 and at_rule else G0sq
        tol = FLOOR * (dd + 2 * du + uu)  # |u_ref|^2 = |d + u|^2
        # the best common factor: u -> c u, every constant over c (as far as the bounds allow)
        a = -math.log1p(du / uu) if uu > 0 and du > -uu else 0.0
        a = min(max(a, lo - float(x.min())), hi - float(x.max()))
        e = math.expm1(-a)  # c - 1
        G2 = dd - 2 * e * du + e * e * uu
        if best is not None and G2 >= best[0]:  # rejected: a shorter step from the best
            mu *= 16.0
        else:
            done = best is not None and best[0] - G2 <= FTOL * best[0] + tol
            c = 1.0 + e
            best = (G2, x + a, c * c * yy, c * yd - c * e * yu)  # J^T J, J^T r at x + a
            if done or n == 1:  # one group: the common factor is the fit
                stop = "converged" if done else "exact"
                break
            mu = mu / 4.0 if evals > 1 else mu
        x, pred = _step(*best[1:], mu, lo, hi)
        if pred <= FTOL * best[0] + tol:  # the model promises no more: no evaluation to find out
            stop = "converged"
            break
    if not at_rule:
        G0sq = moments(problem, problem.k0, masks[:1])[0]
    return {
        "k": problem.k_of(np.exp(best[1])),
        "info": {"phi": best[0] / G0sq, "stop": stop, "evaluations": evals},
    }


def _step(x, JJ, Jr, mu, lo, hi) -> tuple:
    """(x plus the damped Gauss-Newton step p, (JJ + mu diag(JJ)) p = -Jr, within the bounds;
    the decrease of G^2 its linear model predicts), JJ = J^T J and Jr = J^T r of r = sqrt(W)
    (u_ref - u), whose Jacobian in x is sqrt(W) y."""
    d = np.diag(JJ)
    p = np.linalg.solve(JJ + mu * np.diag(np.where(d > 0, d, 1.0)), -Jr)
    xn = np.clip(x + p, lo, hi)
    p = xn - x
    return xn, -float(2 * p @ Jr + p @ JJ @ p)
