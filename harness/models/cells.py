"""Cell connectivity shared by the element models: the hexahedron's split into six
tetrahedra and the node graph of a set of cells."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def hex_to_tets(cells) -> np.ndarray:
    """Six tetrahedra per hexahedron around the diagonal 0-6 (program vertex order)."""
    c = np.asarray(cells)
    split = np.array(
        [[0, 1, 2, 6], [0, 2, 3, 6], [0, 3, 7, 6], [0, 7, 4, 6], [0, 4, 5, 6], [0, 5, 1, 6]]
    )
    return c[:, split].reshape(-1, 4)


def cell_graph(cells, n) -> sp.csr_matrix:
    """The n x n node graph of cells (nodes sharing a cell, and each node itself)."""
    cells = np.asarray(cells)
    k = cells.shape[1]
    r = np.repeat(cells, k, axis=1).ravel()
    c = np.tile(cells, (1, k)).ravel()
    A = sp.csr_matrix((np.ones(len(r), bool), (r, c)), shape=(n, n))
    A.sum_duplicates()
    return A
