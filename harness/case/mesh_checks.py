"""Sanity checks of a user's mesh before anything is built on it.

``check_mesh(mesh, file)`` raises a one-line :class:`SpringbenchError` naming the file,
the problem, the first offending cells/nodes and the fix. Checked, in this order:
non-finite coordinates, coordinates too large or a body too small to compute with (for
its distance from the origin too), empty mesh, node indices out of range, repeated nodes
within a cell, duplicate nodes (distinct indices, same position), nodes used by no cell,
degenerate cells (|signed size| tiny relative to the median cell), inverted cells (signed
size of the opposite sign to the majority: a consistently mirrored mesh is accepted),
mixed cell types (the FEM reference meshes one), non-manifold input (a face of a volume
mesh, or an edge of a surface mesh, shared by more than two cells) and a body in several
disconnected pieces (a loose piece has no constraint and floats). Everything is
vectorised over cells.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from harness.case.schema import LARGEST, SMALLEST
from harness.errors import SpringbenchError

#: faces of each volume cell type (local node indices); an edge list for surface cells
FACES = {
    "tetra": ((0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)),
    "hexahedron": (
        (0, 1, 2, 3),
        (4, 5, 6, 7),
        (0, 1, 5, 4),
        (1, 2, 6, 5),
        (2, 3, 7, 6),
        (3, 0, 4, 7),
    ),
    "triangle": ((0, 1), (1, 2), (2, 0)),
    "quad": ((0, 1), (1, 2), (2, 3), (3, 0)),
}
DEGENERATE_RTOL = 1e-8
# a body's extent relative to its largest coordinate: below this too few significant digits
# are left inside the body (cell sizes, duplicate-node and degeneracy tests lose their meaning)
EXTENT_RTOL = 1e-6


def _first(idx, n=5) -> str:
    idx = [int(i) for i in np.asarray(idx).ravel()[:n]]
    return ", ".join(map(str, idx)) + (", ..." if len(idx) == n else "")


def signed_size(points: np.ndarray, kind: str, cells: np.ndarray) -> np.ndarray:
    """Signed area (triangle, quad) or volume (tetra; hexahedron: Jacobian at the centre
    times 8, VTK node order) of each cell. 2-D points only for triangle/quad."""
    p = points[cells]
    if kind == "triangle" or kind == "quad":
        if points.shape[1] != 2:
            return np.ones(len(cells))  # surface in 3-D: orientation is not a volume sign
        if kind == "triangle":
            a, b = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
            return 0.5 * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
        x, y = p[..., 0], p[..., 1]  # shoelace
        return 0.5 * np.sum(x * np.roll(y, -1, 1) - np.roll(x, -1, 1) * y, axis=1)
    if kind == "tetra":
        a, b, c = (p[:, i] - p[:, 0] for i in (1, 2, 3))
        return np.einsum("ij,ij->i", np.cross(a, b), c) / 6.0
    if kind == "hexahedron":
        # derivative of the trilinear map at the centre, node order as VTK / the bc2000 program
        s = (
            np.array(
                [
                    [-1, -1, -1],
                    [1, -1, -1],
                    [1, 1, -1],
                    [-1, 1, -1],
                    [-1, -1, 1],
                    [1, -1, 1],
                    [1, 1, 1],
                    [-1, 1, 1],
                ],
                float,
            )
            / 8.0
        )
        J = np.einsum("ekd,kr->edr", p, s)  # (e, dim, ref)
        return np.linalg.det(J) * 8.0
    raise ValueError(kind)


def coordinate_problem(points) -> str | None:
    """Why a body's coordinates cannot be computed with (None if they can): too large,
    a body too small, or too small for its distance from the origin."""
    p = np.asarray(points, float)
    big, extent = float(np.abs(p).max()), float(np.max(p.max(0) - p.min(0)))
    if big > LARGEST:
        return f"coordinates up to {big:.3g} are too large to compute with"
    if extent < SMALLEST:
        return f"the body is {extent:.3g} across, too small to compute with"
    if extent < EXTENT_RTOL * big:
        return (
            f"the body is {extent:.3g} across but {big:.3g} from the origin "
            "(too few significant digits)"
        )
    return None


COORDINATE_FIX = "change the length unit or move the body near the origin"


def check_mesh(mesh, file: str | None = None) -> None:
    """Raise :class:`SpringbenchError` if ``mesh`` (a harness.io.meshfile.Mesh) is unusable."""
    file = file or getattr(mesh, "source", "") or None

    def fail(msg, fix):  # the mesh's name stays in the message when a case file is named instead
        where = f"mesh {Path(file).name}: " if file else ""
        raise SpringbenchError(where + msg, file=file, fix=fix)

    pts = np.asarray(mesh.points, float)
    if pts.ndim != 2 or len(pts) == 0:
        fail("the mesh has no nodes", "give a mesh with nodes and cells")
    bad = np.flatnonzero(~np.isfinite(pts).all(axis=1))
    if len(bad):
        fail(f"non-finite coordinates at nodes {_first(bad)}", "fix the node coordinates")
    problem = coordinate_problem(pts)
    if problem:
        fail(problem, COORDINATE_FIX)
    cells = {k: np.asarray(v) for k, v in mesh.cells.items() if len(v)}
    if not cells:
        fail("the mesh has no cells", "give triangle, quad, tetra or hexahedron cells")
    if pts.shape[1] == 3 and not cells.keys() & {"tetra", "hexahedron"}:
        _surface(pts, cells, fail)
    used = np.zeros(len(pts), bool)
    for kind, c in cells.items():
        _check_indices(kind, c, len(pts), fail)
        used[c.ravel()] = True
    _check_nodes(pts, used, fail)
    for kind, c in cells.items():
        _check_sizes(pts, kind, c, fail)
    if len(cells) > 1:  # the FEM reference meshes one cell type: it would drop the others
        split = "hexahedra into tetrahedra" if "hexahedron" in cells else "quads into triangles"
        fail(
            f"the mesh mixes {' and '.join(sorted(cells))} cells",
            f"give one cell type, e.g. split the {split}",
        )
    for kind, c in cells.items():
        _check_manifold(kind, c, fail)
    _check_connected(pts, cells, fail)


def _check_indices(kind: str, c: np.ndarray, n: int, fail) -> None:
    """Cells of one kind: nodes that exist, none repeated in a cell, no cell twice."""
    if c.min() < 0 or c.max() >= n:
        row = np.flatnonzero((c < 0).any(1) | (c >= n).any(1))
        fail(
            f"{kind} cells {_first(row)} refer to nodes that do not exist (mesh has {n} nodes)",
            "node indices must be 0 .. n-1",
        )
    s = np.sort(c, axis=1)
    rep = np.flatnonzero((s[:, 1:] == s[:, :-1]).any(1))
    if len(rep):
        fail(
            f"{kind} cells {_first(rep)} repeat a node (collapsed cells)",
            "remove or fix those cells",
        )
    _, first, counts = np.unique(s, axis=0, return_index=True, return_counts=True)
    if (counts > 1).any():
        fail(
            f"{int((counts > 1).sum())} {kind} cells appear twice (e.g. cell "
            f"{first[counts > 1][0]})",
            "remove duplicate cells",
        )


def _check_nodes(pts: np.ndarray, used: np.ndarray, fail) -> None:
    """No two nodes at one position, none outside every cell."""
    scale = float(np.linalg.norm(pts.max(0) - pts.min(0))) or 1.0
    from scipy.spatial import cKDTree

    pairs = cKDTree(pts).query_pairs(1e-10 * scale, output_type="ndarray")
    if len(pairs):
        fail(
            f"duplicate nodes: {len(pairs)} pairs at the same position (e.g. nodes "
            f"{pairs[0, 0]} and {pairs[0, 1]})",
            "merge duplicate nodes (e.g. meshio/gmsh 'Coherence' or remove_duplicate_points)",
        )
    unused = np.flatnonzero(~used)
    if len(unused):
        fail(
            f"{len(unused)} nodes belong to no cell (nodes {_first(unused)})",
            "remove unused nodes (meshio: mesh.remove_orphaned_nodes())",
        )


def _check_sizes(pts: np.ndarray, kind: str, c: np.ndarray, fail) -> None:
    """Cells of one kind: none of zero size, all of one orientation."""
    v = signed_size(pts, kind, c)
    ref = np.median(np.abs(v))
    degen = np.flatnonzero(np.abs(v) <= DEGENERATE_RTOL * max(ref, np.finfo(float).tiny))
    if len(degen) or ref == 0:
        degen = degen if len(degen) else np.arange(len(c))
        fail(
            f"{len(degen)} degenerate {kind} cells with zero size (cells {_first(degen)})",
            "remove flat or collapsed cells",
        )
    pos, neg = np.flatnonzero(v > 0), np.flatnonzero(v < 0)
    if len(pos) and len(neg):
        wrong = neg if len(neg) <= len(pos) else pos
        fail(
            f"{len(wrong)} inverted {kind} cells (cells {_first(wrong)}) have the "
            "opposite orientation to the rest",
            "reorder their nodes so every cell has positive volume",
        )


def _check_manifold(kind: str, c: np.ndarray, fail) -> None:
    """No face (2-D: edge) shared by more than two cells."""
    faces = np.concatenate([np.sort(c[:, list(f)], axis=1) for f in FACES[kind]])
    _, counts = np.unique(faces, axis=0, return_counts=True)
    over = int((counts > 2).sum())
    if over:
        what = "edges" if kind in ("triangle", "quad") else "faces"
        fail(
            f"non-manifold {kind} mesh: {over} {what} shared by more than two cells",
            "each face may belong to at most two cells; remove overlapping or duplicate cells",
        )


def _surface(pts, cells, fail):
    """Triangles or quads whose nodes do not lie in z = 0: a surface in 3-D (an STL, a
    shell), which has no volume to be elastic in, or a flat mesh in another plane."""
    what = " and ".join(f"{len(c)} {kind}s" for kind, c in sorted(cells.items()))
    z = pts[:, 2]
    if np.ptp(z) <= 1e-12 * max(float(np.ptp(pts[:, :2], axis=0).max()), np.finfo(float).tiny):
        fail(
            f"a flat mesh of {what} at z = {z[0]:g}: 2-D meshes lie in the plane z = 0",
            "move it to z = 0, or give volume cells (tetrahedra or hexahedra)",
        )
    fail(
        f"no volume cells: the mesh is a surface in 3-D ({what})",
        "tetrahedralise it first, e.g. with gmsh",
    )


def _check_connected(pts, cells, fail):
    """One piece: every node reachable from every other through the cells."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    rows = np.concatenate(
        [np.repeat(c[:, :1], c.shape[1] - 1, axis=1).ravel() for c in cells.values()]
    )
    cols = np.concatenate([c[:, 1:].ravel() for c in cells.values()])
    n = len(pts)
    count, label = connected_components(
        sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n)), directed=False
    )
    if count > 1:
        sizes = np.bincount(label)
        small = int(np.argmin(sizes))
        fail(
            f"the mesh is {count} disconnected pieces (node counts "
            f"{sorted(sizes.tolist(), reverse=True)[:5]}; "
            f"node {int(np.flatnonzero(label == small)[0])} is in one of {sizes[small]} nodes)",
            "mesh the body as one connected piece, or remove the loose pieces",
        )
