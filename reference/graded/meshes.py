"""Graded tensor-product meshes of rectangles and boxes, refined in levels.

Elastic solutions on a box are singular along its edges (where a clamped or loaded face
meets a free one), and uniform P2 tetrahedra converge there only like h^1.1 at the
scored points. A tensor mesh whose nodes along each axis follow a power law
x = w (i / n)^beta towards both ends of the axis (the end zones, w = half the shortest
side) puts small cells along every face, edge and corner; the middle of a long axis gets
uniform cells as large as the largest graded one. Level k has ``n_k`` cells per end zone
(and the middle's cells scale with it): one family of meshes, uniformly refined in the
parameter s = i / n, which is what Richardson extrapolation over the levels needs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import skfem

GRADE_EXPONENT = 3.0  # beta, and ZONE: the end zones' width / the shortest side. Measured on the
ZONE = 0.5  # sec6 cube's shear against an independent solve (tests/independent/)
MESHES = {2: skfem.MeshQuad, 3: skfem.MeshHex}


@dataclass(frozen=True)
class AxisMap:
    """The graded map of one axis at level n: the continuous cell index t in [0, N]
    (node i at t = i) to the coordinate x in [0, length] and back. ``n`` power-graded
    cells in each end zone of width zone * min(length, shortest) (at most half the axis),
    ``m`` uniform cells in between (an even number, as many as keep them no larger than
    the largest graded cell at n, proportional to n), so the axis is symmetric and its
    midpoint is a node."""

    length: float
    w: float
    n: int
    m: int
    beta: float

    @classmethod
    def of(
        cls,
        length: float,
        shortest: float,
        n: int,
        beta: float = GRADE_EXPONENT,
        zone: float = ZONE,
    ) -> "AxisMap":
        if n < 1:
            raise ValueError("need at least one cell per end zone")
        w = min(zone * shortest, 0.5 * length)
        middle = length - 2 * w
        # largest graded cell ~ zone_slope w / n (the zone's end slope; the count is
        # proportional to n); an even count puts a vertex on the mid-plane, where
        # reference/graded/symmetry.py cuts the box
        m = (
            0
            if middle <= 1e-12 * length
            else 2 * max(1, int(np.ceil(middle * n / (2 * zone_slope(beta) * w) - 1e-9)))
        )
        return cls(float(length), float(w) if m else 0.5 * float(length), int(n), m, float(beta))

    @property
    def cells(self) -> int:
        return 2 * self.n + self.m

    def x(self, t) -> np.ndarray:
        t = np.clip(np.asarray(t, float), 0.0, self.cells)
        end = lambda s: self.w * zone_map(np.clip(s, 0.0, self.n) / self.n, self.beta)  # noqa: E731
        mid = self.w + (t - self.n) * (self.length - 2 * self.w) / max(self.m, 1)
        return np.where(
            t <= self.n,
            end(t),
            np.where(t >= self.n + self.m, self.length - end(self.cells - t), mid),
        )

    def t(self, x) -> np.ndarray:
        x = np.clip(np.asarray(x, float), 0.0, self.length)
        end = lambda d: self.n * zone_inverse(np.clip(d, 0.0, self.w) / self.w, self.beta)  # noqa: E731
        mid = self.n + (x - self.w) * max(self.m, 1) / max(self.length - 2 * self.w, 1e-300)
        return np.where(
            x <= self.w,
            end(x),
            np.where(x >= self.length - self.w, self.cells - end(self.length - x), mid),
        )


def zone_map(s, beta: float = GRADE_EXPONENT) -> np.ndarray:
    """The end zone's map [0, 1] -> [0, 1]: s^beta + c (s^(beta+1) - s^(beta+2)) with c
    = beta (beta - 1) / (2 beta + 2), which makes its curvature vanish where the zone
    ends. A plain s^beta has curvature there, and at a cube's mid-plane the mirrored zone
    has the opposite: a kink in the cell sizes that the averaging window of
    reference/lattice.py straddles for points near the mid-plane, whose level values
    then swing again. Near the face it is s^beta, the grading the edges need."""
    s = np.asarray(s, float)
    c = beta * (beta - 1) / (2 * beta + 2)
    return s**beta + c * (s ** (beta + 1) - s ** (beta + 2))


def zone_slope(beta: float = GRADE_EXPONENT) -> float:
    """d zone_map / ds at s = 1: the size of the zone's last cell times n / w."""
    c = beta * (beta - 1) / (2 * beta + 2)
    return beta - c


