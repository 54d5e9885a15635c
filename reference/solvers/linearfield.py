"""Loads whose finite element solution is a linear field, found without a solve.

A box stretched by a uniform traction on rollers (basic2d/basic3d's stretches) has a
linear exact solution, which every P2/Q2 mesh represents exactly: the FEM returns it, to
the solver's rounding (on the 10:1 box at nu = 0.49 the Cholesky's rounding is 1e-8 of
the field). Here the Galerkin problem is solved over the linear fields that vanish on
the fixed dofs (dim (dim + 1) of them, minus the constrained) and the result is accepted
by the same residual test as any solve (reference/solvers/sparse.py): if K x = b holds on the
free dofs to that tolerance, x is the solution, found with a dozen products with K."""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from reference.solvers import sparse


def linear_fields(doflocs: np.ndarray) -> np.ndarray:
    """(ndof, dim (dim + 1)): u_c = 1 and u_c = x_j (centred, unit-scaled) for each
    component c, interleaved (global dof = dim * node + component)."""
    dim, ns = doflocs.shape
    x = doflocs - doflocs.mean(axis=1, keepdims=True)
    x = x / max(float(np.abs(x).max()), 1e-300)
    cols = []
    for c in range(dim):
        for f in [np.ones(ns)] + list(x):
            u = np.zeros((ns, dim))
            u[:, c] = f
            cols.append(u.ravel())
    return np.column_stack(cols)


def solve(apply_K, doflocs: np.ndarray, b: np.ndarray, fixed: np.ndarray, normA: float):
    """(x (ndof, m), its largest relative residual): x zero on ``fixed``, linear, with
    K x = b (ndof, m) on the free dofs to the solvers' tolerance (``apply_K``: (ndof, k)
    -> K times it, ``normA`` >= ||K||_inf); None when no linear field solves every column."""
    Phi = linear_fields(doflocs)
    N = _null_space(Phi[fixed])
    if N.shape[1] == 0:
        return None
    V = Phi @ N
    KV = apply_K(V)
    free = np.ones(len(b), bool)
    free[fixed] = False
    G = V[free].T @ KV[free]
    try:
        c = sla.solve(0.5 * (G + G.T), V[free].T @ b[free], assume_a="pos")
    except (sla.LinAlgError, ValueError):
        return None
    x = V @ c
    x[fixed] = 0.0
    bnorm = np.linalg.norm(b[free], axis=0)
    live = bnorm > 0
    if not live.any():
        return None
    r = np.linalg.norm((b - KV @ c)[free], axis=0)
    tol = sparse.accepted_rtol(normA, np.linalg.norm(x[free], axis=0), np.where(live, bnorm, 1.0))
    if np.all(r[live] <= tol[live] * bnorm[live]) and np.all(r[~live] == 0):
        return x, float(np.max(r[live] / bnorm[live]))
    return None


def _null_space(R: np.ndarray) -> np.ndarray:
    """Orthonormal basis of {c : R c = 0} for R (m, k) with m possibly large (the fixed dofs):
    from the economy SVD of R padded to at least k rows (scipy's null_space forms the full
    m x m U)."""
    k = R.shape[1]
    if len(R) < k:
        R = np.vstack([R, np.zeros((k - len(R), k))])
    _, s, Vt = np.linalg.svd(R, full_matrices=False)
    rank = int(np.sum(s > 1e-10 * max(float(s[0]), 1e-300))) if s[0] > 0 else 0
    return Vt[rank:].T
