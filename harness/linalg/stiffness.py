"""The map from spring constants to the stiffness matrix K = B diag(k) B^T of a fixed
incidence B: computed once per B, it turns every later assembly into one sparse
matrix-vector product (the fits assemble K thousands of times)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def stiffness_pattern(B: sp.csc_matrix) -> sp.csc_matrix:
    """The pattern of B B^T (csc, sorted indices, zero values): every entry any k can fill,
    all an ordering or a symbolic factorisation needs (without P's memory: on a 50k-tet
    mesh with a volume term per node, P and its construction take ~1.5 GB per load set)."""
    B = sp.csc_matrix(B)
    B.sort_indices()
    pattern = (abs(B) @ abs(B).T).tocsc()
    pattern.sort_indices()
    pattern.data[:] = 0.0
    return pattern


def stiffness_map(B: sp.csc_matrix):
    """Pattern of B B^T (csc) and the sparse matrix P with K.data = P @ k."""
    B = sp.csc_matrix(B)
    B.sort_indices()
    n, e = B.shape
    pattern = stiffness_pattern(B)
    # col*n + row
    keys = np.repeat(np.arange(n, dtype=np.int64), np.diff(pattern.indptr)) * n + pattern.indices
    # every pair (a, b) of nonzeros of each column j adds B[a, j] B[b, j] k_j to K[b, a];
    # built over blocks of columns (the same entries in the same order as all at once): the
    # index arithmetic's temporaries stay a block's, not ~10 arrays of every pair's
    cnt = np.diff(B.indptr).astype(np.int64)
    sq = cnt * cnt
    ends = np.cumsum(sq)
    cuts = np.searchsorted(ends, np.arange(PAIRS_PER_BLOCK, ends[-1] if e else 0, PAIRS_PER_BLOCK))
    bounds = np.unique(np.concatenate([[0], cuts, [e]]))
    rows = np.empty(int(ends[-1]) if e else 0, np.int64)
    data = np.empty(len(rows))
    for j0, j1 in zip(bounds[:-1], bounds[1:]):
        at = slice(int(ends[j0] - sq[j0]), int(ends[j1 - 1]))
        rows[at], data[at] = _pairs(B, keys, n, cnt[j0:j1], sq[j0:j1], j0)
    # the pairs come column by column: P's csc arrays as they are, then its rows
    indptr = np.concatenate([[0], ends]) if e else np.zeros(1, np.int64)
    P = sp.csc_matrix((data, rows, indptr), shape=(len(keys), e)).tocsr()
    return pattern, P


PAIRS_PER_BLOCK = 2_000_000


def _pairs(B, keys, n, cnt, sq, j0):
    """(row of K.data, B[a, j] B[b, j]) of every pair of nonzeros of columns j0, j0 + 1, ..."""
    col = np.repeat(np.arange(len(cnt), dtype=np.int64), sq)
    t = np.arange(len(col), dtype=np.int64) - np.repeat(np.cumsum(sq) - sq, sq)
    c = cnt[col]
    first = B.indptr[j0 + col].astype(np.int64)
    pa, pb = first + t // c, first + t % c
    ia, ib = B.indices[pa].astype(np.int64), B.indices[pb].astype(np.int64)
    return np.searchsorted(keys, ib * n + ia), B.data[pa] * B.data[pb]


def restriction(pattern: sp.csc_matrix, dofs: np.ndarray) -> tuple[sp.csc_matrix, np.ndarray]:
    """The pattern of K on ``dofs`` (ascending ids of ``pattern``'s rows) and where each of
    its entries sits in ``pattern.data``: K_dofs.data = K.data[gather]. The same entries as
    :func:`stiffness_pattern` of B's rows ``dofs`` (an entry is there when a column touches
    both dofs), so a restriction of one whole-network map gives every load set's K, value
    for value as its own map would (each entry sums the same columns in the same order)."""
    dofs = np.asarray(dofs, np.int64)
    numbered = pattern.copy()
    numbered.data = np.arange(1, pattern.nnz + 1, dtype=float)  # exact below 2**53
    sub = numbered[dofs][:, dofs].tocsc()
    sub.sort_indices()
    index = np.int32 if pattern.nnz < 2**31 else np.int64
    gather = (sub.data - 1).astype(index)
    sub.data[:] = 0.0
    return sub, gather
