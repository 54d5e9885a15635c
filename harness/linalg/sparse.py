"""Sparse SPD factorisation for the optimisers, and BLAS thread control.

SuperLU's own orderings (COLAMD, MMD) fill in badly on 3-D spring networks (a 20^3
grid: 64 M nonzeros, 40 s). A nested-dissection ordering computed here from the
vertices' coordinates and the matrix graph (median bisections, each separator a minimum
vertex cover of the cut) cuts that to ~20 M and ~7 s, and helps in 2-D too; SuperLU then
factorises with the NATURAL order and no pivoting, the multifrontal Cholesky
(harness/linalg/multifrontal.py) on the same tree.
"""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import maximum_bipartite_matching

from harness.errors import ModelError

LEAF = 96


def row_entries(indptr: np.ndarray, V: np.ndarray):
    """(positions of rows V's entries in a csr matrix's arrays, row of each within V)."""
    V = np.asarray(V, np.int64)
    first = indptr[V].astype(np.int64)
    count = indptr[V + 1].astype(np.int64) - first
    rows = np.repeat(np.arange(len(V), dtype=np.int64), count)
    return np.repeat(first - (np.cumsum(count) - count), count) + np.arange(len(rows)), rows


def dissection_tree(A: sp.spmatrix, coords: np.ndarray, leaf: int = LEAF) -> list:
    """Nested-dissection tree of symmetric A with vertex coordinates (n, dim): recursive
    bisection at the median of the widest coordinate; the separator is the smallest set of
    vertices that covers every edge across the cut (:func:`_cover`). Returns [(vertices,
    child node ids)] in postorder (children before their separator), so concatenating the
    vertices gives the order."""
    A = sp.csr_matrix(A)
    A = sp.csr_matrix((np.ones(A.nnz), A.indices, A.indptr), shape=A.shape)
    coords = np.asarray(coords, float)
    nodes: list = []
    pos = np.full(A.shape[0], -1, np.int64)

    def rec(idx: np.ndarray) -> int:
        left = None
        if len(idx) > leaf:
            c = coords[idx][:, int(np.argmax(np.ptp(coords[idx], axis=0)))]
            m = np.median(c)
            left = c < m
            if left.all() or not left.any():
                left = c <= m
                if left.all():
                    left = None
        if left is None:
            nodes.append((idx, []))
            return len(nodes) - 1
        sep = _cover(A, idx, left, pos)
        kids = [rec(part) for part in (idx[left & ~sep], idx[~left & ~sep]) if len(part)]
        nodes.append((idx[sep], kids))
        return len(nodes) - 1

    rec(np.arange(A.shape[0]))
    return nodes


# edges per vertex of a cut above which the matching is not worth its time: scipy's
# Hopcroft-Karp took 0.2 ms on a P2 cut of 726 vertices and 6,460 edges (8.9 per vertex),
# 0.24 s on a cut of 1,869 and 101,592 (54: the Galerkin matrices of coarse levels couple
# that widely, and a 214k-dof one ran for over half an hour); there the cover is the
# smaller of the two layers that touch the other side
DENSE_CUT = 20


