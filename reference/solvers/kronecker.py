"""The Q2 stiffness of one homogeneous elastic tensor on a tensor mesh, applied without
assembling it: a sum of Kronecker products of 1-D matrices.

On a tensor mesh the Q2 basis is a product of 1-D quadratic Lagrange functions, so
G_pq[I, J] = int d_p phi_I d_q phi_J factors over the axes r into 1-D matrices: the
stiffness A_r (r = p = q), D_r[i, j] = int phi_i' phi_j (r = p != q), its transpose
(r = q != p) or the mass M_r. With Ct = S^T C S (S the Voigt selector,
reference/fem.py) the stiffness is K[(I, a), (J, b)] = sum_pq Ct[a, p, b, q] G_pq[I, J]
-- the same matrix as reference/fem.py's box assembly to rounding. Each 1-D matrix is a
band of five diagonals (vertices couple to two neighbours each way), so a product along
one axis costs 5 N for N nodes; the products along the later axes are shared between the
terms (sum factorisation). Measured on the 10:1 box's 261k-dof quarter: see
results/bench/reference.csv (solver 'tensor').

Fields live on the lattice: arrays (dim, n_0, .., n_dim-1), component first, x slowest.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from reference.fem import VOIGT

GAUSS = np.polynomial.legendre.leggauss(3)  # exact for the 1-D Q2 mass (degree 4)


def axis_matrices(nodes: np.ndarray) -> dict[str, np.ndarray]:
    """1-D global matrices (dense, (n, n)) of the quadratic Lagrange basis on an axis's
    Q2 nodes (vertices and cell midpoints alternating, n odd): mass 'M', stiffness 'A',
    'D'[i, j] = int phi_i' phi_j and its transpose 'Dt'."""
    nodes = np.asarray(nodes, float)
    n = len(nodes)
    xg, wg = GAUSS
    t = 0.5 * (xg + 1.0)
    N = np.stack([2 * (1 - t) * (0.5 - t), 4 * t * (1 - t), 2 * t * (t - 0.5)])  # basis at t
    dN = np.stack([4 * t - 3, 4 - 8 * t, 4 * t - 1])  # d/dt
    Me = 0.5 * np.einsum("iq,jq,q->ij", N, N, wg)
    Ae = 0.5 * np.einsum("iq,jq,q->ij", dN, dN, wg)
    De = 0.5 * np.einsum("iq,jq,q->ij", dN, N, wg)  # the cell length cancels
    M, A, D = np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n))
    for c in range(n // 2):
        s = slice(2 * c, 2 * c + 3)
        h = nodes[2 * c + 2] - nodes[2 * c]
        M[s, s] += h * Me
        A[s, s] += Ae / h
        D[s, s] += De
    return {"M": M, "A": A, "D": D, "Dt": D.T.copy()}


def bands(L: np.ndarray) -> np.ndarray:
    """(5, n): the diagonals of a 1-D matrix, bands[k, i] = L[i, i + k - 2] (0 outside)."""
    n = len(L)
    out = np.zeros((5, n))
    for k in range(5):
        off = k - 2
        i = np.arange(max(0, -off), min(n, n - off))
        out[k, i] = L[i, i + off]
    return out


@numba.njit(cache=True, nogil=True)
def _band(B, v, out, coef):  # pragma: no cover - compiled
    """out[p, i, q] += coef sum_j B[j - i + 2, i] v[p, j, q] (|j - i| <= 2)."""
    pre, n, post = v.shape
    for p in range(pre):
        for i in range(n):
            for j in range(max(0, i - 2), min(n, i + 3)):
                w = coef * B[j - i + 2, i]
                if w != 0.0:
                    for q in range(post):
                        out[p, i, q] += w * v[p, j, q]


@numba.njit(cache=True, nogil=True)
def _band_last(B, v, out, coef):  # pragma: no cover - compiled
    """:func:`_band` along the last (contiguous) axis: v, out (pre, n)."""
    pre, n = v.shape
    for p in range(pre):
        for i in range(n):
            acc = 0.0
            for j in range(max(0, i - 2), min(n, i + 3)):
                acc += B[j - i + 2, i] * v[p, j]
            out[p, i] += coef * acc


def band_apply(
    B: np.ndarray, u: np.ndarray, axis: int, out: np.ndarray | None = None, coef: float = 1.0
) -> np.ndarray:
    """out + coef L u along ``axis`` of a C-contiguous u (out zero when not given), L given
    by its bands (see :func:`bands`); a compiled loop (numpy's nine passes over the array
    per product took 3/4 of the thin box's CG time)."""
    n = u.shape[axis]
    shape3 = (int(np.prod(u.shape[:axis])), n, int(np.prod(u.shape[axis + 1 :])))
    out = np.zeros(u.shape) if out is None else out
    if not out.flags.c_contiguous or out.shape != u.shape:
        raise ValueError(
            "band_apply: out must be C-contiguous and shaped like u (it is written in place)"
        )
    v = np.ascontiguousarray(u).reshape(shape3)
    if shape3[2] == 1:
        _band_last(B, v.reshape(shape3[:2]), out.reshape(shape3[:2]), float(coef))
    else:
        _band(B, v, out.reshape(shape3), float(coef))
    return out


def voigt_tensor(C: np.ndarray) -> np.ndarray:
    """Ct[a, p, b, q] = sum_vw S[v, a, p] C[v, w] S[w, b, q] of one Voigt matrix C."""
    nv = C.shape[-1]
    dim = 2 if nv == 3 else 3
    S = np.zeros((nv, dim, dim))
    for v, (i, j) in enumerate(VOIGT[dim]):
        S[v, i, j] += 1.0
        if i != j:
            S[v, j, i] += 1.0
    return np.einsum("vap,vw,wbq->apbq", S, C, S)


def _pattern(p: int, q: int, dim: int) -> tuple[str, ...]:
    """The 1-D matrix of G_pq along each axis."""
    return tuple(
        "A" if r == p == q else "D" if r == p else "Dt" if r == q else "M" for r in range(dim)
    )


@dataclass(frozen=True)
class KroneckerStiffness:
    """K of the Voigt stiffness C (one for the whole mesh) on the Q2 lattice of ``axes``
    (per axis the Q2 node coordinates)."""

    axes: tuple
    bands: tuple  # per axis {name: (5, n) bands}
    terms: tuple  # (a, b, pattern, coefficient) with Ct[a, p, b, q] != 0

    @classmethod
    def of(cls, axes, C: np.ndarray) -> "KroneckerStiffness":
        dim = len(axes)
        mats = [axis_matrices(x) for x in axes]
        Ct = voigt_tensor(np.asarray(C, float))
        small = 1e-14 * np.abs(Ct).max()
        terms = tuple(
            (a, b, _pattern(p, q, dim), float(Ct[a, p, b, q]))
            for a in range(dim)
            for b in range(dim)
            for p in range(dim)
            for q in range(dim)
            if abs(Ct[a, p, b, q]) > small
        )
        return cls(
            tuple(np.asarray(x, float) for x in axes),
            tuple({k: bands(L) for k, L in m.items()} for m in mats),
            terms,
        )

    @property
    def shape(self) -> tuple:
        return (len(self.axes),) + tuple(len(x) for x in self.axes)

    def apply(self, u: np.ndarray) -> np.ndarray:
        """K u for a lattice field u (dim, n_0, ..): the 1-D products applied from the
        last axis to the first, each partial product computed once per input component."""
        dim = len(self.axes)
        out = np.zeros(self.shape)
        cache: dict = {}

        def partial(b: int, pattern: tuple) -> np.ndarray:
            """(the pattern's products along axes len(pattern)-1 .. 0 of pattern) u_b."""
            key = (b, pattern)
            if key not in cache:
                r = dim - len(pattern)
                inner = u[b] if len(pattern) == 1 else partial(b, pattern[1:])
                cache[key] = band_apply(self.bands[r][pattern[0]], inner, r)
            return cache[key]

        for a, b, pattern, coef in self.terms:
            inner = u[b] if len(pattern) == 1 else partial(b, pattern[1:])
            band_apply(self.bands[0][pattern[0]], inner, 0, out[a], coef)
        return out

    def diagonal(self) -> np.ndarray:
        """diag K as a lattice field."""
        out = np.zeros(self.shape)
        for a, b, pattern, coef in self.terms:
            if a != b:
                continue
            d = coef
            for r, name in enumerate(pattern):
                d = (
                    np.multiply.outer(d, self.bands[r][name][2])
                    if r
                    else d * self.bands[r][name][2]
                )
            out[a] += d
        return out

    def norm_bound(self) -> float:
        """An upper bound of ||K||_inf: sum over the terms of |coefficient| times the
        product of the 1-D matrices' infinity norms."""
        total = np.zeros(len(self.axes))
        for a, b, pattern, coef in self.terms:
            total[a] += abs(coef) * np.prod(
                [np.abs(self.bands[r][n]).sum(axis=0).max() for r, n in enumerate(pattern)]
            )
        return float(total.max())
