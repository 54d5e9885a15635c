"""Test meshes made with gmsh (its PyPI package): bodies users bring that are not boxes.
Each function writes a linear-element mesh as VTU (via meshio) and returns its path."""

from __future__ import annotations

import signal
from pathlib import Path

import meshio
import numpy as np


def gmsh_start(gmsh) -> None:
    """gmsh.initialize, then SIGPIPE back to ignored: gmsh's C++ start resets it to the
    default, and a later write to a closed pipe or socket (a Dask test's) then killed the
    whole pytest run with exit 141 instead of raising EPIPE."""
    gmsh.initialize(["-noenv"])
    signal.signal(signal.SIGPIPE, signal.SIG_IGN)


def _mesh(path: Path, build, size: float, dim: int, scale: float = 1.0) -> Path:
    import gmsh

    gmsh_start(gmsh)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.option.setNumber("Mesh.RandomSeed", 0)
        gmsh.model.add("body")
        build(gmsh.model.occ)
        gmsh.model.occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.option.setNumber("Mesh.MeshSizeMin", size / 3)
        gmsh.model.mesh.generate(dim)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        kind = 4 if dim == 3 else 2  # gmsh element types: 4 tetrahedron, 2 triangle
        _, nodes = gmsh.model.mesh.getElementsByType(kind)
    finally:
        gmsh.finalize()
    index = np.zeros(int(tags.max()) + 1, int)
    index[tags.astype(int)] = np.arange(len(tags))
    pts = coords.reshape(-1, 3) * scale  # VTU stores 3 coordinates; a 2-D mesh has z = 0
    cells = index[nodes.astype(int)].reshape(-1, dim + 1)
    used = np.unique(cells)  # drop nodes of the geometry that no cell uses
    remap = np.full(len(pts), -1)
    remap[used] = np.arange(len(used))
    meshio.write(
        path, meshio.Mesh(pts[used], [("tetra" if dim == 3 else "triangle", remap[cells])])
    )
    return path


def cylinder(
    folder: Path, radius=0.1, length=0.5, size=0.06, scale=1.0, name="cylinder.vtu"
) -> Path:
    return _mesh(
        Path(folder) / name,
        lambda occ: occ.addCylinder(0, 0, 0, length, 0, 0, radius),
        size,
        3,
        scale,
    )


def ellipsoid(folder: Path, axes=(0.3, 0.2, 0.15), size=0.07) -> Path:
    def build(occ):
        s = occ.addSphere(0, 0, 0, 1.0)
        occ.dilate([(3, s)], 0, 0, 0, *axes)

    return _mesh(Path(folder) / "ellipsoid.vtu", build, size, 3)


def holed_block(folder: Path, size=0.07) -> Path:
    def build(occ):
        b = occ.addBox(0, 0, 0, 0.6, 0.3, 0.2)
        c = occ.addCylinder(0.3, 0.15, -0.1, 0, 0, 0.4, 0.07)
        occ.cut([(3, b)], [(3, c)])

    return _mesh(Path(folder) / "holed_block.vtu", build, size, 3)


def ellipse(folder: Path, axes=(0.4, 0.25), size=0.06) -> Path:
    """A 2-D ellipse centred at the origin: a curved boundary in triangles."""
    return _mesh(Path(folder) / "ellipse.vtu", lambda occ: occ.addDisk(0, 0, 0, *axes), size, 2)


def holed_plate(folder: Path, size=0.06) -> Path:
    def build(occ):
        r = occ.addRectangle(0, 0, 0, 0.8, 0.4)
        d = occ.addDisk(0.4, 0.2, 0, 0.1, 0.1)
        occ.cut([(2, r)], [(2, d)])

    return _mesh(Path(folder) / "holed_plate.vtu", build, size, 2)


def wedge(folder: Path, length=1.0, half_width=0.3, h=0.1) -> Path:
    """A triangle (2-D) with its apex at x = 0: an end that is a single point (scipy's
    Delaunay of points in rows across x)."""
    from scipy.spatial import Delaunay

    pts = [(0.0, 0.0)]
    for x in np.arange(h, length + h / 2, h):
        w = half_width * x / length
        n = max(1, int(np.ceil(2 * w / h)))
        pts += [(x, y) for y in np.linspace(-w, w, n + 1)]
    pts = np.array(pts)
    tri = Delaunay(pts).simplices
    path = Path(folder) / "wedge.vtu"
    meshio.write(path, meshio.Mesh(np.c_[pts, np.zeros(len(pts))], [("triangle", tri)]))
    return path


def cylinder_groups(folder: Path, radius=0.1, length=0.5, size=0.05, name="cylinder.msh") -> Path:
    """A cylinder along x as gmsh .msh 4.1 with named physical groups: surfaces ``clamp``
    (x = 0), ``tip`` (x = length) and ``side``, the volume ``body``."""
    import gmsh

    path = Path(folder) / name
    gmsh_start(gmsh)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.option.setNumber("Mesh.RandomSeed", 0)
        gmsh.model.add("body")
        v = gmsh.model.occ.addCylinder(0, 0, 0, length, 0, 0, radius)
        gmsh.model.occ.synchronize()
        faces = {}
        for _, tag in gmsh.model.getBoundary([(3, v)], oriented=False):
            x = gmsh.model.occ.getCenterOfMass(2, tag)[0]
            faces["clamp" if x < 0.25 * length else "tip" if x > 0.75 * length else "side"] = tag
        for group, tag in faces.items():
            gmsh.model.addPhysicalGroup(2, [tag], name=group)
        gmsh.model.addPhysicalGroup(3, [v], name="body")
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.option.setNumber("Mesh.MeshSizeMin", size / 3)
        gmsh.model.mesh.generate(3)
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    return path


def grid_bar(folder: Path, name: str = "bar.vtu"):
    """A 3 x 1 x 1 bar of 4 x 3 x 3 grid nodes, each cube split into 6 tetrahedra, as VTU:
    (path, tets)."""
    from harness.geometry import grid_points
    from harness.models.cells import hex_to_tets
    from harness.models.topology import grid_structure

    shape = (4, 3, 3)
    pts = grid_points(np.zeros(3), np.array([3.0, 1.0, 1.0]), shape)
    tets = hex_to_tets(grid_structure(shape, "edges").cells["hexahedron"])
    path = Path(folder) / name
    meshio.write(path, meshio.Mesh(pts, [("tetra", tets)]))
    return path, tets
