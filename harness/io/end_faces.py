"""The end faces of a mesh along an axis, as boundary parts: ``[body.parts] clamp =
{ end = "x0" }`` (optionally ``band`` and ``cos``).

An end face is the set of boundary facets whose centroids lie within ``band`` times the
body's extent of the extreme of the axis (``x0``: its minimum, ``x1``: its maximum) and
whose outward unit normals point along it (``n . e >= cos`` with e = -e_x at x0, +e_x at
x1). A flat end gives its face; a rounded end a cap; a hollow part's hole and the side
walls beside the end are left out (their normals lie across the axis). Like a mesh group
(harness.io.mesh_groups) it is a set of facets of the user's mesh, so the FEM (on every
refinement of the mesh), the spring networks on its nodes and every exported force see
the same region through one predicate.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from harness.io.mesh_groups import cell_simplices, on_simplices
from harness.io.meshfile import mesh_surface

BAND = 0.05  # default band: 5 % of the body's extent along the axis
COS = 0.5  # default: normals within 60 degrees of the axis
FACET_TYPE = {2: "line", 3: "triangle", 4: "quad"}


@dataclass(frozen=True)
class EndPart:
    """A ``[body.parts]`` entry ``{ end = "x0" | "x1" | "y0" ..., band, cos }`` of a mesh body."""

    axis: int
    side: int  # 0: the low end, 1: the high end
    file: Path
    format: str | None = None
    band: float = BAND
    cos: float = COS

    @property
    def name(self) -> str:
        return f"{'xyz'[self.axis]}{self.side}"


def outward_normals(
    points: np.ndarray, facets: np.ndarray, inside: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(centroids (m, dim), outward unit normals (m, dim)) of boundary facets (m, k) whose
    cells have the centroids ``inside`` (m, dim): segments in 2-D, polygons in 3-D."""
    x = points[facets]
    if x.shape[2] == 2:
        d = x[:, 1] - x[:, 0]
        n = np.stack([d[:, 1], -d[:, 0]], axis=1)
    else:
        n = np.zeros((len(x), 3))
        for i in range(1, x.shape[1] - 1):
            n += np.cross(x[:, i] - x[:, 0], x[:, i + 1] - x[:, 0])
    c = x.mean(axis=1)
    n = n / np.maximum(np.linalg.norm(n, axis=1), 1e-300)[:, None]
    return c, n * np.where(np.einsum("ij,ij->i", n, c - inside) < 0, -1.0, 1.0)[:, None]


def facet_sizes(points: np.ndarray, fac: np.ndarray) -> np.ndarray:
    """Sizes (m,) of facets (m, k): lengths in 2-D, polygon areas in 3-D."""
    x = points[fac]
    if x.shape[2] == 2:
        return np.linalg.norm(x[:, 1] - x[:, 0], axis=1)
    a = np.zeros((len(x), 3))
    for i in range(1, x.shape[1] - 1):
        a += np.cross(x[:, i] - x[:, 0], x[:, i + 1] - x[:, 0]) / 2
    return np.linalg.norm(a, axis=1)


def facet_geometry(points: np.ndarray, facets, inside) -> list[tuple]:
    """(centroids, outward unit normals, sizes) per facet array of ``facets``: computed
    once for the many bands a region is grown through."""
    return [
        (*outward_normals(points, fac, cell), facet_sizes(points, fac))
        for fac, cell in zip(facets, inside)
    ]


def end_masks(points: np.ndarray, geometry, axis: int, side: int, band: float, cos: float):
    """Masks (one per facet array of ``geometry``, :func:`facet_geometry`) of the end
    face's facets."""
    x = points[:, axis]
    lo, hi = float(x.min()), float(x.max())
    width = band * (hi - lo)
    sign = 1.0 if side else -1.0
    return [
        ((c[:, axis] >= hi - width) if side else (c[:, axis] <= lo + width))
        & (sign * n[:, axis] >= cos)
        for c, n, _ in geometry
    ]


def end_facets(
    points: np.ndarray, facets, inside, axis: int, side: int, band: float = BAND, cos: float = COS
) -> list[np.ndarray]:
    """The end face's facets: one (m, k) vertex-index array per facet size of ``facets``
    (harness.io.meshfile.boundary_facets with the cells' centroids ``inside``)."""
    masks = end_masks(points, facet_geometry(points, facets, inside), axis, side, band, cos)
    return [fac[m] for fac, m in zip(facets, masks)]


def part_facets(part: EndPart) -> list[np.ndarray]:
    """The facets (vertex indices of the mesh file's points) of an end part."""
    points, facets, inside = mesh_surface(part.file, part.format)
    return end_facets(points, facets, inside, part.axis, part.side, part.band, part.cos)


@functools.lru_cache(maxsize=8)
def _geometry(
    file: str, fmt: str | None, stamp: tuple, axis: int, side: int, band: float, cos: float
):
    part = EndPart(axis, side, Path(file), fmt, band, cos)
    points = mesh_surface(file, fmt)[0]
    by_k: dict[int, list] = {}
    for fac in part_facets(part):
        for s in cell_simplices(FACET_TYPE[fac.shape[1]], fac, points):
            by_k.setdefault(s.shape[1], []).append(s)
    return {k: np.concatenate(v) for k, v in by_k.items()}


def end_predicate(part: EndPart, tol: float):
    """Predicate (coordinates (dim, n) -> mask) of the points on the end part's facets."""
    st = Path(part.file).stat()
    geometry = _geometry(
        str(part.file),
        part.format,
        (st.st_mtime_ns, st.st_size),
        part.axis,
        part.side,
        float(part.band),
        float(part.cos),
    )

    def on_end(x):
        x = np.asarray(x, float).T
        mask = np.zeros(len(x), bool)
        for simplices in geometry.values():
            mask |= on_simplices(x, simplices, tol)
        return mask

    return on_end
