"""Meshes and elements for the reference: tensor meshes of rectangles/boxes, a Delaunay
triangulation of polygons, and mesh files (harness.io.meshfile) turned into scikit-fem meshes."""

from __future__ import annotations

import logging

import numpy as np
import skfem

from harness.errors import ModelError
from harness.io.meshfile import read_mesh

# refined meshes are converted to C order silently (scikit-fem logs a warning each time)
logging.getLogger("skfem.mesh.mesh").setLevel(logging.ERROR)

MESHES = {"tri": skfem.MeshTri, "quad": skfem.MeshQuad, "tet": skfem.MeshTet, "hex": skfem.MeshHex}
ELEMENTS = {
    ("tri", "P1"): skfem.ElementTriP1,
    ("tri", "P2"): skfem.ElementTriP2,
    ("quad", "P1"): skfem.ElementQuad1,
    ("quad", "P2"): skfem.ElementQuad2,
    ("tet", "P1"): skfem.ElementTetP1,
    ("tet", "P2"): skfem.ElementTetP2,
    ("hex", "P1"): skfem.ElementHex1,
    ("hex", "P2"): skfem.ElementHex2,
}
MESHIO_TYPES = {"tri": "triangle", "quad": "quad", "tet": "tetra", "hex": "hexahedron"}
SIMPLEX = {"tri": True, "quad": False, "tet": True, "hex": False}


def default_divisions(dim: int, element: str) -> int:
    """Initial elements along the shortest side when the case does not say."""
    return {(2, "P1"): 8, (2, "P2"): 4, (3, "P1"): 4, (3, "P2"): 2}[(dim, element)]


def element(cell: str, order: str) -> skfem.Element:
    """The scalar Lagrange element; vector fields interleave dim components per dof."""
    return ELEMENTS[(cell, order)]()


def box_mesh(lo, size, cell: str, divisions: int) -> skfem.Mesh:
    """Tensor mesh of [lo, lo + size] with ``divisions`` cells along the shortest side."""
    lo, size = np.asarray(lo, float), np.asarray(size, float)
    n = np.maximum(1, np.round(divisions * size / size.min()).astype(int))
    axes = [np.linspace(a, a + s, k + 1) for a, s, k in zip(lo, size, n)]
    return MESHES[cell].init_tensor(*axes)


def polygon_mesh(vertices, divisions: int) -> skfem.MeshTri:
    """Triangulate a simple polygon: boundary points every h, interior points of a
    triangular lattice kept at least h/2 from the boundary, Delaunay, and triangles whose
    centroid lies outside dropped. h = (shortest bbox side) / divisions."""
    from matplotlib.path import Path
    from scipy.spatial import Delaunay

    v = np.asarray(vertices, float)
    if np.sum(_cross2(v, np.roll(v, -1, 0))) < 0:
        v = v[::-1]
    lo, hi = v.min(0), v.max(0)
    h = float((hi - lo).min()) / divisions
    edges = []
    for a, b in zip(v, np.roll(v, -1, 0)):
        k = max(1, int(np.ceil(np.linalg.norm(b - a) / h)))
        edges.append(a + np.linspace(0, 1, k, endpoint=False)[:, None] * (b - a))
    boundary = np.vstack(edges)
    ys = np.arange(lo[1], hi[1] + h, h * np.sqrt(3) / 2)
    lattice = [
        np.column_stack(
            [
                np.arange(lo[0] + (i % 2) * h / 2, hi[0] + h, h),
                np.full(len(np.arange(lo[0] + (i % 2) * h / 2, hi[0] + h, h)), y),
            ]
        )
        for i, y in enumerate(ys)
    ]
    lattice = np.vstack(lattice)
    path = Path(np.vstack([v, v[:1]]), closed=True)
    inside = path.contains_points(lattice)
    lattice = lattice[inside]
    lattice = lattice[_distance_to_segments(lattice, v) > 0.5 * h]
    pts = np.vstack([boundary, lattice])
    tri = Delaunay(pts).simplices
    cent = pts[tri].mean(1)
    keep = path.contains_points(cent)
    a = pts[tri]
    area = 0.5 * np.abs(_cross2(a[:, 1] - a[:, 0], a[:, 2] - a[:, 0]))
    keep &= area > 1e-10 * h * h
    tri = tri[keep]
    used = np.unique(tri)
    remap = np.full(len(pts), -1)
    remap[used] = np.arange(len(used))
    return skfem.MeshTri(pts[used].T.copy(), remap[tri].T.copy())


def _cross2(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _distance_to_segments(x, v):
    d = np.full(len(x), np.inf)
    for a, b in zip(v, np.roll(v, -1, 0)):
        ab = b - a
        t = np.clip(((x - a) @ ab) / (ab @ ab), 0, 1)
        d = np.minimum(d, np.linalg.norm(x - a - t[:, None] * ab, axis=1))
    return d


def file_mesh(body, cell: str) -> skfem.Mesh:
    """A mesh file as a scikit-fem mesh of the requested cell type (via skfem.io)."""
    import meshio
    from skfem.io.meshio import from_meshio

    m = read_mesh(body.file, body.format)
    kind = MESHIO_TYPES[cell]
    if kind not in m.cells:
        have = ", ".join(k for k, v in MESHIO_TYPES.items() if v in m.cells)
        raise ModelError(
            f"the mesh has no {kind} cells",
            file=str(body.file),
            field="reference.cell",
            fix=f"set reference.cell to one of: {have}",
        )
    pts = m.points if m.points.shape[1] == m.dim else m.points[:, : m.dim]
    mesh = from_meshio(meshio.Mesh(pts, [(kind, m.cells[kind])]))
    used = np.unique(mesh.t)
    if len(used) < mesh.p.shape[1]:  # drop nodes no cell uses (they would be floating dofs)
        remap = np.full(mesh.p.shape[1], -1)
        remap[used] = np.arange(len(used))
        mesh = type(mesh)(mesh.p[:, used], remap[mesh.t])
    return mesh


def base_mesh(case) -> skfem.Mesh:
    """The level-0 mesh of a case (before any refinement)."""
    spec = case.reference
    div = spec.divisions or default_divisions(case.dim, spec.element)
    body = case.body
    if body.shape in ("rectangle", "box"):
        return box_mesh(body.origin, body.size, spec.cell, div)
    if body.shape == "polygon":
        return polygon_mesh(body.vertices, div)
    return file_mesh(body, spec.cell)  # the file's mesh is level 0; divisions do not apply
