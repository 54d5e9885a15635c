"""Read volume/surface meshes: every meshio format, plus the original Bourguignon &
Cani program's format (see shared/reference-data/bourguignon2000/README.md).

Formats register in ``READERS``; adding one is one function.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness.errors import SpringbenchError

# node flags of the original program
FREE, FIXED, PULLED, OBSERVED = 0, 1, 2, 3


@dataclass(frozen=True)
class Mesh:
    """points (n, dim); cells: cell type ("triangle", "quad", "tetra", "hexahedron")
    -> (m, k) int array; flags (n,) node flags of the original format (0 if none)."""
    points: np.ndarray
    cells: dict
    flags: np.ndarray
    source: str = ""

    @property
    def dim(self) -> int:
        return self.points.shape[1]


def read_bc2000(path: Path) -> Mesh:
    """The original program's format: ``nNodes nElems``, nodes ``x y z<TAB>flag``,
    elements of 4 (tetra) or 8 (hexa) 0-based indices."""
    lines = [ln.split() for ln in Path(path).read_text().splitlines() if ln.strip()]
    n_nodes, n_elems = int(lines[0][0]), int(lines[0][1])
    nodes = np.array([[float(t) for t in ln[:4]] for ln in lines[1:1 + n_nodes]])
    elems = np.array([[int(t) for t in ln] for ln in lines[1 + n_nodes:1 + n_nodes + n_elems]])
    if nodes.shape != (n_nodes, 4) or len(elems) != n_elems:
        raise ValueError(f"expected {n_nodes} nodes and {n_elems} elements")
    if elems.min() < 0 or elems.max() >= n_nodes:
        raise ValueError("element index out of range")
    kind = {4: "tetra", 8: "hexahedron"}.get(elems.shape[1])
    if kind is None:
        raise ValueError(f"elements with {elems.shape[1]} nodes")
    return Mesh(nodes[:, :3], {kind: elems}, nodes[:, 3].astype(int), str(path))


def looks_like_bc2000(path: Path) -> bool:
    try:
        with open(path) as fh:
            first = fh.readline().split()
        return len(first) == 2 and all(t.isdigit() for t in first)
    except (OSError, UnicodeDecodeError):
        return False


def read_meshio(path: Path) -> Mesh:
    import contextlib
    import io

    import meshio
    # meshio prints and calls sys.exit on some unreadable files: keep both contained
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        try:
            m = meshio.read(path)
        except SystemExit:
            raise ValueError("meshio could not read it") from None
    pts = np.asarray(m.points, float)
    cells = {}
    for block in m.cells:
        if block.type in ("triangle", "quad", "tetra", "hexahedron"):
            cells[block.type] = np.vstack([cells[block.type], block.data]) if block.type in cells else block.data
    if not cells:
        raise ValueError("no triangle, quad, tetra or hexahedron cells")
    kinds = set(cells)
    if kinds & {"tetra", "hexahedron"}:
        cells = {k: v for k, v in cells.items() if k in ("tetra", "hexahedron")}
    else:
        pts = pts[:, :2] if np.allclose(pts[:, 2:], 0) else pts
    return Mesh(pts, cells, np.zeros(len(pts), int), str(path))


READERS = {"bc2000": read_bc2000, "meshio": read_meshio}


def read_mesh(path, fmt: str | None = None) -> Mesh:
    """Read a mesh; ``fmt`` None guesses (bc2000 if the first line is two integers)."""
    path = Path(path)
    if not path.is_file():  # meshio's own error for this is a long ReadError
        raise SpringbenchError(f"no such mesh file '{path.name}'", file=str(path),
                               fix="check the path (relative to the case file)")
    if fmt is None:
        fmt = "bc2000" if looks_like_bc2000(path) else "meshio"
    try:
        return READERS[fmt](path)
    except FileNotFoundError:
        raise SpringbenchError("file not found", file=str(path), fix="check the path")
    except Exception as exc:  # any parser failure becomes one line
        raise SpringbenchError(f"cannot read mesh ({type(exc).__name__}: {exc})".replace("\n", " "),
                               file=str(path), fix="give a bc2000 mesh or any format meshio reads")


FACETS = {"triangle": [(0, 1), (1, 2), (2, 0)], "quad": [(0, 1), (1, 2), (2, 3), (3, 0)],
          "tetra": [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)],
          "hexahedron": [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]}


def boundary_facets(cells, points=None):
    """The facets (edges in 2-D, triangles / quads in 3-D) that belong to exactly one
    cell, one (m, k) vertex-index array per facet size. With ``points``, also the
    centroids of their cells (one (m, dim) array each): the inside of every facet."""
    by_size: dict[int, list] = {}
    for ctype, c in cells.items():
        c = np.asarray(c, int)
        cent = points[c].mean(axis=1) if points is not None else None
        for f in FACETS[ctype]:
            by_size.setdefault(len(f), []).append((c[:, list(f)], cent))
    out, inside = [], []
    for pairs in by_size.values():
        faces = np.concatenate([f for f, _ in pairs])
        _, first, count = np.unique(np.sort(faces, axis=1), axis=0, return_index=True, return_counts=True)
        keep = np.sort(first[count == 1])
        out.append(faces[keep])
        if points is not None:
            inside.append(np.concatenate([c for _, c in pairs])[keep])
    return (out, inside) if points is not None else out