def _cover(A: sp.csr_matrix, idx: np.ndarray, left: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """Mask over idx of a minimum vertex cover of the edges between idx[left] and
    idx[~left] (König: from a maximum matching, the left vertices no alternating path from
    an unmatched left vertex reaches, and the right ones it reaches). On P2 tetrahedra it
    is about half the layer of left vertices that touch the right side (a 49k-dof lug:
    18 instead of 64 Gflop to factorise); on a dense cut (DENSE_CUT) the smaller of the two
    touching layers. ``pos``: -1 for every vertex, as it is left."""
    L, R = np.flatnonzero(left), np.flatnonzero(~left)
    at, rows = row_entries(A.indptr, idx[L])
    pos[idx[R]] = np.arange(len(R))
    cols = pos[A.indices[at]]
    pos[idx[R]] = -1
    rows = rows[cols >= 0]
    sep = np.zeros(len(idx), bool)
    if not len(rows):
        return sep
    rows, r = np.unique(rows, return_inverse=True)
    cols, c = np.unique(cols[cols >= 0], return_inverse=True)
    B = sp.csr_matrix((np.ones(len(r)), (r, c)), shape=(len(rows), len(cols)))
    if B.nnz > DENSE_CUT * sum(B.shape):  # the matching's time: the smaller touching layer
        sep[L[rows] if len(rows) <= len(cols) else R[cols]] = True
        return sep
    match = maximum_bipartite_matching(B, perm_type="column")  # column of each row, or -1
    owner = np.full(len(cols), -1)
    owner[match[match >= 0]] = np.flatnonzero(match >= 0)
    seen_r, seen_c = match < 0, np.zeros(len(cols), bool)
    frontier = np.flatnonzero(seen_r)
    while len(frontier):
        reached = np.unique(B[frontier].indices)
        reached = reached[~seen_c[reached]]
        seen_c[reached] = True
        frontier = owner[reached]
        frontier = frontier[frontier >= 0]
        frontier = frontier[~seen_r[frontier]]
        seen_r[frontier] = True
    sep[L[rows[~seen_r]]] = True
    sep[R[cols[seen_c]]] = True
    return sep


def nested_dissection(A: sp.spmatrix, coords: np.ndarray) -> np.ndarray:
    """A fill-reducing permutation of symmetric A (separators numbered last)."""
    return np.concatenate([V for V, _ in dissection_tree(A, coords)])


class Factor:
    """LU (no pivoting, so effectively LDL^T) of an SPD matrix in nested-dissection order.
    ``solve`` takes a vector or a (n, m) block of right-hand sides."""

    def __init__(self, K: sp.spmatrix, perm: np.ndarray | None = None, name: str = ""):
        K = sp.csc_matrix(K)
        self.perm = perm
        try:
            if perm is None:  # no coordinates: SuperLU's minimum degree on A^T + A
                self.lu = spla.splu(
                    K,
                    permc_spec="MMD_AT_PLUS_A",
                    diag_pivot_thresh=0.0,
                    options=dict(SymmetricMode=True),
                )
            else:
                self.iperm = np.empty_like(perm)
                self.iperm[perm] = np.arange(len(perm))
                self.lu = spla.splu(
                    K[perm][:, perm].tocsc(),
                    permc_spec="NATURAL",
                    diag_pivot_thresh=0.0,
                    options=dict(SymmetricMode=True),
                )
        except RuntimeError as exc:
            raise ModelError(
                f"load '{name}': stiffness matrix is singular ({exc})",
                field="springs",
                fix="the network has a mechanism or floating node; add springs or constraints",
            ) from None
        d = self.lu.U.diagonal()
        if np.any(d <= 0) or np.min(d) < 1e-13 * np.max(d):
            raise ModelError(
                f"load '{name}': stiffness matrix is singular or indefinite (pivot ratio "
                f"{np.min(d) / np.max(d):.1e})",
                field="springs",
                fix="the network has a mechanism or floating node, or a spring constant <= 0",
            )

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        if self.perm is None:
            return self.lu.solve(np.asarray(rhs, float))
        x = self.lu.solve(np.ascontiguousarray(rhs[self.perm]))
        return x[self.iperm]


class DenseFactor:
    """Cholesky of a small dense SPD matrix (cheaper than sparse machinery below ~400 dofs)."""

    def __init__(self, K: np.ndarray, name: str = ""):
        import scipy.linalg as sla

        try:
            self.c = sla.cho_factor(K, lower=True, check_finite=False)
        except np.linalg.LinAlgError:
            raise ModelError(
                f"load '{name}': stiffness matrix is singular or indefinite",
                field="springs",
                fix="the network has a mechanism or floating node, or a spring constant <= 0",
            ) from None
        d = np.diag(self.c[0])
        if np.min(d) < 1e-7 * np.max(d):
            raise ModelError(
                f"load '{name}': stiffness matrix is singular (pivot ratio "
                f"{np.min(d) / np.max(d):.1e})",
                field="springs",
                fix="the network has a mechanism or floating node",
            )

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        import scipy.linalg as sla

        return sla.cho_solve(self.c, rhs, check_finite=False)


# --- BLAS threads ------------------------------------------------------------------------
_ONE_THREAD = 0  # depth of nested single_thread_blas blocks
_OUTER = 1  # BLAS threads in effect when the outermost block began
_CONTROLLER: list = []  # [(len(sys.modules) when built, threadpoolctl.ThreadpoolController)]


def blas_controller():
    """The process's threadpoolctl controller, built again only when modules were imported
    since (a new module may load a BLAS library): building one scans every shared library
    the process has loaded (~2 ms in calibrate's process), and the fits enter a one-thread
    block for every factorisation and solve, thousands of times."""
    import sys

    if not _CONTROLLER or _CONTROLLER[0][0] != len(sys.modules):
        from threadpoolctl import ThreadpoolController

        _CONTROLLER[:] = [(len(sys.modules), ThreadpoolController())]
    return _CONTROLLER[0][1]


def _blas_threads(controller) -> int:
    """The most threads a BLAS library of ``controller`` runs now (1 without one)."""
    return max(
        [lib.num_threads for lib in controller.lib_controllers if lib.user_api == "blas"] or [1]
    )


@contextmanager
def seeded_numpy(seed: int = 0):
    """Run the block with numpy's global random state seeded (and put it back after): pyamg
    draws the start vector of its spectral-radius estimate from it, so an AMG hierarchy,
    and every solve it accepts, would differ from run to run at the solver's tolerance."""
    state = np.random.get_state()
    np.random.seed(seed)
    try:
        yield
    finally:
        np.random.set_state(state)


@contextmanager
def single_thread_blas():
    """Run the block with one BLAS thread: threads do not speed up a chain's small dense
    products, and the other core runs another chain. Nested blocks cost nothing (the
    outer one already holds the limit); an outermost one costs ~40 us (a cached
    controller, :func:`blas_controller`)."""
    global _ONE_THREAD, _OUTER
    if _ONE_THREAD:
        _ONE_THREAD += 1
        try:
            yield
        finally:
            _ONE_THREAD -= 1
        return
    controller = blas_controller()
    _OUTER = _blas_threads(controller)
    with controller.limit(limits=1):
        _ONE_THREAD += 1
        try:
            yield
        finally:
            _ONE_THREAD -= 1


def blas_limited() -> bool:
    """Whether a single_thread_blas block is running (a caller asked for one thread)."""
    return _ONE_THREAD > 0


@contextmanager
def outer_blas_threads():
    """Inside single_thread_blas: the BLAS threads from before it (a pool worker's one, or
    the machine's cores) for a block of large dense products; outside: nothing changes."""
    if not _ONE_THREAD or _OUTER <= 1:
        yield
        return
    with blas_controller().limit(limits=_OUTER, user_api="blas"):
        yield
