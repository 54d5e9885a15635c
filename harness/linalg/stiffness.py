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
    # every pair (a, b) of nonzeros of each column j adds B[a, j] B[b, j] k_j to K[b, a]
    cnt = np.diff(B.indptr).astype(np.int64)
    sq = cnt * cnt
    col = np.repeat(np.arange(e, dtype=np.int64), sq)
    t = np.arange(len(col), dtype=np.int64) - np.repeat(np.cumsum(sq) - sq, sq)
    c = cnt[col]
    first = B.indptr[col].astype(np.int64)
    pa, pb = first + t // c, first + t % c
    ia, ib = B.indices[pa].astype(np.int64), B.indices[pb].astype(np.int64)
    rows = np.searchsorted(keys, ib * n + ia)
    P = sp.csr_matrix((B.data[pa] * B.data[pb], (rows, col)), shape=(len(keys), e))
    return pattern, P
