"""Read volume/surface meshes: every meshio format, plus the original Bourguignon &
Cani program's format (see shared/reference-data/bourguignon2000/README.md).

Formats of our own register in ``harness.registry.MESH_READERS``; adding one is one
function and its line there; any other name is a meshio format.
"""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness.errors import SpringbenchError
from harness.registry import MESH_READERS

# node flags of the original program
FREE, FIXED, PULLED, OBSERVED = 0, 1, 2, 3


@dataclass(frozen=True)
class Mesh:
    """points (n, dim); cells: cell type ("triangle", "quad", "tetra", "hexahedron")
    -> (m, k) int array; flags (n,) node flags of the original format (0 if none);
    groups: name -> harness.io.mesh_groups.Group (physical groups, cell and node sets)."""

    points: np.ndarray
    cells: dict
    flags: np.ndarray
    source: str = ""
    groups: dict = field(default_factory=dict)

    @property
    def dim(self) -> int:
        return self.points.shape[1]


def read_bc2000(path: Path) -> Mesh:
    """The original program's format: ``nNodes nElems``, nodes ``x y z<TAB>flag``,
    elements of 4 (tetra) or 8 (hexa) 0-based indices."""
    lines = [ln.split() for ln in Path(path).read_text().splitlines() if ln.strip()]
    n_nodes, n_elems = int(lines[0][0]), int(lines[0][1])
    nodes = np.array([[float(t) for t in ln[:4]] for ln in lines[1 : 1 + n_nodes]])
    elems = np.array([[int(t) for t in ln] for ln in lines[1 + n_nodes : 1 + n_nodes + n_elems]])
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


