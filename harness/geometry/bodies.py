"""Bodies as geometry: a 2-D polygon (rectangles are polygons), a 3-D box, or a mesh.

``body_geometry(case)`` turns a case's ``[body]`` into a :class:`BodyGeom` that
placement, Lloyd iteration, masses and the statics share: inside/boundary tests,
corners (the G "corner" class), volume. Polygons are stored counter-clockwise.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping

import numpy as np

from harness.case.moments import mesh_moments
from harness.errors import ModelError
from harness.io.meshfile import read_mesh


def polygon_area(v: np.ndarray) -> float:
    """Signed area (positive for counter-clockwise vertices)."""
    v = np.asarray(v, float)
    x, y = v[:, 0], v[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def polygon_centroid(v: np.ndarray) -> tuple[float, np.ndarray]:
    """(area, centroid) of a simple polygon; degenerate polygons give (0, mean vertex)."""
    v = np.asarray(v, float)
    if len(v) < 3:
        return 0.0, v.mean(0) if len(v) else np.zeros(2)
    x, y = v[:, 0], v[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    c = x * yn - xn * y
    a = 0.5 * c.sum()
    if abs(a) < 1e-300:
        return 0.0, v.mean(0)
    return float(a), np.array([((x + xn) * c).sum(), ((y + yn) * c).sum()]) / (6 * a)


def clip_halfplane(poly: np.ndarray, normal: np.ndarray, offset: float) -> np.ndarray:
    """Sutherland-Hodgman: the part of ``poly`` with normal . x <= offset.

    The subject may be non-convex (the result then may contain zero-width bridges,
    which do not change area or centroid)."""
    if len(poly) == 0:
        return poly
    d = poly @ normal - offset
    inside = d <= 0
    if inside.all():
        return poly
    if not inside.any():
        return poly[:0]
    nxt = np.roll(poly, -1, axis=0)
    dn = np.roll(d, -1)
    cross = inside != np.roll(inside, -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(cross, d / (d - dn), 0.0)
    cand = np.stack([poly, poly + t[:, None] * (nxt - poly)], axis=1)  # (n, 2 slots, 2)
    keep = np.stack([inside, cross], axis=1)
    return cand[keep]


def clip_box(poly: np.ndarray, lo, hi) -> np.ndarray:
    """The part of a polygon inside the axis-aligned box [lo, hi]."""
    for axis in range(2):
        n = np.zeros(2)
        n[axis] = 1.0
        poly = clip_halfplane(poly, n, hi[axis])
        poly = clip_halfplane(poly, -n, -lo[axis])
    return poly


def points_in_polygon(x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Crossing-number test, vectorised over points (boundary points: either)."""
    x = np.asarray(x, float)
    px, py = x[:, 0:1], x[:, 1:2]
    ax, ay = v[:, 0], v[:, 1]
    bx, by = np.roll(ax, -1), np.roll(ay, -1)
    cond = (ay > py) != (by > py)
    with np.errstate(divide="ignore", invalid="ignore"):
        xint = ax + (py - ay) * (bx - ax) / (by - ay)
    return (np.sum(cond & (px < xint), axis=1) % 2) == 1


