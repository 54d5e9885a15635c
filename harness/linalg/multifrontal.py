"""Multifrontal sparse Cholesky on a geometric nested-dissection tree (numpy/LAPACK, and
a numba-compiled substitution for many right-hand sides).

scipy has no sparse Cholesky (CHOLMOD is not installed; the PyPI wheel measured ~1.3x
SuperLU) and SuperLU is slow on 3-D spring networks even with a good ordering. Here
every node of the dissection tree (a leaf block or a separator) gets a dense frontal
matrix over its own dofs V and its update set U (the ancestor dofs coupled to V or to
its subtree): partial Cholesky of the front, then the Schur complement on U is added
into the parent's front. All arithmetic is dense BLAS-3. Measured (one thread, factor +
one solve): 2-D 2,500 nodes 15-18 ms vs SuperLU in nested-dissection order 25-30 ms;
3-D 8,000 nodes 1.3 s vs 3.7 s. Used by the fits, by the SA baseline and, with leaves of
64 dofs and batched solves of 64 right-hand sides, by the incremental SA engine.

The symbolic part (tree, fronts, index maps) depends only on the sparsity pattern and is
built once per load set; ``factor(K)`` is numeric only.
"""

from __future__ import annotations

import contextlib

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from harness.errors import ModelError
from harness.linalg.sparse import (
    blas_limited,
    dissection_tree,
    outer_blas_threads,
    row_entries,
    single_thread_blas,
)

# dofs per leaf front: best measured for factor + solve (2-D 2,500: 16 vs 18 ms at 256;
# 3-D 8,000: 1.16 vs 1.33 s)
LEAF = 128
BIG_FRONT = 1000  # fronts of at least this many dofs factorise with every BLAS thread the caller
# allows (a 104k-dof spring network of a 200k-tet mesh: 107 fronts, 95 % of the flops)


def _tree(A: sp.csr_matrix, coords: np.ndarray, leaf: int, last) -> list:
    """The dissection tree of A (:func:`dissection_tree`), with the dofs ``last`` (None: none)
    kept out of it and eliminated after it, as one root front."""
    if last is None or not len(last):
        return dissection_tree(A, coords, leaf)
    last = np.asarray(last, np.int64)
    rest = np.setdiff1d(np.arange(A.shape[0]), last)
    sub = dissection_tree(A[rest][:, rest], coords[rest], leaf) if len(rest) else []
    return [(rest[V], kids) for V, kids in sub] + [(last, [len(sub) - 1] if sub else [])]


class Symbolic:
    """Elimination tree, fronts and assembly maps for a fixed pattern (csr, symmetric);
    ``last``: dofs eliminated after all others, as the root front (harness/linalg/shared.py
    keeps that front unfactored)."""

    def __init__(self, pattern: sp.spmatrix, coords: np.ndarray, leaf: int = LEAF, last=None):
        A = sp.csr_matrix(pattern)
        A.sort_indices()
        n = A.shape[0]
        self.n = n
        coords = np.asarray(coords, float)
        nodes = _tree(A, coords, leaf, last)  # (V, children) in postorder
        # elimination order: postorder of the tree, each node's V contiguous
        order = np.concatenate([V for V, _ in nodes])
        rank = np.empty(n, np.int64)
        rank[order] = np.arange(n)
        self.nodes = []
        U_of = []
        parent = [-1] * len(nodes)
        for t, (V, kids) in enumerate(nodes):
            for c in kids:
                parent[c] = t
        for t, (V, kids) in enumerate(nodes):
            top = rank[V].max(initial=-1)
            cols = A.indices[row_entries(A.indptr, V)[0]]
            cand = [cols[rank[cols] > top]] + [U_of[c][rank[U_of[c]] > top] for c in kids]
            U = np.unique(np.concatenate(cand)) if cand else np.empty(0, int)
            U = U[np.argsort(rank[U])]
            U_of.append(U)
        pos = np.full(n, -1, np.int64)
        for t, (V, kids) in enumerate(nodes):
            U = U_of[t]
            front = np.concatenate([V, U])
            nv, nf = len(V), len(front)
            pos[front] = np.arange(nf)
            # original entries of rows V into the front's lower triangle: (row, column) when
            # the column is an earlier V dof, its mirror (column, row) when it is in U
            kidx, rows = row_entries(A.indptr, V)
            cl = pos[A.indices[kidx]]
            keep = (cl >= 0) & ((cl <= rows) | (cl >= nv))
            kidx, rows, cl = kidx[keep], rows[keep], cl[keep]
            lower = np.where(cl >= nv, cl * nf + rows, rows * nf + cl)
            start = int(rank[V[0]]) if nv else 0
            self.nodes.append(
                dict(
                    V=V,
                    U=U,
                    nv=nv,
                    nf=nf,
                    kids=kids,
                    kidx=kidx,
                    lower=lower,
                    child_maps=[pos[U_of[c]] for c in kids],
                    sl=slice(start, start + nv),
                    Ur=rank[U],
                )
            )
            pos[front] = -1
        self.parent = parent
        self.order = order
        self.indptr, self.indices = A.indptr, A.indices  # the pattern the maps index

    def estimate(self) -> dict:
        """Work (Gflop) and peak memory (GB: the factor, plus the largest front and its
        Schur complement and product, measured ~3 of them) of the factorisation."""
        nv = np.array([nd["nv"] for nd in self.nodes], float)
        nu = np.array([len(nd["U"]) for nd in self.nodes], float)
        flop = np.sum(nv**3 / 3 + nv**2 * nu + nv * nu**2)
        mem = 8 * (np.sum(nv * (nv + nu)) + 3 * np.max((nv + nu) ** 2, initial=0.0))
        return {"gflop": float(flop / 1e9), "gbytes": float(mem / 1e9)}


