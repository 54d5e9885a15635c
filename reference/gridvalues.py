"""Point values of a Q2 field on a tensor mesh by cubic interpolation of its nodal values.

The Q2 nodes of a tensor mesh (vertices, edge, face and cell midpoints) form a tensor
grid. Where the solution is smooth, Q2 nodal values are superconvergent (error
O(h^4) at the Lobatto points), while the Q2 polynomial between them is only O(h^3),
with a constant that depends on where a point sits inside its cell: that varies from
level to level and spoils Richardson extrapolation of point values. A tensor-product
cubic through the 4 x 4 (x 4) nearest grid values is O(h^4) wherever the point is, and
reproduces every nodal value and every cubic field exactly.
"""

from __future__ import annotations

import numpy as np


class GridField:
    """Nodal values of one level as a tensor grid: axes (per axis the sorted grid
    coordinates) and ``index`` mapping scalar dofs to flat grid positions."""

    def __init__(self, doflocs: np.ndarray):
        dim = doflocs.shape[0]
        self.axes = []
        flat = np.zeros(doflocs.shape[1], np.int64)
        for a in range(dim):
            x = doflocs[a]
            g, first, inv = np.unique(np.round((x - x.min()) / max(np.ptp(x), 1e-300), 10),
                                      return_index=True, return_inverse=True)
            self.axes.append(x[first])
            flat = flat * len(g) + inv
        self.shape = tuple(len(g) for g in self.axes)
        if np.prod(self.shape) != doflocs.shape[1]:
            raise ValueError("the dof locations are not a tensor grid")
        self.index = flat

    def grid(self, values: np.ndarray) -> np.ndarray:
        """Scalar-dof values (ns, c) -> grid array (n_x, n_y[, n_z], c)."""
        out = np.empty((int(np.prod(self.shape)), values.shape[1]))
        out[self.index] = values
        return out.reshape(self.shape + (values.shape[1],))

    def evaluate(self, values: np.ndarray, points: np.ndarray) -> np.ndarray:
        """Field (ns, c) at points (m, dim) -> (m, c)."""
        G = self.grid(np.asarray(values, float).reshape(len(self.index), -1))
        pts = np.asarray(points, float)
        idx, w = zip(*(_stencil(g, pts[:, a]) for a, g in enumerate(self.axes)))
        out = np.zeros((len(pts), G.shape[-1]))
        for offs in np.ndindex(*(4,) * len(self.axes)):
            i = tuple(ix[:, o] for ix, o in zip(idx, offs))
            wt = np.prod([wa[:, o] for wa, o in zip(w, offs)], axis=0)
            out += wt[:, None] * G[i]
        return out


def _stencil(g: np.ndarray, x: np.ndarray):
    """Indices (m, 4) of the 4 grid points around each x (shifted inwards at the ends)
    and the cubic Lagrange weights (m, 4)."""
    if len(g) < 4:
        raise ValueError("a cubic needs 4 grid points per axis")
    j = np.clip(np.searchsorted(g, x) - 2, 0, len(g) - 4)
    idx = j[:, None] + np.arange(4)
    xs = g[idx]
    w = np.ones((len(x), 4))
    for a in range(4):
        for b in range(4):
            if a != b:
                w[:, a] *= (x - xs[:, b]) / (xs[:, a] - xs[:, b])
    return idx, w