def segment_distance(x: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distances (n, m) of points x (n, 2) to segments a->b (m, 2) and the parameters t."""
    ab = b - a
    L2 = np.maximum(np.sum(ab * ab, axis=1), 1e-300)
    t = np.clip(((x[:, None, :] - a[None]) * ab[None]).sum(-1) / L2, 0, 1)
    proj = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(x[:, None, :] - proj, axis=-1), t


@dataclass(frozen=True, eq=False)
class BodyGeom:
    """Geometry of a body. kind: "polygon" (2-D, ``vertices`` counter-clockwise),
    "box" (3-D, [lo, hi]) or "mesh" (``mesh_points``, ``mesh_cells``)."""

    dim: int
    kind: str
    lo: np.ndarray
    hi: np.ndarray
    vertices: np.ndarray | None = None
    mesh_points: np.ndarray | None = None
    mesh_cells: Mapping[str, np.ndarray] = field(default_factory=dict)

    @property
    def tol(self) -> float:
        return 1e-9 * float(np.linalg.norm(self.hi - self.lo))

    def bbox(self) -> tuple[np.ndarray, np.ndarray]:
        return self.lo, self.hi

    @property
    def is_box(self) -> bool:
        """True for an axis-aligned rectangle or box."""
        if self.kind == "box":
            return True
        if self.kind == "polygon" and len(self.vertices) == 4:
            return bool(
                np.all(
                    np.any(
                        np.isclose(
                            self.vertices[:, None, :],
                            np.stack([self.lo, self.hi])[None],
                            atol=self.tol,
                        ),
                        axis=1,
                    )
                )
            )
        return False

    @property
    def corners(self) -> np.ndarray:
        """Vertices of the body (G 'corner' class): polygon vertices or box corners."""
        if self.kind == "polygon":
            return self.vertices
        if self.kind == "box":
            g = np.array(np.meshgrid(*[[0, 1]] * 3, indexing="ij")).reshape(3, -1).T
            return self.lo + g * (self.hi - self.lo)
        return np.zeros((0, self.dim))

    @property
    def volume(self) -> float:
        if self.kind == "polygon":
            return polygon_area(self.vertices)
        if self.kind == "box":
            return float(np.prod(self.hi - self.lo))
        return float(mesh_moments(self.mesh_points, self.mesh_cells)[0])

    def contains(self, x: np.ndarray) -> np.ndarray:
        """Points (n, dim) inside or on the boundary."""
        x = np.atleast_2d(np.asarray(x, float))
        inbox = np.all((x >= self.lo - self.tol) & (x <= self.hi + self.tol), axis=1)
        if self.kind == "polygon":
            return inbox & (points_in_polygon(x, self.vertices) | self.on_boundary(x))
        if self.kind == "box":
            return inbox
        raise ModelError(
            "inside tests are not implemented for mesh bodies",
            field="body.shape",
            fix="use placement = 'mesh' (the mesh's own nodes) for mesh bodies",
        )

    def on_boundary(self, x: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(np.asarray(x, float))
        if self.kind == "polygon":
            v = self.vertices
            d, _ = segment_distance(x, v, np.roll(v, -1, axis=0))
            return d.min(axis=1) <= self.tol
        if self.kind == "box":
            return np.any(
                (np.abs(x - self.lo) <= self.tol) | (np.abs(x - self.hi) <= self.tol), axis=1
            )
        return np.zeros(len(x), bool)

    def boundary_edge(self, x: np.ndarray) -> np.ndarray:
        """Index of the polygon edge (vertex i -> i+1) each 2-D point lies on, -1 if none."""
        v = self.vertices
        d, _ = segment_distance(np.atleast_2d(x), v, np.roll(v, -1, axis=0))
        e = d.argmin(axis=1)
        return np.where(d[np.arange(len(e)), e] <= self.tol, e, -1)

    def perimeter(self) -> float:
        v = self.vertices
        return float(np.linalg.norm(np.roll(v, -1, axis=0) - v, axis=1).sum())


def rectangle(lo, hi) -> BodyGeom:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    v = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
    return BodyGeom(2, "polygon", lo, hi, vertices=v)


def box(lo, hi) -> BodyGeom:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return BodyGeom(3, "box", lo, hi)


def polygon(vertices) -> BodyGeom:
    v = np.asarray(vertices, float)
    if polygon_area(v) < 0:
        v = v[::-1]
    return BodyGeom(2, "polygon", v.min(0), v.max(0), vertices=v)


def mesh_body(points, cells) -> BodyGeom:
    p = np.asarray(points, float)
    return BodyGeom(
        p.shape[1],
        "mesh",
        p.min(0),
        p.max(0),
        mesh_points=p,
        mesh_cells=MappingProxyType({k: np.asarray(c, int) for k, c in cells.items()}),
    )


def body_geometry(case) -> BodyGeom:
    """The :class:`BodyGeom` of a ``harness.case.reader.Case``."""
    b = case.body
    lo, hi = b.bbox()
    if b.shape == "rectangle":
        return rectangle(lo, hi)
    if b.shape == "box":
        return box(lo, hi)
    if b.shape == "polygon":
        return polygon(b.vertices)
    m = read_mesh(b.file, b.format)
    return mesh_body(m.points, m.cells)
