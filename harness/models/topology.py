"""Which node pairs get a spring: named grid structures, Delaunay, or a mesh's edges.

Every builder returns a :class:`Topology`: springs (e, 2) with i < j, a group id per
spring (for grouped optimisation: Deussen Fig. 8 gives horizontal, vertical and
diagonal springs one constant each) with the group names, and the cells (elements)
the springs came from, which the van Gelder and Lloyd stiffness rules need.

Grid structures (Deussen Fig. 3b; node index i + nx*(j + ny*k)):

2-D  "edges"                    horizontal + vertical neighbours (a mechanism: shear)
     "edges+diagonal"           + one diagonal per cell (lower-left to upper-right)
     "structure1"               + both diagonals per cell ("edges+diagonals")
     "edges+diagonals+second"   structure 1 + second neighbours along x and y
3-D  "edges"                    cubic lattice edges (a mechanism)
     "edges+face"               + both diagonals of every cell face
     "edges+face+body"          + the four body diagonals of every cell
     "edges+body"               edges + body diagonals only
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping

import numpy as np
from scipy.spatial import Delaunay

from harness.errors import ModelError

STRUCTURES_2D = (
    "edges",
    "edges+diagonal",
    "structure1",
    "edges+diagonals",
    "edges+diagonals+second",
)
STRUCTURES_3D = ("edges", "edges+face", "edges+face+body", "edges+body")
ALIASES = {
    "edges+diagonals": "structure1",
    "structure 1": "structure1",
    "cubic": "edges",
    "cubic+face": "edges+face",
    "cubic+face+body": "edges+face+body",
}


@dataclass(frozen=True, eq=False)
class Topology:
    springs: np.ndarray
    groups: np.ndarray
    group_names: tuple[str, ...]
    cells: Mapping[str, np.ndarray] = field(default_factory=dict)


def _finish(pairs, gids, names, cells) -> Topology:
    pairs = np.sort(np.asarray(pairs, int), axis=1)
    _, idx = np.unique(pairs, axis=0, return_index=True)
    idx = np.sort(idx)
    return Topology(
        pairs[idx],
        np.asarray(gids, int)[idx],
        tuple(names),
        MappingProxyType({k: np.asarray(v, int) for k, v in cells.items()}),
    )


def grid_structure(shape, name: str) -> Topology:
    """Springs of a regular grid of ``shape`` nodes with the named structure."""
    shape = tuple(int(s) for s in shape)
    name = ALIASES.get(name, name)
    dim = len(shape)
    ids = np.arange(int(np.prod(shape))).reshape(shape[::-1]).transpose()  # ids[i, j(, k)]
    known = STRUCTURES_2D if dim == 2 else STRUCTURES_3D
    if name not in known:
        raise ModelError(
            f"unknown {dim}-D grid structure '{name}'",
            field="model.structure",
            fix=f"one of {', '.join(known)}",
        )
    pairs, gids, names = [], [], []

    def add(a, b, gname):
        if gname not in names:
            names.append(gname)
        pairs.append(np.stack([a.ravel(), b.ravel()], 1))
        gids.append(np.full(a.size, names.index(gname)))

    if dim == 2:
        add(ids[:-1, :], ids[1:, :], "horizontal")
        add(ids[:, :-1], ids[:, 1:], "vertical")
        if name != "edges":
            add(ids[:-1, :-1], ids[1:, 1:], "diagonal")
        if name in ("structure1", "edges+diagonals+second"):
            add(ids[1:, :-1], ids[:-1, 1:], "diagonal")
        if name == "edges+diagonals+second":
            add(ids[:-2, :], ids[2:, :], "second-horizontal")
            add(ids[:, :-2], ids[:, 2:], "second-vertical")
        quads = np.stack(
            [
                ids[:-1, :-1].ravel(),
                ids[1:, :-1].ravel(),
                ids[1:, 1:].ravel(),
                ids[:-1, 1:].ravel(),
            ],
            1,
        )
        return _finish(np.concatenate(pairs), np.concatenate(gids), names, {"quad": quads})
    add(ids[:-1], ids[1:], "edge-x")
    add(ids[:, :-1], ids[:, 1:], "edge-y")
    add(ids[:, :, :-1], ids[:, :, 1:], "edge-z")
    if "face" in name:
        add(ids[:-1, :-1, :], ids[1:, 1:, :], "face-xy")
        add(ids[1:, :-1, :], ids[:-1, 1:, :], "face-xy")
        add(ids[:-1, :, :-1], ids[1:, :, 1:], "face-xz")
        add(ids[1:, :, :-1], ids[:-1, :, 1:], "face-xz")
        add(ids[:, :-1, :-1], ids[:, 1:, 1:], "face-yz")
        add(ids[:, 1:, :-1], ids[:, :-1, 1:], "face-yz")
    if "body" in name:
        add(ids[:-1, :-1, :-1], ids[1:, 1:, 1:], "body")
        add(ids[1:, :-1, :-1], ids[:-1, 1:, 1:], "body")
        add(ids[:-1, 1:, :-1], ids[1:, :-1, 1:], "body")
        add(ids[:-1, :-1, 1:], ids[1:, 1:, :-1], "body")
    s = [slice(0, -1), slice(1, None)]
    hexes = np.stack(
        [
            ids[s[a], s[b], s[c]].ravel()
            for c, b, a in [
                (0, 0, 0),
                (0, 0, 1),
                (0, 1, 1),
                (0, 1, 0),
                (1, 0, 0),
                (1, 0, 1),
                (1, 1, 1),
                (1, 1, 0),
            ]
        ],
        1,
    )
    return _finish(np.concatenate(pairs), np.concatenate(gids), names, {"hexahedron": hexes})


def simplex_quality(points: np.ndarray, simplices: np.ndarray) -> np.ndarray:
    """Size-free quality in [0, 1] (1 = equilateral): d! |volume| / (mean edge length)^d
    normalised by the regular simplex value."""
    p = points[simplices]
    d = points.shape[1]
    vol = np.abs(np.linalg.det(p[:, 1:] - p[:, :1])) / (2 if d == 2 else 6)
    idx = [(i, j) for i in range(d + 1) for j in range(i + 1, d + 1)]
    L = np.sqrt(np.mean([np.sum((p[:, i] - p[:, j]) ** 2, axis=1) for i, j in idx], axis=0))
    regular = np.sqrt(3) / 4 if d == 2 else 1 / (6 * np.sqrt(2))
    return vol / (regular * L**d)


def delaunay(points: np.ndarray, body=None, min_quality: float = 1e-3) -> Topology:
    """Delaunay edges; simplices whose centroid is outside a non-convex body and slivers
    (quality below ``min_quality``, e.g. flat triangles of collinear boundary points) are
    dropped first. One group per spring ("each")."""
    points = np.asarray(points, float)
    simp = Delaunay(points).simplices
    if body is not None and body.kind == "polygon":
        simp = simp[body.contains(points[simp].mean(axis=1))]
    simp = simp[simplex_quality(points, simp) >= min_quality]
    ctype = "triangle" if points.shape[1] == 2 else "tetra"
    return mesh_edges({ctype: simp}, len(points))


_EDGES = {
    "triangle": [(0, 1), (1, 2), (0, 2)],
    "quad": [(0, 1), (1, 2), (2, 3), (0, 3), (0, 2), (1, 3)],  # + both diagonals
    "tetra": [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)],
    # hexahedron (meshio/VTK order): 12 edges, 12 face diagonals, 4 body diagonals
    "hexahedron": [
        (0, 1),
        (1, 2),
        (2, 3),
        (0, 3),
        (4, 5),
        (5, 6),
        (6, 7),
        (4, 7),
        (0, 4),
        (1, 5),
        (2, 6),
        (3, 7),
        (0, 2),
        (1, 3),
        (4, 6),
        (5, 7),
        (0, 5),
        (1, 4),
        (1, 6),
        (2, 5),
        (2, 7),
        (3, 6),
        (0, 7),
        (3, 4),
        (0, 6),
        (1, 7),
        (2, 4),
        (3, 5),
    ],
}


def element_pairs(ctype: str) -> list[tuple[int, int]]:
    """Local node pairs that become springs in a cell of this type."""
    return _EDGES[ctype]


def mesh_edges(cells: Mapping[str, np.ndarray], n_nodes: int | None = None) -> Topology:
    """Springs along a user mesh's edges: triangle and tetra edges; quads add both
    diagonals and hexahedra add face and body diagonals (otherwise those cells are
    mechanisms). Each spring is its own group."""
    pairs = []
    for ctype, c in cells.items():
        if ctype not in _EDGES:
            raise ModelError(
                f"cell type '{ctype}' is not supported",
                field="body.file",
                fix="use triangle, quad, tetra or hexahedron cells",
            )
        c = np.asarray(c, int)
        pairs.extend(c[:, list(p)] for p in _EDGES[ctype])
    if not pairs:
        raise ModelError("no cells, hence no springs", field="model")
    pairs = np.unique(np.sort(np.concatenate(pairs), axis=1), axis=0)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    return Topology(
        pairs,
        np.zeros(len(pairs), int),
        ("all",),
        MappingProxyType({k: np.asarray(v, int) for k, v in cells.items()}),
    )
