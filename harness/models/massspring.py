"""The classic mass-spring system on a volume mesh (the comparison model of Bourguignon
& Cani 2000): one damped spring per unique edge; tetra: the 6 edges of each
tetrahedron; hexa: the 12 edges plus the 4 body diagonals (0-6, 1-7, 2-4, 3-5).

Springs keep the program's order and orientation (first occurrence of each edge while
walking the elements), so a compiled run accumulates forces in the program's order.
Forces are nonlinear: F = -[ks (|l| - L0) + kd (dv . n)] n with l = x_p - x_q, kd
physical (N s/m). ``forces`` is numpy, vectorised, complex-safe.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from harness.errors import ModelError
from harness.models.cells import hex_to_tets

TET_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])
HEX_EDGES = np.array(
    [
        [0, 1],
        [1, 2],
        [2, 3],
        [3, 0],
        [4, 5],
        [5, 6],
        [6, 7],
        [7, 4],
        [0, 4],
        [1, 5],
        [2, 6],
        [3, 7],
        [0, 6],
        [1, 7],
        [2, 4],
        [3, 5],
    ]
)


def mesh_edges(cells) -> np.ndarray:
    """Unique springs (s, 2) in the program's order and orientation."""
    cells = np.asarray(cells)
    local = {4: TET_EDGES, 8: HEX_EDGES}.get(cells.shape[1])
    if local is None:
        raise ModelError(f"elements with {cells.shape[1]} nodes: need tetrahedra or hexahedra")
    e = cells[:, local].reshape(-1, 2)
    key = np.sort(e, axis=1)
    _, first = np.unique(key, axis=0, return_index=True)
    return e[np.sort(first)]


@dataclass(frozen=True, eq=False)
class MassSpring:
    """points (n, 3) rest positions; springs (s, 2); L0, ks, kd (s,) (kd physical)."""

    points: np.ndarray
    springs: np.ndarray
    L0: np.ndarray
    ks: np.ndarray
    kd: np.ndarray
    cells: np.ndarray | None = None

    @property
    def n_nodes(self) -> int:
        return len(self.points)

    def tets(self):
        if self.cells is None:
            return None
        return self.cells if self.cells.shape[1] == 4 else hex_to_tets(self.cells)

    def node_graph(self) -> sp.csr_matrix:
        n, s = self.n_nodes, self.springs
        r = np.concatenate([s[:, 0], s[:, 1], np.arange(n)])
        c = np.concatenate([s[:, 1], s[:, 0], np.arange(n)])
        return sp.csr_matrix((np.ones(len(r), bool), (r, c)), shape=(n, n))

    def forces(self, x, v=None) -> np.ndarray:
        p, q = self.springs[:, 0], self.springs[:, 1]
        l = x[p] - x[q]
        L = np.sqrt(np.sum(l * l, axis=-1))
        n = l / L[:, None]
        s = self.ks * (L - self.L0)
        if v is not None:
            s = s + self.kd * np.sum((v[p] - v[q]) * n, axis=-1)
        F = -s[:, None] * n
        out = np.zeros((self.n_nodes, 3), dtype=F.dtype)
        for d in range(3):  # three scatters, vectorised over springs
            if np.iscomplexobj(F):
                out[:, d] = (
                    np.bincount(p, F[:, d].real, self.n_nodes)
                    - np.bincount(q, F[:, d].real, self.n_nodes)
                    + 1j
                    * (
                        np.bincount(p, F[:, d].imag, self.n_nodes)
                        - np.bincount(q, F[:, d].imag, self.n_nodes)
                    )
                )
            else:
                out[:, d] = np.bincount(p, F[:, d], self.n_nodes) - np.bincount(
                    q, F[:, d], self.n_nodes
                )
        return out

    def energy(self, x) -> float:
        L = np.linalg.norm(x[self.springs[:, 0]] - x[self.springs[:, 1]], axis=-1)
        return float(0.5 * np.sum(self.ks * (L - self.L0) ** 2))

    def stiffness_matrix(self, x=None) -> sp.csr_matrix:
        """Linear stiffness K = -df/dx at x (default: rest), (3n, 3n)."""
        x = self.points if x is None else x
        p, q = self.springs[:, 0], self.springs[:, 1]
        l = x[p] - x[q]
        L = np.linalg.norm(l, axis=-1)
        n = l / L[:, None]
        nn = n[:, :, None] * n[:, None, :]
        k = self.ks[:, None, None] * (nn + (1 - self.L0 / L)[:, None, None] * (np.eye(3) - nn))
        rows, cols, vals = [], [], []
        for a, b, sgn in ((p, p, 1), (q, q, 1), (p, q, -1), (q, p, -1)):
            r = (3 * a[:, None, None] + np.arange(3)[None, :, None]).repeat(3, axis=2)
            c = (3 * b[:, None, None] + np.arange(3)[None, None, :]).repeat(3, axis=1)
            rows.append(r.ravel()), cols.append(c.ravel()), vals.append((sgn * k).ravel())
        N = 3 * self.n_nodes
        return sp.csr_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(N, N)
        )


def build_massspring(points, cells, *, ks=2.5, kd=0.0) -> MassSpring:
    """Classic springs on the mesh edges; ks, kd (physical) one number or one per spring."""
    points = np.asarray(points, float)
    cells = np.asarray(cells, dtype=np.int64)
    springs = mesh_edges(cells)
    l = points[springs[:, 0]] - points[springs[:, 1]]
    L0 = np.sqrt(l[:, 0] * l[:, 0] + l[:, 1] * l[:, 1] + l[:, 2] * l[:, 2])
    s = len(springs)
    ks = np.broadcast_to(np.asarray(ks, float), (s,)).copy()
    kd = np.broadcast_to(np.asarray(kd, float), (s,)).copy()
    return MassSpring(points, springs, L0, ks, kd, cells)
