"""The free dofs' locations when a caller hands a solve the rigid-body modes instead of
coordinates: enough for the Cholesky's nested dissection (reference/solvers/sparse.py)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def coords_from_modes(A: sp.spmatrix, near_null: np.ndarray | None) -> np.ndarray | None:
    """Locations of the free dofs (up to scale and shift: enough for the nested
    dissection) read off the rigid-body modes ``Discretisation.rigid_modes`` builds:
    translations first (column c is 1 on the dofs of component c), then rotations, which
    hold the coordinates (2-D: [-y, x]; 3-D: [-y, x, 0], [0, -z, y], [-z, 0, x]). A
    coordinate a dof's modes do not carry is the mean over its graph neighbours that
    carry it. None if the modes do not look like that."""
    if near_null is None:
        return None
    R = np.asarray(near_null, float)
    n = R.shape[0]
    if R.ndim != 2 or R.shape[1] not in (3, 6):
        return None
    dim = 2 if R.shape[1] == 3 else 3
    T = R[:, :dim]
    if not (np.all((T == 0) | (T == 1)) and np.all(T.sum(axis=1) == 1)):
        return None
    comp = np.argmax(T, axis=1)
    X = np.zeros((n, dim))
    known = np.zeros((n, dim), bool)
    # (mode column, component, coordinate, sign): mode value = sign * coordinate
    table = (
        [(2, 0, 1, -1), (2, 1, 0, 1)]
        if dim == 2
        else [(3, 0, 1, -1), (3, 1, 0, 1), (4, 1, 2, -1), (4, 2, 1, 1), (5, 0, 2, -1), (5, 2, 0, 1)]
    )
    for col, c, j, sign in table:
        on = comp == c
        X[on, j] = sign * R[on, col]
        known[on, j] = True
    G = sp.csr_matrix((np.ones(A.nnz), A.indices, A.indptr), shape=A.shape)
    for _ in range(3):
        if known.all():
            break
        num, cnt = G @ (X * known), G @ known.astype(float)
        fill = ~known & (cnt > 0)
        X[fill] = num[fill] / cnt[fill]
        known |= fill
    return X
