"""Named regions of a mesh file (gmsh physical groups, cell sets, node sets, as meshio
reads them) as boundary parts: ``[body.parts] clamp = { group = "clamp" }``.

A group is a union of cells of any dimension (points, lines, triangles, quads, tets,
hexes; a node set adds the mesh's boundary facets all of whose vertices it holds). Its
predicate selects the points that lie on those cells (within a tolerance), so it holds
the nodes of the file's mesh, of every uniform refinement of it (new vertices lie on the
old facets) and the mid-edge dofs of P2 elements alike: the FEM and every model select
the same region through one code path (harness.case.parts.part_predicate).
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from harness.errors import SpringbenchError
from harness.io.meshfile import boundary_facets, read_mesh

HEX_FACES = ((0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7))
BARY_TOL = 1e-9  # barycentric coordinates may be this far below 0 (rounding)


@dataclass(frozen=True)
class GroupPart:
    """A ``[body.parts]`` entry that names a group of the body's mesh file."""

    group: str
    file: Path
    format: str | None = None


def cell_simplices(ctype: str, cells: np.ndarray, x: np.ndarray) -> list[np.ndarray]:
    """Coordinate arrays (m, k, dim) of simplices covering the cells; quads are fans
    about their centre, hexes pyramids of those fans to theirs, so the centres that
    refinement adds lie on them even when a face is not planar."""
    p = x[cells]
    if ctype == "quad":
        c = p.mean(axis=1)
        return [np.stack([c, p[:, i], p[:, (i + 1) % 4]], axis=1) for i in range(4)]
    if ctype == "hexahedron":
        c = p.mean(axis=1)
        out = []
        for face in HEX_FACES:
            q = p[:, list(face)]
            fc = q.mean(axis=1)
            out.extend(np.stack([c, fc, q[:, i], q[:, (i + 1) % 4]], axis=1) for i in range(4))
        return out
    return [p]


def group_simplices(mesh, name: str) -> dict[int, np.ndarray]:
    """Simplices covering group ``name`` of a harness.io.meshfile.Mesh, by vertex count k:
    {k: (m, k, dim) coordinates}. A node set's nodes count, and so do the mesh's
    boundary facets all of whose vertices are in it (what a refined mesh adds there)."""
    g, x = mesh.groups[name], mesh.points
    by_k: dict[int, list] = {}
    cells = list(g.cells.items())
    if len(g.nodes):
        by_k[1] = [x[g.nodes][:, None]]
        held = np.zeros(len(x), bool)
        held[g.nodes] = True
        for fac in boundary_facets(mesh.cells):
            cells.append(
                ({2: "line", 3: "triangle", 4: "quad"}[fac.shape[1]], fac[held[fac].all(axis=1)])
            )
    for ctype, c in cells:
        for s in cell_simplices(ctype, np.asarray(c, int), x):
            by_k.setdefault(s.shape[1], []).append(s)
    return {k: np.concatenate(v) for k, v in by_k.items()}


def on_simplices(x: np.ndarray, simplices: np.ndarray, tol: float) -> np.ndarray:
    """Mask (n,) of the points x (n, dim) within ``tol`` of one of the simplices
    (m, k, dim): barycentric coordinates of the projection >= 0, distance <= tol."""
    x = np.asarray(x, float)
    mask = np.zeros(len(x), bool)
    if not len(x) or not len(simplices):
        return mask
    cent = simplices.mean(axis=1)
    radius = np.linalg.norm(simplices - cent[:, None], axis=2).max(axis=1) + tol
    hits = cKDTree(x).query_ball_point(cent, radius)
    counts = np.fromiter(map(len, hits), int, len(hits))
    if not counts.sum():
        return mask
    s = np.repeat(np.arange(len(simplices)), counts)
    p = np.fromiter(itertools.chain.from_iterable(hits), int, counts.sum())
    v0 = simplices[:, 0]
    r = x[p] - v0[s]
    if simplices.shape[1] == 1:
        ok = np.linalg.norm(r, axis=1) <= tol
    else:
        E = (simplices[:, 1:] - v0[:, None]).transpose(0, 2, 1)  # (m, dim, k-1) edge vectors
        lam = np.einsum("pij,pj->pi", np.linalg.pinv(E)[s], r)
        dist = np.linalg.norm(np.einsum("pij,pj->pi", E[s], lam) - r, axis=1)
        ok = (dist <= tol) & np.all(lam >= -BARY_TOL, axis=1) & (lam.sum(axis=1) <= 1 + BARY_TOL)
    mask[p[ok]] = True
    return mask


@functools.lru_cache(maxsize=8)
def _geometry(file: str, fmt: str | None, stamp: tuple, name: str) -> dict[int, np.ndarray]:
    return group_simplices(read_mesh(file, fmt), name)


def group_predicate(part: GroupPart, tol: float):
    """Predicate (coordinates (dim, n) -> mask) of the points on the group ``part``."""
    st = Path(part.file).stat()
    geometry = _geometry(str(part.file), part.format, (st.st_mtime_ns, st.st_size), part.group)

    def on_group(x):
        x = np.asarray(x, float).T
        mask = np.zeros(len(x), bool)
        for simplices in geometry.values():
            mask |= on_simplices(x, simplices, tol)
        return mask

    return on_group


def require_group(mesh, name: str, *, file: str, field: str, error=None):
    """Raise a one-line error (``error``, default SpringbenchError) when ``mesh`` has no
    group ``name``, naming the mesh file and the groups it has."""
    if name in mesh.groups:
        return
    have = ", ".join(sorted(mesh.groups))
    fix = (
        f"groups of {Path(mesh.source).name}: {have}"
        if have
        else f"{Path(mesh.source).name} has no named groups (gmsh: addPhysicalGroup with a name; "
        "meshio: cell_sets or point_sets)"
    )
    raise (error or SpringbenchError)(
        f"mesh '{Path(mesh.source).name}' has no group '{name}'", file=file, field=field, fix=fix
    )


def scaled_copy(path, fmt: str | None, scale: float, folder) -> Path:
    """The mesh file with its coordinates times ``scale``, written in its own format into
    ``folder`` so that its groups stay with it."""
    import meshio

    m = meshio.read(path, file_format=fmt)
    m.points = m.points * scale
    out = Path(folder) / f"mesh{Path(path).suffix}"
    # meshio writes a '.msh' as ANSYS unless told: the groups are gmsh's
    meshio.write(out, m, file_format=fmt or ("gmsh" if out.suffix.lower() == ".msh" else None))
    return out
