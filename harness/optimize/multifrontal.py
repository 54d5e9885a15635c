"""Multifrontal sparse Cholesky on a geometric nested-dissection tree, numpy/LAPACK only.

scipy has no sparse Cholesky (CHOLMOD is not installed) and SuperLU is slow on 3-D spring
networks even with a good ordering. Here every node of the dissection tree (a leaf block
or a separator) gets a dense frontal matrix over its own dofs V and its update set U (the
ancestor dofs coupled to V or to its subtree): partial Cholesky of the front, then the
Schur complement on U is added into the parent's front. All arithmetic is dense BLAS-3.

The symbolic part (tree, fronts, index maps) depends only on the sparsity pattern and is
built once per load set; ``factor(K)`` is numeric only.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from harness.errors import ModelError
from harness.optimize.linalg import dissection_tree

LEAF = 256


class Symbolic:
    """Elimination tree, fronts and assembly maps for a fixed pattern (csr, symmetric)."""

    def __init__(self, pattern: sp.spmatrix, coords: np.ndarray, leaf: int = LEAF):
        A = sp.csr_matrix(pattern)
        A.sort_indices()
        n = A.shape[0]
        self.n = n
        coords = np.asarray(coords, float)
        nodes = dissection_tree(A, coords, leaf)  # (V, children) in postorder
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
            cols = A.indices[np.concatenate([np.arange(A.indptr[v], A.indptr[v + 1]) for v in V])] if len(V) else np.empty(0, int)
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
            # original entries: rows V, columns in the front (V or U) -> F[:nv, :] and mirror
            ptr = [np.arange(A.indptr[v], A.indptr[v + 1]) for v in V]
            kidx = np.concatenate(ptr) if ptr else np.empty(0, np.int64)
            rows = np.repeat(np.arange(nv), [len(p) for p in ptr]) if ptr else np.empty(0, np.int64)
            cl = pos[A.indices[kidx]]
            keep = cl >= 0
            kidx, rows, cl = kidx[keep], rows[keep], cl[keep]
            direct = rows * nf + cl
            upper = cl >= nv
            mirror = cl[upper] * nf + rows[upper]
            child_maps = [pos[U_of[c]] for c in kids]
            start = int(rank[V[0]]) if nv else 0
            self.nodes.append(dict(V=V, U=U, nv=nv, nf=nf, kids=kids, kidx=kidx, direct=direct,
                                   mirror=mirror, kidx_m=kidx[upper], child_maps=child_maps,
                                   sl=slice(start, start + nv), Ur=rank[U]))
            pos[front] = -1
        self.parent = parent
        self.order = order


class MultifrontalCholesky:
    """Numeric factorisation for a Symbolic pattern; ``solve`` takes (n,) or (n, m)."""

    def __init__(self, K: sp.spmatrix, sym: Symbolic, name: str = ""):
        from harness.optimize.linalg import single_thread_blas
        with single_thread_blas():   # many small dense ops: threads only add overhead
            self._factor(K, sym, name)

    def _factor(self, K, sym, name):
        K = sp.csr_matrix(K)
        K.sort_indices()
        data = K.data
        self.sym = sym
        self.L11, self.L21 = [], []
        updates = {}
        for t, nd in enumerate(sym.nodes):
            nf, nv = nd["nf"], nd["nv"]
            F = np.zeros(nf * nf)
            F[nd["direct"]] = data[nd["kidx"]]
            F[nd["mirror"]] = data[nd["kidx_m"]]
            F = F.reshape(nf, nf)
            for c, loc in zip(nd["kids"], nd["child_maps"]):
                Uc = updates.pop(c)
                if len(loc):
                    F[np.ix_(loc, loc)] += Uc
            if nv:
                try:
                    L11 = sla.cholesky(F[:nv, :nv], lower=True, check_finite=False)
                except np.linalg.LinAlgError:
                    raise ModelError(f"load '{name}': stiffness matrix is not positive definite", field="springs",
                                     fix="the network has a mechanism or floating node, or a spring constant <= 0") from None
                d = np.diag(L11)
                if d.min() < 1e-7 * d.max():
                    raise ModelError(f"load '{name}': stiffness matrix is singular (pivot ratio {d.min() / d.max():.1e})",
                                     field="springs", fix="the network has a mechanism or floating node")
                L21 = sla.solve_triangular(L11, F[nv:, :nv].T, lower=True, check_finite=False).T if nf > nv else np.empty((0, nv))
            else:
                L11, L21 = np.empty((0, 0)), np.empty((nf, 0))
            if nf > nv:
                C = sla.blas.dsyrk(-1.0, L21, beta=1.0, c=np.asfortranarray(F[nv:, nv:]), lower=1) if nv else F[nv:, nv:]
                if nv:
                    C = np.tril(C)
                    C = C + np.tril(C, -1).T
                updates[t] = C
            else:
                updates[t] = np.empty((0, 0))
            self.L11.append(L11)
            self.L21.append(np.ascontiguousarray(L21))

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Forward and back substitution front by front, in elimination order (each
        front's own dofs are a contiguous slice there)."""
        from harness.optimize.linalg import single_thread_blas
        with single_thread_blas():
            return self._solve(rhs)

    def _solve(self, rhs):
        rhs = np.asarray(rhs, float)
        vec = rhs.ndim == 1
        order = self.sym.order
        b = rhs[order][:, None] if vec else rhs[order]
        b = np.ascontiguousarray(b)
        trtrs = sla.lapack.dtrtrs
        for nd, L11, L21 in zip(self.sym.nodes, self.L11, self.L21):
            if nd["nv"] == 0:
                continue
            sl = nd["sl"]
            y = trtrs(L11, b[sl], lower=1)[0]
            b[sl] = y
            if len(nd["Ur"]):
                b[nd["Ur"]] -= L21 @ y
        for nd, L11, L21 in zip(reversed(self.sym.nodes), reversed(self.L11), reversed(self.L21)):
            if nd["nv"] == 0:
                continue
            sl = nd["sl"]
            y = b[sl]
            if len(nd["Ur"]):
                y = y - L21.T @ b[nd["Ur"]]
            b[sl] = trtrs(L11, y, lower=1, trans=1)[0]
        out = np.empty_like(b)
        out[order] = b
        return out[:, 0] if vec else out