_NOTHING = contextlib.nullcontext()


def _csr_data(K: sp.spmatrix, sym: Symbolic) -> np.ndarray:
    """K's values in the order of the symbolic pattern's csr arrays. A csc matrix on that
    pattern is taken as it is: the pattern is symmetric, so its csc arrays are the csr
    ones, and the factorisation reads K as symmetric anyway (rows of each front only)."""
    if sp.issparse(K) and K.format in ("csr", "csc") and K.has_sorted_indices:
        if np.array_equal(K.indptr, sym.indptr) and np.array_equal(K.indices, sym.indices):
            return K.data
    K = sp.csr_matrix(K)
    K.sort_indices()
    return K.data


def _partial(F: np.ndarray, nv: int, potrf, trtrs, name: str):
    """(L11, L21, Schur complement on the update set) of a front F (nf, nf) whose first nv
    dofs are eliminated. Only F's lower triangle is read and only the complement's lower
    triangle is formed (SYRK: half GEMM's flops): a front's dofs are in elimination order,
    so the parent's assembly maps a child's lower triangle into its own lower triangle."""
    nf = F.shape[0]
    L11, info = potrf(F[:nv, :nv], lower=1, clean=1, overwrite_a=0)
    if info != 0:
        raise ModelError(
            f"load '{name}': stiffness matrix is not positive definite",
            field="springs",
            fix="the network has a mechanism or floating node, or a spring constant <= 0",
        )
    d = np.diag(L11)
    if d.min() < 1e-7 * d.max():
        raise ModelError(
            f"load '{name}': stiffness matrix is singular (pivot ratio {d.min() / d.max():.1e})",
            field="springs",
            fix="the network has a mechanism or floating node",
        )
    if nf == nv:
        return L11, np.empty((0, nv)), np.empty((0, 0))
    X = trtrs(L11, F[nv:, :nv].T, lower=1)[0]  # L11^-1 F21^T = L21^T
    S = sla.blas.dsyrk(-1.0, X, beta=1.0, c=F[nv:, nv:], trans=1, lower=1)  # F22 - X^T X (lower)
    return L11, X.T, S