def is_gmsh_v1(path: Path) -> bool:
    """True if the file is gmsh's legacy v1 format (a ``$NOD`` section, no ``$MeshFormat``)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096).decode("ascii", "replace").split()
    except OSError:
        return False
    return bool(head) and head[0] in ("$NOD", "$NOE") and "$MeshFormat" not in head


def gmsh_v1_error(path: Path) -> SpringbenchError:
    """The one line for a gmsh v1 mesh: what it is and the command that converts it."""
    new = path.with_name(path.stem + "-v2.msh")
    return SpringbenchError(
        "gmsh's legacy v1 mesh format ($NOD/$ELM sections), which meshio does not read",
        file=str(path),
        fix=f"convert it: gmsh {path} -save -format msh2 -o {new}; or -format msh4",
    )


def read_meshio(path: Path, file_format: str | None = None) -> Mesh:

    import meshio

    # meshio prints and calls sys.exit on some unreadable files: keep both contained
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        try:
            m = meshio.read(path, file_format=file_format)
        except SystemExit:
            raise ValueError("meshio could not read it") from None
    pts = np.asarray(m.points, float)
    cells = {}
    for block in m.cells:
        if block.type in ("triangle", "quad", "tetra", "hexahedron"):
            cells[block.type] = (
                np.vstack([cells[block.type], block.data]) if block.type in cells else block.data
            )
    if not cells:
        raise ValueError("no triangle, quad, tetra or hexahedron cells")
    kinds = set(cells)
    if kinds & {"tetra", "hexahedron"}:
        cells = {k: v for k, v in cells.items() if k in ("tetra", "hexahedron")}
    else:
        pts = pts[:, :2] if np.allclose(pts[:, 2:], 0) else pts
    return Mesh(pts, cells, np.zeros(len(pts), int), str(path), read_groups(m))


# corner nodes of the cell types a group may hold (higher-order types by their corners)
CORNERS = {
    "vertex": 1,
    "line": 2,
    "line3": 2,
    "triangle": 3,
    "triangle6": 3,
    "quad": 4,
    "quad8": 4,
    "quad9": 4,
    "tetra": 4,
    "tetra10": 4,
    "hexahedron": 8,
    "hexahedron20": 8,
    "hexahedron27": 8,
}
DIMS = {"vertex": 0, "line": 1, "triangle": 2, "quad": 2, "tetra": 3, "hexahedron": 3}


@dataclass(frozen=True)
class Group:
    """One named region: cells (meshio type -> (m, k) node indices) and loose nodes (p,)."""

    cells: dict = field(default_factory=dict)
    nodes: np.ndarray = field(default_factory=lambda: np.zeros(0, int))


def read_groups(m) -> dict[str, Group]:
    """The named groups of a meshio mesh: its cell sets (gmsh physical groups arrive as
    these; meshio's own ``gmsh:*`` bookkeeping sets are skipped), gmsh physical tags
    without a cell set, and its point sets."""
    out: dict[str, dict] = {}

    def add(name, ctype, data):
        if ctype in CORNERS and len(data):
            cells = out.setdefault(name, {})
            data = np.asarray(data, int)[:, : CORNERS[ctype]]
            base = ctype.rstrip("0123456789")  # tetra10 -> tetra, triangle6 -> triangle
            cells[base] = np.vstack([cells[base], data]) if base in cells else data

    for name, per_block in (m.cell_sets or {}).items():
        if name.startswith("gmsh:"):
            continue
        for block, idx in zip(m.cells, per_block):
            if idx is not None and len(idx):
                add(name, block.type, block.data[np.asarray(idx, int)])
            else:
                out.setdefault(name, {})
    tags = (m.cell_data or {}).get("gmsh:physical")
    if tags is not None:  # gmsh tags are per dimension: field_data holds (tag, dim)
        for name, (tag, dim) in ((n, v) for n, v in (m.field_data or {}).items() if n not in out):
            for block, t in zip(m.cells, tags):
                if DIMS.get(block.type.rstrip("0123456789")) == dim:
                    add(name, block.type, block.data[np.asarray(t) == tag])
    groups = {n: Group(c) for n, c in out.items()}
    for name, idx in (m.point_sets or {}).items():
        nodes = np.unique(np.asarray(idx, int))
        groups[name] = Group(groups[name].cells if name in groups else {}, nodes)
    return groups


def read_mesh(path, fmt: str | None = None) -> Mesh:
    """Read a mesh; ``fmt`` None guesses (bc2000 if the first line is two integers)."""
    path = Path(path)
    if not path.is_file():  # meshio's own error for this is a long ReadError
        raise SpringbenchError(
            f"no such mesh file '{path.name}'",
            file=str(path),
            fix="check the path (relative to the case file)",
        )
    if path.stat().st_size == 0:
        raise SpringbenchError(
            "the mesh file is empty", file=str(path), fix="give a mesh with nodes and cells"
        )
    if fmt in (None, "meshio", "gmsh") and is_gmsh_v1(path):
        raise gmsh_v1_error(path)
    if fmt is None:
        fmt = "bc2000" if looks_like_bc2000(path) else "meshio"
    try:
        # meshio's names
        return MESH_READERS.load(fmt)(path) if fmt in MESH_READERS else read_meshio(path, fmt)
    except FileNotFoundError:
        raise SpringbenchError("file not found", file=str(path), fix="check the path")
    except Exception as exc:  # any parser failure becomes one line
        raise SpringbenchError(
            f"cannot read mesh ({type(exc).__name__}: {exc})".replace("\n", " "),
            file=str(path),
            fix="give a bc2000 mesh or any format meshio reads",
        )


FACETS = {
    "triangle": [(0, 1), (1, 2), (2, 0)],
    "quad": [(0, 1), (1, 2), (2, 3), (3, 0)],
    "tetra": [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)],
    "hexahedron": [
        (0, 3, 2, 1),
        (4, 5, 6, 7),
        (0, 1, 5, 4),
        (1, 2, 6, 5),
        (2, 3, 7, 6),
        (3, 0, 4, 7),
    ],
}


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
        keep = _once(np.sort(faces, axis=1))
        out.append(faces[keep])
        if points is not None:
            inside.append(np.concatenate([c for _, c in pairs])[keep])
    return (out, inside) if points is not None else out


def _once(rows: np.ndarray) -> np.ndarray:
    """Indices (increasing) of the rows of an int array (m, k) that occur exactly once:
    rows packed into one int64 key each when the values allow (a 1-D sort, ~10x faster
    than np.unique over rows), else by rows."""
    m, k = rows.shape
    base = int(rows.max(initial=0)) + 1
    if m and rows.min() >= 0 and base**k < 2**62:
        key = np.zeros(m, np.int64)
        for j in range(k):
            key = key * base + rows[:, j]
        _, first, count = np.unique(key, return_index=True, return_counts=True)
    else:
        _, first, count = np.unique(rows, axis=0, return_index=True, return_counts=True)
    return np.sort(first[count == 1])


_CACHE: dict = {}  # (what, path, format, size, mtime) -> read-only arrays, the last few


def _cached(what: str, path, fmt, make):
    p = Path(path)
    if not p.is_file():
        read_mesh(p, fmt)  # its one-line error naming the file
    st = p.stat()
    key = (what, str(p.resolve()), fmt, st.st_size, st.st_mtime_ns)
    if key not in _CACHE:
        value = make(read_mesh(p, fmt))
        for a in value if isinstance(value, tuple) else (value,):
            for arr in a if isinstance(a, list) else [a]:
                arr.flags.writeable = False
        if len(_CACHE) >= 8:
            _CACHE.pop(next(iter(_CACHE)))
        _CACHE[key] = value
    return _CACHE[key]


def mesh_points(path, fmt: str | None = None) -> np.ndarray:
    """The points of a mesh file, read once per version of the file (path, size, mtime)
    and read-only: a mesh body's bounding box is asked for by every part predicate
    (139 readings, 3 s, in one calibration of a 50k-tet mesh)."""
    return _cached("points", path, fmt, lambda m: np.array(m.points))


def mesh_surface(path, fmt: str | None = None):
    """(points, facets, inside) of a mesh file: its points and ``boundary_facets(cells,
    points)``, read and computed once per version of the file (path, size, mtime) and
    returned read-only: the homogeneous and facet loads of every network of a calibration
    ask for them load by load (44 times, ~1 s each, on a 50k-tet mesh)."""

    def make(m):
        facets, inside = boundary_facets(m.cells, m.points)
        return np.array(m.points), [np.array(a) for a in facets], [np.array(a) for a in inside]

    return _cached("surface", path, fmt, make)
