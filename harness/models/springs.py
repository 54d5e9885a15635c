"""Linear algebra of spring networks shared by statics, optimisers and modal analysis.

A network is points (n, dim) and springs (e, 2) node pairs. Linearised about the rest
shape, spring e contributes k_e b_e b_e^T to K, where b_e (in dof space, dof = dim*node
+ component) is +d_e at node j and -d_e at node i, d_e the unit vector i -> j. Stacking
the b_e as columns gives the incidence matrix B, so K = B diag(k) B^T.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def spring_directions(points: np.ndarray, springs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit directions (e, dim) and rest lengths (e,)."""
    d = points[springs[:, 1]] - points[springs[:, 0]]
    L = np.linalg.norm(d, axis=1)
    return d / L[:, None], L


def incidence(points: np.ndarray, springs: np.ndarray) -> sp.csc_matrix:
    """B (n*dim, e): column e is b_e."""
    points = np.asarray(points, float)
    springs = np.asarray(springs, int)
    n, dim = points.shape
    e = len(springs)
    d, _ = spring_directions(points, springs)
    rows = np.concatenate(
        [springs[:, 1, None] * dim + np.arange(dim), springs[:, 0, None] * dim + np.arange(dim)],
        axis=1,
    )
    vals = np.concatenate([d, -d], axis=1)
    cols = np.repeat(np.arange(e), 2 * dim)
    return sp.csc_matrix((vals.ravel(), (rows.ravel(), cols)), shape=(n * dim, e))


def stiffness_matrix(B: sp.spmatrix, k: np.ndarray) -> sp.csc_matrix:
    """K = B diag(k) B^T."""
    return (B @ sp.diags(np.asarray(k, float)) @ B.T).tocsc()