class MultifrontalCholesky:
    """Numeric factorisation for a Symbolic pattern; ``solve`` takes (n,) or (n, m).
    ``keep_root``: the root front is assembled but not factorised (``root``: its lower
    triangle holds the Schur complement on the root's dofs), for callers that factorise
    parts of it themselves (harness/linalg/shared.py); ``solve`` is then not available."""

    def __init__(self, K: sp.spmatrix, sym: Symbolic, name: str = "", keep_root: bool = False):
        threaded = not blas_limited()  # a caller that asked for one thread keeps it
        self.root = None
        with single_thread_blas():  # many small dense ops: threads only add overhead
            self._factor(K, sym, name, threaded, keep_root)

    def _factor(self, K, sym, name, threaded=False, keep_root=False):
        data = _csr_data(K, sym)
        potrf, trtrs = sla.lapack.dpotrf, sla.lapack.dtrtrs
        scatter, extend_add = _assembly_kernels()
        self.sym = sym
        self.L11, self.L21 = [], []
        updates = {}
        for t, nd in enumerate(sym.nodes):
            nf, nv = nd["nf"], nd["nv"]
            # the front's lower triangle (all that is read): K's entries, children's updates
            F = np.zeros(nf * nf)
            scatter(F, data, nd["kidx"], nd["lower"])
            for c, loc in zip(nd["kids"], nd["child_maps"]):
                extend_add(F, nf, loc, updates.pop(c))
            F = F.reshape(nf, nf)
            if keep_root and t == len(sym.nodes) - 1:
                self.root = F
                break
            if nv:
                with outer_blas_threads() if threaded and nf >= BIG_FRONT else _NOTHING:
                    L11, L21, updates[t] = _partial(F, nv, potrf, trtrs, name)
            else:
                L11, L21 = np.empty((0, 0)), np.empty((nf, 0))
                updates[t] = F
            self.L11.append(L11)
            self.L21.append(np.ascontiguousarray(L21))

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Forward and back substitution front by front, in elimination order (each
        front's own dofs are a contiguous slice there). Many right-hand sides at once
        (the SA engine's batches) go through a compiled loop over the fronts with the
        inverted diagonal blocks (:func:`_subst`); ``_solve`` is the LAPACK version."""
        if self.root is not None:
            raise ValueError("a factorisation with its root kept (keep_root) solves by its owner")
        rhs = np.asarray(rhs, float)
        with single_thread_blas():
            many = rhs.ndim == 2 and rhs.shape[1] >= SUBST_MIN
            if (
                many or getattr(self, "_flat_cache", None) is not None
            ) and _subst_kernel() is not None:
                return self._solve_compiled(rhs.reshape(len(rhs), -1)).reshape(rhs.shape)
            return self._solve(rhs)

    def _flat(self, drop: bool = False):
        """The factor as flat arrays for the compiled substitution: per front its first
        row, sizes and offsets; inverted L11 blocks and L21 blocks (row-major). ``drop``
        frees the LAPACK path's blocks as they are copied (the factor is held once, not
        twice; numba is then required)."""
        if getattr(self, "_flat_cache", None) is None:
            keep = [t for t, nd in enumerate(self.sym.nodes) if nd["nv"]]
            nv = np.array([self.sym.nodes[t]["nv"] for t in keep], np.int64)
            nu = np.array([len(self.sym.nodes[t]["Ur"]) for t in keep], np.int64)
            start = np.array([self.sym.nodes[t]["sl"].start for t in keep], np.int64)
            off = lambda sizes: np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
            o11, o21 = off(nv * nv), off(nv * nu)
            Li, L21 = np.empty(o11[-1]), np.empty(o21[-1])
            for j, t in enumerate(keep):
                Li[o11[j] : o11[j + 1]] = sla.lapack.dtrtri(self.L11[t], lower=1)[0].ravel()
                L21[o21[j] : o21[j + 1]] = self.L21[t].ravel()
                if drop:
                    self.L11[t] = self.L21[t] = None
            Ur = np.concatenate(
                [self.sym.nodes[t]["Ur"] for t in keep] + [np.empty(0, np.int64)]
            ).astype(np.int64)
            self._flat_cache = (start, nv, nu, o11, o21, off(nu), Li, L21, Ur)
            if drop:  # every later solve takes the compiled path: the blocks are not needed
                self.L11 = self.L21 = None
        return self._flat_cache

    def solve_ordered(self, b: np.ndarray) -> np.ndarray:
        """Solve in place for a C-contiguous (n, q) right-hand side already in elimination
        order (``sym.order``): callers that keep their vectors in that order (the SA engine)
        skip the two row permutations of every solve. Needs numba."""
        with single_thread_blas():
            _subst_kernel()(b, *self._flat())
        return b

    def _solve_compiled(self, rhs):
        order = self.sym.order
        b = np.ascontiguousarray(rhs[order])
        # every later solve takes this path too (solve): the blocks are dropped as copied
        _subst_kernel()(b, *self._flat(drop=True))
        out = np.empty_like(b)
        out[order] = b
        return out

    def _solve(self, rhs):
        rhs = np.asarray(rhs, float)
        vec = rhs.ndim == 1
        order = self.sym.order
        b = rhs[order][:, None] if vec else rhs[order]
        b = np.ascontiguousarray(b)
        self.forward(b)
        self.backward(b)
        out = np.empty_like(b)
        out[order] = b
        return out[:, 0] if vec else out

    def forward(self, b: np.ndarray) -> None:
        """L y = b in place over the factorised fronts, b (n, q) in elimination order (with
        ``keep_root``: the root's rows receive the updates, the Schur right-hand side)."""
        trtrs = sla.lapack.dtrtrs
        for nd, L11, L21 in zip(self.sym.nodes, self.L11, self.L21):
            if nd["nv"] == 0:
                continue
            sl = nd["sl"]
            y = trtrs(L11, b[sl], lower=1)[0]
            b[sl] = y
            if len(nd["Ur"]):
                b[nd["Ur"]] -= L21 @ y

    def backward(self, b: np.ndarray) -> None:
        """L^T x = y in place over the factorised fronts (with ``keep_root``: the root's rows
        of b already hold their solution)."""
        trtrs = sla.lapack.dtrtrs
        nodes = self.sym.nodes[: len(self.L11)]
        for nd, L11, L21 in zip(reversed(nodes), reversed(self.L11), reversed(self.L21)):
            if nd["nv"] == 0:
                continue
            sl = nd["sl"]
            y = b[sl]
            if len(nd["Ur"]):
                y = y - L21.T @ b[nd["Ur"]]
            b[sl] = trtrs(L11, y, lower=1, trans=1)[0]


SUBST_MIN = 8  # right-hand sides from which inverting the diagonal blocks pays (later
# solves with the same factor then take the compiled path too)
_KERNEL = []


def _subst(b, start, nv, nu, oL, o21, oU, Li, L21, Ur):
    """L L^T x = b in place for the fronts' flat arrays (see ``_flat``); compiled by numba."""
    q = b.shape[1]
    nn = len(start)
    cols = np.empty(q, np.int64)
    for t in range(nn):
        s0, k, u = start[t], nv[t], nu[t]
        nz = 0  # right-hand sides not yet reaching this front stay 0:
        for c in range(q):  # sparse b (the SA batches) skips most leaf work
            for r in range(s0, s0 + k):
                if b[r, c] != 0.0:
                    cols[nz] = c
                    nz += 1
                    break
        if nz == 0:
            continue
        if nz == q:
            y = np.dot(Li[oL[t] : oL[t + 1]].reshape(k, k), b[s0 : s0 + k])
            b[s0 : s0 + k] = y
        else:
            bb = np.empty((k, nz))
            for r in range(k):
                for c in range(nz):
                    bb[r, c] = b[s0 + r, cols[c]]
            y = np.dot(Li[oL[t] : oL[t + 1]].reshape(k, k), bb)
            for r in range(k):
                for c in range(nz):
                    b[s0 + r, cols[c]] = y[r, c]
        if u:
            w = np.dot(L21[o21[t] : o21[t + 1]].reshape(u, k), y)
            for i in range(u):
                r = Ur[oU[t] + i]
                if nz == q:
                    for c in range(q):
                        b[r, c] -= w[i, c]
                else:
                    for c in range(nz):
                        b[r, cols[c]] -= w[i, c]
    for t in range(nn - 1, -1, -1):
        s0, k, u = start[t], nv[t], nu[t]
        y = b[s0 : s0 + k].copy()
        if u:
            g = np.empty((u, q))
            for i in range(u):
                r = Ur[oU[t] + i]
                for c in range(q):
                    g[i, c] = b[r, c]
            y -= np.dot(L21[o21[t] : o21[t + 1]].reshape(u, k).T, g)
        b[s0 : s0 + k] = np.dot(Li[oL[t] : oL[t + 1]].reshape(k, k).T, y)


def _scatter(F, data, kidx, at):
    """F[at[i]] = data[kidx[i]]: a front's entries of K (compiled by numba)."""
    for i in range(len(at)):
        F[at[i]] = data[kidx[i]]


def _extend_add(F, nf, loc, U):
    """F[loc[i], loc[j]] += U[i, j] over U's lower triangle, F flat (nf * nf): a child's
    Schur complement into its parent's front (compiled by numba)."""
    m = len(loc)
    for j in range(m):
        cj = loc[j]
        for i in range(j, m):
            F[loc[i] * nf + cj] += U[i, j]


_ASSEMBLY = []


def _assembly_kernels():
    """numba-compiled :func:`_scatter` and :func:`_extend_add`. With numpy's fancy indexing
    the assembly took 40 % of a factorisation of the fits' 1,900-dof fronts (precomputed
    flat indices, both triangles); compiled and on the lower triangle only, ~10 %."""
    if not _ASSEMBLY:
        import numba

        jit = numba.njit(cache=True, nogil=True)
        _ASSEMBLY.extend([jit(_scatter), jit(_extend_add)])
    return _ASSEMBLY


def _subst_kernel():
    """numba-compiled :func:`_subst` (None without numba). Per front two small matrix
    products (BLAS) and a row scatter/gather; in plain numpy the per-front call overhead
    (~100-300 fronts x 8 calls) costs as much as the flops for the SA engine's batches of
    32-64 right-hand sides (``bench sa``)."""
    if not _KERNEL:
        import numba

        _KERNEL.append(numba.njit(cache=True, nogil=True)(_subst))
    return _KERNEL[0]


def warm_up() -> bool:
    """Compile (first time) or load the cached substitution kernel (numba, a dependency)."""
    k = _subst_kernel()
    if k is not None and len(_KERNEL) == 1:
        z = np.zeros(1, np.int64)
        k(np.zeros((1, 1)), z[:0], z[:0], z[:0], z, z, z, np.zeros(0), np.zeros(0), z[:0])
        _KERNEL.append(True)
    return k is not None
