"""Two-level preconditioned CG for P2/Q2 systems (reference/solvers/sparse.py's ``two-level``):
symmetric Gauss-Seidel on the system itself and an exact solve on the subspace of the
same mesh's P1/Q1 fields.

Smoothed aggregation (pyamg, rigid-body modes) converges slowly on P2 elasticity near
incompressibility: on the 50k-tet cylinder of ``bench calibrate`` (nu = 0.45, 203k free
dofs, 16.6 M nonzeros) CG took 95 V-cycles a load, ~280 s for its three loads on the
loaded 2-core machine. The P1 fields of the same mesh are a natural coarse space (their
interpolant is exact in P2, the vertex dofs are ~1/8 of the dofs): with two
Gauss-Seidel sweeps before and after an exact coarse solve (the multifrontal Cholesky of
P^T A P, 27.6k dofs, 12.6 Gflop) CG needs 23-25 iterations for each load there
(residual 1e-10), ~4x less CPU time than the AMG (setup included). The loads are
iterated together (one coarse substitution for all of them). A coarse system too large for
the Cholesky gets a smoothed-aggregation hierarchy instead (rigid-body modes of the coarse dofs).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from harness.linalg.multifrontal import MultifrontalCholesky, Symbolic
from harness.linalg.sparse import seeded_numpy, single_thread_blas

SWEEPS = 2  # Gauss-Seidel sweeps before and after the coarse correction (measured on
# the 50k-tet cylinder: 1 sweep 40-43 CG iterations, 2 sweeps 23-25, 3 sweeps 19-20; 2 is cheapest)
COARSE_GBYTES = 2.5  # the coarse system is factorised when its Cholesky fits in this, ...
COARSE_GFLOP = 300.0  # ... and costs at most this; else smoothed aggregation on it (the 200k-tet
# cylinder's P1 system, 110k dofs, ~210 Gflop: its AMG inner CG took ~2.5x the Cholesky's time)
WINDOW = 10  # iterations over which the convergence rate is judged (give up when too slow)


def prolongation(d) -> sp.csr_matrix | None:
    """P (ndof, ndof of the P1/Q1 space): the P1/Q1 fields of the Discretisation d's mesh
    interpolated at d's own dofs (exact: they lie in d's P2/Q2 space), interleaved like d;
    None when d is P1/Q1. Each element's local interpolation matrix is the P1/Q1 basis at
    the P2/Q2 element's reference dof locations (the same for every element)."""
    import skfem

    from reference.mesh import element

    if d.order != "P2":
        return None
    low = element(d.cell, "P1")
    fine = skfem.CellBasis(d.mesh, d.elem, mapping=d.mapping, intorder=1)
    coarse = skfem.CellBasis(d.mesh, low, mapping=d.mapping, intorder=1)
    X = np.asarray(d.elem.doflocs, float).T  # dim, nloc fine (reference cell)
    # nloc fine, nloc coarse
    local = np.stack([low.lbasis(X, j)[0] for j in range(low.doflocs.shape[0])], axis=1)
    i, j = np.nonzero(np.abs(local) > 1e-14)
    rows = fine.element_dofs[i].ravel()
    cols = coarse.element_dofs[j].ravel()
    vals = np.repeat(local[i, j], fine.element_dofs.shape[1])
    # shared dofs once
    key, first = np.unique(rows.astype(np.int64) * coarse.N + cols, return_index=True)
    Ps = sp.csr_matrix((vals[first], (key // coarse.N, key % coarse.N)), shape=(fine.N, coarse.N))
    return sp.csr_matrix(sp.kron(Ps, sp.identity(d.dim), format="csr"))


class TwoLevel:
    """The preconditioner for the equilibrated system As = S A S (S = diag(s)): ``SWEEPS``
    forward Gauss-Seidel sweeps, the coarse correction Ps Ac^-1 Ps^T r with Ps = S^-1 P
    and Ac = Ps^T As Ps = P^T A P, ``SWEEPS`` backward sweeps (symmetric, positive
    definite). ``P`` (n, nc) maps coarse to fine dofs, ``coords`` (n, dim) locate the fine
    dofs, ``near_null`` (n, k) are A's rigid-body modes (for an AMG coarse solve)."""

    def __init__(
        self,
        As: sp.csr_matrix,
        s: np.ndarray,
        P: sp.spmatrix,
        coords: np.ndarray,
        near_null: np.ndarray | None = None,
    ):
        P = sp.csr_matrix(P)
        # coarse dofs on free dofs
        used = np.flatnonzero(np.asarray(abs(P).sum(axis=0)).ravel() > 0)
        P = sp.csr_matrix(P[:, used])
        self.As = As
        self.Ps = sp.csr_matrix(P.multiply((1.0 / s)[:, None]))
        self.PsT = sp.csr_matrix(self.Ps.T)
        Ac = sp.csr_matrix(self.PsT @ (As @ self.Ps))
        Ac = sp.csr_matrix(0.5 * (Ac + Ac.T))  # symmetric to rounding
        dc = Ac.diagonal()
        if not np.all(dc > 0):
            raise ValueError("the coarse system has a zero diagonal")
        self.sc = 1.0 / np.sqrt(dc)
        Acs = sp.csr_matrix(Ac.multiply(self.sc[:, None]).multiply(self.sc[None, :]))
        weight = np.asarray(abs(P).sum(axis=0)).ravel()
        # each coarse dof at its support's centre
        cc = np.asarray(abs(P).T @ coords) / weight[:, None]
        sym = Symbolic(Acs, cc)
        est = sym.estimate()
        self.info = {"coarse_dofs": int(Acs.shape[0]), "coarse_gflop": est["gflop"]}
        if est["gbytes"] <= COARSE_GBYTES and est["gflop"] <= COARSE_GFLOP:
            chol = MultifrontalCholesky(Acs, sym)
            with single_thread_blas():  # small blocks: threads only add overhead
                chol._flat()  # every solve takes the compiled substitution
            self._coarse = lambda r: chol.solve(r)
            self.info["coarse"] = "cholesky"
        else:
            import pyamg

            Bc = None
            if near_null is not None:  # the modes at each coarse dof's strongest fine dof
                rows = np.asarray(abs(P).argmax(axis=0)).ravel()
                Bc = np.asarray(near_null, float)[rows] / self.sc[:, None]
            with seeded_numpy():
                ml = pyamg.smoothed_aggregation_solver(Acs, B=Bc, symmetry="hermitian")
            M = ml.aspreconditioner(cycle="V")
            self._coarse = lambda r: np.column_stack(
                [_cg(Acs, r[:, c], M, 1e-3) for c in range(r.shape[1])]
            )
            self.info["coarse"] = "amg"

    def __call__(self, R: np.ndarray) -> np.ndarray:
        """M R for a block R (n, m): pyamg's compiled Gauss-Seidel on each column (a
        kernel that sweeps all columns at once measured no faster), one coarse solve."""
        from pyamg.relaxation.relaxation import gauss_seidel

        R = np.asfortranarray(R, float)
        X = np.zeros_like(R, order="F")  # columns contiguous: swept in place
        for c in range(R.shape[1]):
            gauss_seidel(self.As, X[:, c], R[:, c], iterations=SWEEPS, sweep="forward")
        rc = self.PsT @ (R - self.As @ X)
        X += self.Ps @ (
            self.sc[:, None] * self._coarse(np.ascontiguousarray(self.sc[:, None] * rc))
        )
        for c in range(R.shape[1]):
            gauss_seidel(self.As, X[:, c], R[:, c], iterations=SWEEPS, sweep="backward")
        return X


def _cg(A, b, M, rtol, maxiter=200):
    """A few preconditioned CG steps (an approximate coarse solve)."""
    x = np.zeros_like(b)
    r = b.copy()
    z = M @ r
    p = z.copy()
    rz, nb = r @ z, np.linalg.norm(b)
    for _ in range(maxiter):
        if not nb > 0 or np.linalg.norm(r) <= rtol * nb:
            break
        Ap = A @ p
        a = rz / (p @ Ap)
        x += a * p
        r -= a * Ap
        z = M @ r
        rz, rz_old = r @ z, rz
        p = z + (rz / rz_old) * p
    return x


def pcg(
    As: sp.csr_matrix,
    Bs: np.ndarray,
    M,
    weight: np.ndarray,
    target,
    maxiter: int,
):
    """CG on every column of As Y = Bs at once (each column its own step lengths), with the
    preconditioner M (a function of (n, m) blocks). Column c stops once the weighted
    residual ||weight * (Bs - As Y)|| (the unscaled system's own residual) is below
    target(Y)[c] (a tolerance that may grow with the solution). Returns (Y, iterations,
    reason of a failure or ""): gives up when the iterations run out, the last WINDOW
    iterations' rate cannot reach the targets within them, or CG breaks down."""
    n, m = Bs.shape
    Y = np.zeros((n, m))
    R = np.array(Bs, float, order="C")
    norm = lambda V: np.linalg.norm(weight[:, None] * V, axis=0)  # noqa: E731
    res = norm(R)
    hist = [res.copy()]
    live = res > target(Y)
    if not live.any():
        return Y, 0, ""
    Z = M(R)
    Pd = Z.copy()
    rz = np.einsum("ij,ij->j", R, Z)
    for k in range(1, maxiter + 1):
        AP = As @ Pd
        pap = np.einsum("ij,ij->j", Pd, AP)
        if not np.all(np.isfinite(pap[live])) or np.any(pap[live] <= 0) or np.any(rz[live] <= 0):
            return Y, k, "breakdown (the matrix or the preconditioner is not positive definite)"
        a = np.where(live, rz / np.where(live, pap, 1.0), 0.0)
        Y += a * Pd
        R -= a * AP
        res = norm(R)
        hist.append(res.copy())
        tol = target(Y)
        live = res > tol
        if not live.any():
            return Y, k, ""
        if k >= 2 * WINDOW:
            rate = (np.min(hist[-WINDOW:], axis=0) / np.min(hist[:-WINDOW], axis=0)) ** (1 / WINDOW)
            with np.errstate(divide="ignore"):
                more = np.where(
                    rate < 1, np.log(tol / res) / np.log(np.minimum(rate, 1 - 1e-16)), np.inf
                )
            more = float(np.max(more[live]))
            if more > maxiter - k:
                return (
                    Y,
                    k,
                    f"too slow (rate {float(np.max(rate[live])):.3f} per iteration at {k} "
                    "iterations)",
                )
        Z = M(R)
        rz_new = np.einsum("ij,ij->j", R, Z)
        beta = np.where(live, rz_new / np.where(rz > 0, rz, 1.0), 0.0)
        Pd = Z + beta * Pd
        rz = rz_new
    return Y, maxiter, f"no convergence in {maxiter} iterations"
