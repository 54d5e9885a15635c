"""Exact 1-D element matrices of the quadratic Lagrange basis and the Kronecker assembly
of the Q2 stiffness and face loads on a tensor mesh of boxes."""

from __future__ import annotations

from fractions import Fraction as _F

import numpy as np
import scipy.sparse as sp

# N0 = (1 - t)(1 - 2t), N1 = 4t(1 - t), N2 = t(2t - 1), t = x / h
ELEM_M = [
    [_F(4, 30), _F(2, 30), _F(-1, 30)],  # int N_i N_j dx / h
    [_F(2, 30), _F(16, 30), _F(2, 30)],
    [_F(-1, 30), _F(2, 30), _F(4, 30)],
]
ELEM_A = [
    [_F(7, 3), _F(-8, 3), _F(1, 3)],  # int N_i' N_j' dx * h
    [_F(-8, 3), _F(16, 3), _F(-8, 3)],
    [_F(1, 3), _F(-8, 3), _F(7, 3)],
]
ELEM_B = [
    [_F(-3, 6), _F(-4, 6), _F(1, 6)],  # int N_i' N_j dx (h-free)
    [_F(4, 6), _F(0), _F(-4, 6)],
    [_F(-1, 6), _F(4, 6), _F(3, 6)],
]
ELEM_m = [_F(1, 6), _F(4, 6), _F(1, 6)]  # int N_i dx / h

_M, _A, _B, _m = (np.array(e, float) for e in (ELEM_M, ELEM_A, ELEM_B, ELEM_m))


def lame(E: float, nu: float) -> tuple[float, float]:
    return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))


def q2_nodes(vertices) -> np.ndarray:
    """The Q2 nodes of a 1-D mesh: the vertices and the cell midpoints, in order."""
    v = np.asarray(vertices, float)
    return np.insert(v, np.arange(1, len(v)), 0.5 * (v[:-1] + v[1:]))


def axis_matrices(vertices) -> dict:
    """Global 1-D Q2 matrices of a mesh with these vertices: M, A, B (B[i, j] = int X_i' X_j),
    the load vector m (int X_i) as sparse CSR / dense."""
    v = np.asarray(vertices, float)
    h = np.diff(v)
    ne = len(h)
    nodes = 2 * np.arange(ne)[:, None] + np.arange(3)[None, :]  # (ne, 3)
    rows = np.repeat(nodes, 3, axis=1).ravel()
    cols = np.tile(nodes, (1, 3)).ravel()
    n = 2 * ne + 1

    def glob(elem, scale):
        data = (scale[:, None, None] * elem[None]).ravel()
        return sp.csr_matrix((data, (rows, cols)), shape=(n, n))

    m = np.zeros(n)
    np.add.at(m, nodes, h[:, None] * _m[None])
    return dict(M=glob(_M, h), A=glob(_A, 1.0 / h), B=glob(_B, np.ones(ne)), m=m)


def axis_factor(mats, p, q, d):
    if d == p and d == q:
        return mats["A"]
    if d == p:
        return mats["B"]
    if d == q:
        return mats["B"].T.tocsr()
    return mats["M"]


def stiffness(vertices_xyz, E: float, nu: float) -> sp.csr_matrix:
    """The full (unconstrained) Q2 stiffness on the tensor mesh, components blocked,
    assembled with scipy.sparse.kron."""
    lam, mu = lame(E, nu)
    mats = [axis_matrices(v) for v in vertices_xyz]

    def G(p, q):
        return sp.kron(
            sp.kron(axis_factor(mats[0], p, q, 0), axis_factor(mats[1], p, q, 1)),
            axis_factor(mats[2], p, q, 2),
            format="csr",
        )

    L = G(0, 0) + G(1, 1) + G(2, 2)
    blocks = [[None] * 3 for _ in range(3)]
    for a in range(3):
        for b in range(3):
            K = lam * G(a, b) + mu * G(b, a)
            if a == b:
                K = K + mu * L
            blocks[a][b] = K
    return sp.bmat(blocks, format="csr")


def face_load(vertices_xyz, axis: int, end: int, vector) -> np.ndarray:
    """Load vector (3 N,) of a constant traction ``vector`` on the face axis = end
    (0: lower, 1: upper) of the box: per component t_a (x) of m_d on the other axes and
    the unit vector of the face's node on ``axis``."""
    mats = [axis_matrices(v) for v in vertices_xyz]
    parts = []
    for d in range(3):
        if d == axis:
            e = np.zeros(len(mats[d]["m"]))
            e[-1 if end else 0] = 1.0
            parts.append(e)
        else:
            parts.append(mats[d]["m"])
    f = np.kron(np.kron(parts[0], parts[1]), parts[2])
    return np.concatenate([t * f for t in vector])
