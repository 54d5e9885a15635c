"""A fast-diagonalisation preconditioner for Q2 systems on tensor meshes (the graded
boxes and rectangles of reference/graded/meshes.py).

On a tensor mesh of axis-aligned cells the Q2 basis is a product of 1-D quadratic
Lagrange functions, phi_I = X_i(x) Y_j(y) Z_k(z), so for a homogeneous material the
stiffness block of displacement component c with itself keeps, of its terms
sum_pq C_cpcq int d_p phi_I d_q phi_J, the ones with p = q as a sum of Kronecker
products: B_c = sum_d C_cdcd (M (x) .. A_d .. (x) M), with the 1-D stiffness A_d in
position d and 1-D masses M elsewhere. With per-axis generalised eigenvectors
(A_d V_d = M_d V_d L_d, V_d^T M_d V_d = I), B_c^-1 = W diag(1 / sum_d C_cdcd L_d) W^T,
W = V_x (x) V_y (x) V_z: applied by dense matrix products along each axis, O(N n) for
N nodes and n nodes per axis, nothing factorised. The preconditioner is block-Jacobi
over the components (the cross-component coupling, lambda's, is left to CG).

Constraints: a component's plane at an end of an axis that is fixed as a whole (a clamped
face, a roller, a mirror's cut plane) is a Dirichlet end of that axis in B_c; fixed dofs
off such planes (corner or edge points, part of a face) are masked out, P = R B^-1 R^T,
still symmetric positive definite. A component with no Dirichlet end on any axis (the
stretches' rollers and corner points) has no preconditioner here: its B_c is singular,
and shifted it took 200+ iterations where the Cholesky is quick (and its rounding small
enough for two levels of a linear field to agree, reference/graded/levels.py EXACT). A piecewise
or anisotropic material is preconditioned by its mean elastic tensor's diagonal moduli
(the CG solves the true system). Measured: results/bench/reference.csv (solver 'tensor').
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse.linalg as spla

from reference.lattice import Lattice
from reference.solvers.kronecker import axis_matrices

_PAIRS = {2: {(0, 1): 2}, 3: {(1, 2): 3, (0, 2): 4, (0, 1): 5}}  # Voigt index of a shear pair


def moduli(C: np.ndarray, dim: int) -> np.ndarray:
    """(dim, dim): k[c, d] = C_cdcd of the mean Voigt stiffness (engineering shear)."""
    Cm = np.asarray(C, float).reshape(-1, *C.shape[-2:]).mean(axis=0)
    k = np.empty((dim, dim))
    for c in range(dim):
        for d in range(dim):
            v = c if c == d else _PAIRS[dim][tuple(sorted((c, d)))]
            k[c, d] = Cm[v, v]
    return k


@dataclass(frozen=True)
class _Block:
    """B_c^-1 of one component on its Dirichlet-reduced lattice."""

    keep: tuple  # per axis: the lattice indices that are not Dirichlet ends
    V: tuple  # per axis: M-orthonormal eigenvectors on ``keep``
    inv: np.ndarray  # 1 / eigenvalue sums, shaped like the reduced lattice

    def apply(self, r: np.ndarray) -> np.ndarray:
        t = r[np.ix_(*self.keep)]
        for a, V in enumerate(self.V):  # W^T r
            t = np.moveaxis(np.tensordot(V, t, axes=([0], [a])), 0, a)
        t *= self.inv
        for a, V in enumerate(self.V):  # W t
            t = np.moveaxis(np.tensordot(V, t, axes=([1], [a])), 0, a)
        out = np.zeros_like(r)
        out[np.ix_(*self.keep)] = t
        return out


def _block(axes, mats, free: np.ndarray, k: np.ndarray) -> _Block | None:
    """The component's block: ``free`` (lattice-shaped bool) its free nodes, k its moduli;
    None when no end plane of any axis is fixed as a whole."""
    dim = len(axes)
    keep = []
    for a in range(dim):
        ends = [0, len(axes[a]) - 1]
        plane = lambda i: np.take(free, i, axis=a)  # noqa: E731
        keep.append(
            np.array([i for i in range(len(axes[a])) if not (i in ends and not plane(i).any())])
        )
    if all(len(kept) == len(x) for kept, x in zip(keep, axes)):
        return None
    V, lam = [], []
    for kept, m in zip(keep, mats):
        l, v = sla.eigh(m["A"][np.ix_(kept, kept)], m["M"][np.ix_(kept, kept)])
        V.append(v)
        lam.append(np.maximum(l, 0.0))
    total = sum(
        k[a] * lam[a].reshape([-1 if b == a else 1 for b in range(dim)]) for a in range(dim)
    )
    return _Block(tuple(keep), tuple(V), 1.0 / total)


def blocks(axes, free: np.ndarray, C: np.ndarray) -> list | None:
    """Each component's block for the free nodes ``free`` (dim, lattice shape) of the
    lattice ``axes``, C the Voigt stiffness (one, or per element); None if a component
    has no plane fixed as a whole."""
    mats = [axis_matrices(x) for x in axes]
    k = moduli(C, len(axes))
    out = []
    for c in range(len(axes)):
        out.append(_block(axes, mats, free[c], k[c]))
        if out[-1] is None:
            return None
    return out


def lattice_preconditioner(found: list, free: np.ndarray):
    """z = P r on lattice fields (dim, lattice shape), zero on the fixed nodes."""

    def apply(r: np.ndarray) -> np.ndarray:
        return np.stack([B.apply(np.where(f, rc, 0.0)) for B, f, rc in zip(found, free, r)]) * free

    return apply


def preconditioner(doflocs: np.ndarray, free: np.ndarray, C: np.ndarray):
    """z = P r for the free interleaved dofs ``free`` (global dof = dim * node + component)
    of a Q2 system whose dof locations (dim, ns) form a tensor lattice, C its per-element
    Voigt stiffness; None if the dofs are not such a lattice or a component has no
    plane fixed as a whole."""
    dim, ns = doflocs.shape
    lat = Lattice.q2(doflocs)
    if lat is None:
        return None
    axes, index, shape = lat.axes, lat.index, lat.shape
    node, comp = np.divmod(np.asarray(free), dim)
    at = comp * int(np.prod(shape)) + index[node]  # each free dof's place in a lattice field
    mask = np.zeros(dim * int(np.prod(shape)), bool)
    mask[at] = True
    mask = mask.reshape((dim,) + shape)
    found = blocks(axes, mask, C)
    if found is None:
        return None
    P = lattice_preconditioner(found, mask)

    def apply(r: np.ndarray) -> np.ndarray:
        g = np.zeros(mask.size)
        g[at] = r
        return P(g.reshape(mask.shape)).ravel()[at]

    return apply


RESTARTS = 3  # CG restarts from the true residual (its recursive one drifts below it)


def cg(As, bs, s, apply, pcg, rtol: float, maxiter: int, y0=None):
    """(Y, iterations, reason): CG (``pcg``, reference/solvers/sparse.py's) on the equilibrated
    system As = S A S, columns bs, with the preconditioner ``apply`` ~ A^-1 turned into one
    of As: S^-1 P S^-1, from the initial guesses ``y0`` (columns like bs) or zero. The
    recursive residual of a long CG drifts from the true one (measured on the 10:1 box's
    quarters at nu = 0.49: recursive 2.5e-11, true 5e-11 at 55k dofs, past 1e-10 at 266k,
    and the solve fell back to AMG), so while the true residual is above rtol / 2, CG is
    restarted on it and its solution added."""
    M = spla.LinearOperator(As.shape, matvec=lambda r: apply(np.ravel(r) / s) / s, dtype=float)
    Y = np.zeros_like(bs) if y0 is None else np.array(y0, float)
    its, why = 0, ""
    for j in range(bs.shape[1]):
        b, y = bs[:, j], Y[:, j]
        nb = np.linalg.norm(b)
        k, w = 0, ""
        for _ in range(1 + RESTARTS):
            r = b - As @ y if y.any() else b
            nr = np.linalg.norm(r)
            if w or nr <= rtol / 2 * nb:
                break
            dy, k2, w = pcg(As, r, M, min(0.5, rtol / 4 * nb / nr), maxiter - k, 50)
            y, k = y + dy, k + k2
        Y[:, j] = y
        its, why = max(its, k), why or w
    return Y, its, why
