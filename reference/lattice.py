"""The lattice of a tensor mesh's dofs, and point values of a Q2 field on it by cubic
interpolation of its nodal values.

The Q2 nodes of a tensor mesh (vertices, edge, face and cell midpoints) form a tensor
grid. Where the solution is smooth, Q2 nodal values are superconvergent (error
O(h^4) at the Lobatto points), while the Q2 polynomial between them is only O(h^3),
with a constant that depends on where a point sits inside its cell: that varies from
level to level and spoils Richardson extrapolation of point values. A tensor-product
cubic through the 4 x 4 (x 4) nearest grid values is O(h^4) wherever the point is, and
reproduces every nodal value and every cubic field exactly.

What remains depends on where a point sits in its cell: the error of a Q2 level at a
fixed point, times n^3, swings with the point's local cell coordinate theta (vertex and
mid-edge values carry different error constants), so the levels' values are not
C + D h^p in h and Richardson stalls (measured: 7e-5..1e-4 at n = 8..10 on the Sec. 6
cube whatever the interpolation order). ``evaluate_window`` therefore averages the field
along each axis over a window in the continuous cell index t of the graded map
(reference/graded/meshes.py AxisMap): (4/3) x the mean over one cell minus (1/3) x the mean
over two cells. Both means span whole periods of any function of theta, so its swing
averages out at every level alike; the combination has zero first and second moments,
so a smooth field is changed only at O(window^4), far below the O(h^3) the levels
extrapolate, and the window is placed so that its samples' mean is the point (the graded
map is not linear), which keeps a linear field exact (measured there: 4.3e-5 at n = 8,
1.6e-5 at n = 10, observed order 3.0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Lattice:
    """The scalar dofs of a tensor mesh as a grid: ``axes`` (per axis the sorted grid
    coordinates) and ``index`` (each scalar dof's flat grid site, x slowest). The one
    representation of the graded levels' fields (point values, :meth:`evaluate`), their
    mirror images (reference/graded/symmetry.py) and the matrix-free solvers' lattice
    fields (:meth:`to_lattice`, reference/solvers/tensorsolve.py)."""

    axes: tuple
    index: np.ndarray

    @classmethod
    def of(cls, doflocs: np.ndarray) -> Lattice:
        """The grid of dof locations (dim, ns); ValueError if they are not a tensor grid."""
        dim = doflocs.shape[0]
        axes = []
        flat = np.zeros(doflocs.shape[1], np.int64)
        for a in range(dim):
            x = doflocs[a]
            # one grid line per cluster of coordinates closer than 1e-9 of the extent (the
            # same node computed from different cells differs in the last bits; rounding
            # to fixed decimals splits such a pair when it straddles a rounding boundary)
            order = np.argsort(x, kind="stable")
            gaps = np.diff(x[order]) > 1e-9 * max(np.ptp(x), 1e-300)
            line = np.empty(len(x), np.int64)
            line[order] = np.concatenate([[0], np.cumsum(gaps)])
            first = order[np.concatenate([[True], gaps])]
            axes.append(x[first])
            flat = flat * len(first) + line
        if np.prod([len(g) for g in axes]) != doflocs.shape[1]:
            raise ValueError("the dof locations are not a tensor grid")
        return cls(tuple(axes), flat)

    @classmethod
    def q2(cls, doflocs: np.ndarray) -> Lattice | None:
        """The grid when the dof locations (dim, ns) are the Q2 nodes of a tensor mesh (an
        odd number of nodes per axis, the odd ones midway), else None. The locations
        alone: P2 on a tensor mesh's tetrahedra fills the same lattice, so the caller
        checks the element."""
        try:
            lat = cls.of(doflocs)
        except ValueError:
            return None
        for x in lat.axes:
            tol = 1e-9 * max(float(np.ptp(x)), 1e-300)
            if (
                len(x) % 2 == 0
                or len(x) < 3
                or np.abs(x[1:-1:2] - 0.5 * (x[:-2:2] + x[2::2])).max() > tol
            ):
                return None
        return lat

    @property
    def shape(self) -> tuple:
        """Grid points per axis."""
        return tuple(len(g) for g in self.axes)

    @property
    def field_shape(self) -> tuple:
        """The shape of a vector field on the lattice: (dim, *shape)."""
        return (len(self.axes),) + self.shape

    def to_lattice(self, v: np.ndarray) -> np.ndarray:
        """Interleaved dof vectors (ndof,) or (ndof, m) -> lattice fields (dim, ..) or
        (m, dim, ..)."""
        dim = len(self.axes)
        v2 = np.asarray(v, float).reshape(len(self.index), dim, -1)
        out = np.zeros((v2.shape[2], dim, int(np.prod(self.shape))))
        out[:, :, self.index] = v2.transpose(2, 1, 0)
        out = out.reshape((-1,) + self.field_shape)
        return out[0] if np.ndim(v) == 1 else out

    def from_lattice(self, U: np.ndarray) -> np.ndarray:
        """The inverse of :meth:`to_lattice`."""
        dim = len(self.axes)
        U2 = np.asarray(U, float).reshape(-1, dim, int(np.prod(self.shape)))[:, :, self.index]
        out = U2.transpose(2, 1, 0).reshape(-1, U2.shape[0])
        return out[:, 0] if np.ndim(U) == len(self.field_shape) else out

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

    def evaluate_window(
        self,
        values: np.ndarray,
        points: np.ndarray,
        maps,
        origin,
        average: np.ndarray,
        chunk: int = 2000,
    ) -> np.ndarray:
        """Field (ns, c) at points (m, dim) -> (m, c), averaged along axis d over the
        window (module docstring) of ``maps[d]`` (AxisMap, coordinates from ``origin``)
        where ``average[:, d]`` is True, else interpolated there as ``evaluate`` does."""
        G = self.grid(np.asarray(values, float).reshape(len(self.index), -1))
        pts = np.asarray(points, float)
        dim = len(self.axes)
        out = np.zeros((len(pts), G.shape[-1]))
        for lo in range(0, len(pts), chunk):
            sel = slice(lo, lo + chunk)
            starts, weights = zip(
                *(
                    _axis_weights(self.axes[d], pts[sel, d], maps[d], origin[d], average[sel, d])
                    for d in range(dim)
                )
            )
            idx = [
                np.minimum(st[:, None] + np.arange(w.shape[1]), len(self.axes[d]) - 1)
                for d, (st, w) in enumerate(zip(starts, weights))
            ]
            if dim == 2:
                block = G[idx[0][:, :, None], idx[1][:, None, :]]
                out[sel] = np.einsum("pi,pj,pijc->pc", weights[0], weights[1], block)
            else:
                block = G[
                    idx[0][:, :, None, None], idx[1][:, None, :, None], idx[2][:, None, None, :]
                ]
                out[sel] = np.einsum(
                    "pi,pj,pk,pijkc->pc", weights[0], weights[1], weights[2], block
                )
        return out


WINDOW_SAMPLES = 8  # midpoint samples per cell: exact for the swing's harmonics up to the 7th


def window(samples: int = WINDOW_SAMPLES):
    """Sample offsets (in cells) and weights of the window: a mean over [-1/2, 1/2] times
    (about) 4/3 minus a mean over [-1, 1] times 1/3, each by the midpoint rule."""
    one = (np.arange(samples) + 0.5) / samples - 0.5
    two = (np.arange(2 * samples) + 0.5) / samples - 1.0
    # the samples' own second moments, so that the combination's is zero to rounding
    v1, v2 = np.mean(one**2), np.mean(two**2)
    a = v2 / (v2 - v1)  # 4/3 for the exact means
    return (
        np.concatenate([one, two]),
        np.concatenate(
            [np.full(samples, a / samples), np.full(2 * samples, (1 - a) / (2 * samples))]
        ),
    )


def _axis_weights(g: np.ndarray, x: np.ndarray, amap, origin: float, average: np.ndarray):
    """Per point the first grid index (m,) and the weights (m, R) of grid values
    g[start .. start + R - 1] that give the windowed (or plain cubic) value at x."""
    tau, wt = window()
    t = amap.t(x - origin)
    mean = lambda t: (origin + amap.x(t[:, None] + tau[None, :])) @ wt  # noqa: E731
    # centre the window so that its samples' mean is x: a linear field stays exact
    for _ in range(20):
        slope = np.maximum((mean(t + 1e-4) - mean(t - 1e-4)) / 2e-4, 1e-300)
        step = np.where(average, (mean(t) - x) / slope, 0.0)
        t = t - step
        if np.all(np.abs(step) <= 1e-13 * max(amap.cells, 1)):
            break
    xs = np.where(average[:, None], origin + amap.x(t[:, None] + tau[None, :]), x[:, None])
    ws = np.where(average[:, None], wt[None, :], np.eye(1, len(tau))[0][None, :])
    idx, w = _stencil(g, xs.ravel())
    idx, w = idx.reshape(len(x), len(tau), 4), w.reshape(len(x), len(tau), 4) * ws[:, :, None]
    start = idx.min(axis=(1, 2))
    span = int((idx.max(axis=(1, 2)) - start).max()) + 1
    W = np.zeros((len(x), span))
    rows = np.broadcast_to(np.arange(len(x))[:, None, None], idx.shape)
    np.add.at(W, (rows, idx - start[:, None, None]), w)
    return start, W


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
