"""The graded boxes' systems solved without assembling them: CG on the Q2 lattice with
the stiffness applied as Kronecker products (reference/solvers/kronecker.py) and the
fast-diagonalisation preconditioner (reference/solvers/tensorpre.py). For one elastic tensor on
the whole mesh only; the constrained dofs are masked out of the lattice fields (their
rows and columns of K dropped), so the CG solves exactly the system the assembled path
(reference/solvers/sparse.py, method 'tensor') solves, equilibrated the same way and accepted
by the same residual test. A solve that is not accepted returns None, and the caller
assembles K and falls back as 'auto' does."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse.linalg as spla

from reference.lattice import Lattice
from reference.solvers import sparse, tensorpre
from reference.solvers.kronecker import KroneckerStiffness
from reference.solvers.record import Fallback, SolveRecord

ATTEMPTS = 3  # CG passes, each with a tighter target if the last fell short of the acceptance


def homogeneous(C: np.ndarray) -> np.ndarray | None:
    """The one Voigt matrix of per-element stiffnesses C (ne, nv, nv) that are all equal,
    else None."""
    C = np.asarray(C, float)
    return C[0] if np.allclose(C, C[0], rtol=1e-12, atol=1e-12 * np.abs(C[0]).max()) else None


@dataclass(frozen=True)
class Operator:
    """K of one Voigt matrix ``C`` on a lattice, applied to interleaved dof vectors."""

    lat: Lattice
    C: np.ndarray
    K: KroneckerStiffness

    def apply_dofs(self, V: np.ndarray) -> np.ndarray:
        """K V for interleaved dof vectors V (ndof, k)."""
        U = self.lat.to_lattice(V)
        return self.lat.from_lattice(np.stack([self.K.apply(u) for u in U]))

    def norm_bound(self) -> float:
        return self.K.norm_bound()


def operator(lat: Lattice, C: np.ndarray) -> Operator:
    return Operator(lat, np.asarray(C, float), KroneckerStiffness.of(lat.axes, C))


def solve(A: Operator, b: np.ndarray, fixed: np.ndarray, x0: np.ndarray | None = None):
    """(x, record): x (ndof, m) with K x = b (ndof, m) on the free dofs and x = 0 on
    ``fixed`` (interleaved global dofs), K = ``A``, and its SolveRecord; (None, Fallback)
    when the CG is not accepted; (None, None) when a component has no plane fixed as a
    whole. ``x0``: initial guesses like b."""
    t0 = time.perf_counter()
    lat, op = A.lat, A.K
    dim = len(lat.axes)
    free = np.ones(lat.field_shape, bool).reshape(dim, -1)
    node, comp = np.divmod(np.asarray(fixed, int), dim)
    free[comp, lat.index[node]] = False
    free = free.reshape(lat.field_shape)
    found = tensorpre.blocks(lat.axes, free, A.C)
    if found is None:
        return None, None
    P = tensorpre.lattice_preconditioner(found, free)
    s = np.where(free, 1.0 / np.sqrt(op.diagonal()), 0.0).ravel()
    n = s.size

    def Af(v):
        return (op.apply(np.where(free, v.reshape(lat.field_shape), 0.0)) * free).ravel()

    As = spla.LinearOperator((n, n), matvec=lambda y: s * Af(s * np.ravel(y)), dtype=float)
    B = lat.to_lattice(b).reshape(-1, n).T * free.reshape(-1, 1)
    bnorm = np.linalg.norm(B, axis=0)
    live = bnorm > 0
    safe = np.where(s > 0, s, 1.0)
    normA = op.norm_bound()
    y0 = None
    target = sparse.RTOL
    if x0 is not None:
        X0 = lat.to_lattice(x0).reshape(-1, n).T[:, live] * free.reshape(-1, 1)
        y0 = X0 / safe[:, None]
        # the tolerance the solution will be accepted at (it grows with ||x||, see sparse.FLOOR):
        # iterating below it (1e-8 on the 10:1 box's cantilevers) only chases rounding
        target = float(np.min(sparse.accepted_rtol(normA, np.linalg.norm(X0, axis=0), bnorm[live])))
    its = 0
    for _ in range(ATTEMPTS):
        y0, k, why = tensorpre.cg(
            As,
            B[:, live] * s[:, None],
            safe,
            lambda r: P(r.reshape(lat.field_shape)).ravel(),
            sparse._pcg,
            target,
            sparse.TENSOR_MAXITER - its,
            y0,
        )
        its += k
        X = np.zeros_like(B)
        X[:, live] = y0 * s[:, None]
        r = (
            np.linalg.norm(B[:, live] - np.column_stack([Af(x) for x in X[:, live].T]), axis=0)
            / bnorm[live]
        )
        tol = sparse.accepted_rtol(normA, np.linalg.norm(X[:, live], axis=0), bnorm[live])
        if why or not np.all(np.isfinite(r)) or np.all(r <= tol):
            break
        target *= float(np.min(tol / r)) / 2  # the equilibrated residual fell short of the true one
    seconds = time.perf_counter() - t0
    res = float(r.max()) if r.size else 0.0
    if not np.all(np.isfinite(r)) or np.any(r > tol):
        return None, Fallback("tensor", res, why or "residual above the tolerance", seconds)
    rec = SolveRecord(
        "tensor", res, float(tol.max()) if tol.size else sparse.RTOL, its, seconds, matrix_free=True
    )
    return lat.from_lattice(X.T.reshape((-1,) + lat.field_shape)), rec