def zone_inverse(y, beta: float = GRADE_EXPONENT) -> np.ndarray:
    """s in [0, 1] with zone_map(s) = y, by Newton from below (the map is increasing and
    convex on [0, 1], so the iterates stay in it and converge)."""
    y = np.clip(np.asarray(y, float), 0.0, 1.0)
    c = beta * (beta - 1) / (2 * beta + 2)
    s = y ** (1.0 / beta) * 0.0 + np.clip(y, 0.0, 1.0) ** (1.0 / beta)
    for _ in range(100):
        d = beta * s ** (beta - 1) + c * ((beta + 1) * s**beta - (beta + 2) * s ** (beta + 1))
        step = np.divide(zone_map(s, beta) - y, d, out=np.zeros_like(s), where=d > 0)
        s = np.clip(s - step, 0.0, 1.0)
        if np.all(np.abs(step) <= 1e-15):
            break
    return s


def axis_nodes(
    length: float, shortest: float, n: int, beta: float = GRADE_EXPONENT, zone: float = ZONE
) -> np.ndarray:
    """Node coordinates in [0, length] of the graded axis (AxisMap) at level n."""
    a = AxisMap.of(length, shortest, n, beta, zone)
    x = a.x(np.arange(a.cells + 1))
    x[-1] = length
    return x


def axis_maps(size, n: int, beta: float = GRADE_EXPONENT, zone: float = ZONE) -> list[AxisMap]:
    """The AxisMap of every axis of a box of ``size`` at level n."""
    size = np.asarray(size, float)
    return [AxisMap.of(s, float(size.min()), n, beta, zone) for s in size]


def graded_axes(origin, size, n: int, beta: float = GRADE_EXPONENT, zone: float = ZONE) -> list:
    """The node coordinates along each axis of the graded mesh of [origin, origin + size]."""
    origin, size = np.asarray(origin, float), np.asarray(size, float)
    shortest = float(size.min())
    return [o + axis_nodes(s, shortest, n, beta, zone) for o, s in zip(origin, size)]


def tensor_mesh(axes) -> skfem.Mesh:
    return MESHES[len(axes)].init_tensor(*axes)


def q2_doflocs(mesh: skfem.Mesh) -> np.ndarray:
    """The Q2 dof locations (dim, ns) of a quadrilateral or hexahedral mesh in
    scikit-fem's numbering (vertices, then edge (3-D), facet and cell midpoints), without
    building a basis: a CellBasis of a million-dof level holds ~1 GB of quadrature data."""
    p = mesh.p
    parts = [p] + ([p[:, mesh.edges].mean(axis=1)] if p.shape[0] == 3 else [])
    return np.concatenate(
        parts + [p[:, mesh.facets].mean(axis=1), p[:, mesh.t].mean(axis=1)], axis=1
    )


def graded_mesh(
    origin, size, n: int, beta: float = GRADE_EXPONENT, zone: float = ZONE
) -> skfem.Mesh:
    """Quadrilateral (2-D) or hexahedral (3-D) tensor mesh of [origin, origin + size]
    graded towards every face, ``n`` cells per end zone."""
    return tensor_mesh(graded_axes(origin, size, n, beta, zone))


def probe_points(origin, size, per_axis: int = 9) -> np.ndarray:
    """A tensor grid of points (per_axis along every axis, faces, edges and corners
    included) on which the levels are compared to fit the order and decide when to stop."""
    origin, size = np.asarray(origin, float), np.asarray(size, float)
    axes = [o + np.linspace(0.0, s, per_axis) for o, s in zip(origin, size)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(size))
