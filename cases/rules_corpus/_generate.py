"""Writes the corpus the shipped ``learned`` stiffness rule was fitted on
(harness/models/learned_rule.json):

    python cases/rules_corpus/_generate.py      # rewrites cases/rules_corpus/*.vtu

Small gmsh meshes (its PyPI package; one thread, seed 0: the same files on every run of
one gmsh version) of varied shapes, none of them the test meshes of tests/meshes.py (a
cylinder, an ellipsoid, a holed block, an ellipse, a holed plate), which stay out of the
corpus to test the rule on: seven tetrahedral bodies (500-3,000 tets) and three
triangulated plates (2-D). Two of them are graded (a size field finer near one corner)
so that edge lengths vary within a mesh. Then refit the rule with

    springbench rules fit cases/rules_corpus/*.vtu --nu 0.2 0.3 0.4 0.45 \\
        --out harness/models/learned_rule.json
"""

from __future__ import annotations

import signal
import sys
from pathlib import Path

import meshio
import numpy as np

HERE = Path(__file__).resolve().parent


def _graded(gmsh, point, fine, coarse, reach):
    """A mesh size growing from ``fine`` at ``point`` to ``coarse`` at distance ``reach``."""
    p = gmsh.model.occ.addPoint(*point)
    gmsh.model.occ.synchronize()
    f = gmsh.model.mesh.field
    d = f.add("Distance")
    f.setNumbers(d, "PointsList", [p])
    t = f.add("Threshold")
    f.setNumber(t, "InField", d)
    for key, v in (("SizeMin", fine), ("SizeMax", coarse), ("DistMin", 0.0), ("DistMax", reach)):
        f.setNumber(t, key, v)
    f.setAsBackgroundMesh(t)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)


def mesh(name: str, build, size: float, dim: int, grade=None) -> Path:
    """Mesh the OCC geometry ``build(occ)`` with element size ``size`` (or the graded size
    field ``grade`` = (point, fine, coarse, reach)) and write ``name`` as VTU."""
    import gmsh

    gmsh.initialize(["-noenv"])
    signal.signal(signal.SIGPIPE, signal.SIG_IGN)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.option.setNumber("Mesh.RandomSeed", 0)
        gmsh.model.add(name)
        build(gmsh.model.occ)
        gmsh.model.occ.synchronize()
        if grade is not None:
            _graded(gmsh, *grade)
        else:
            gmsh.option.setNumber("Mesh.MeshSizeMax", size)
            gmsh.option.setNumber("Mesh.MeshSizeMin", size / 3)
        gmsh.model.mesh.generate(dim)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        _, nodes = gmsh.model.mesh.getElementsByType(4 if dim == 3 else 2)
    finally:
        gmsh.finalize()
    index = np.zeros(int(tags.max()) + 1, int)
    index[tags.astype(int)] = np.arange(len(tags))
    pts = coords.reshape(-1, 3)
    cells = index[nodes.astype(int)].reshape(-1, dim + 1)
    used = np.unique(cells)  # drop geometry nodes no cell uses
    remap = np.full(len(pts), -1)
    remap[used] = np.arange(len(used))
    path = HERE / f"{name}.vtu"
    meshio.write(
        path,
        meshio.Mesh(np.round(pts[used], 12), [("tetra" if dim == 3 else "triangle", remap[cells])]),
    )
    return path


def bar(occ):
    occ.addBox(0, 0, 0, 1.0, 0.2, 0.25)


def plate_holes(occ):
    b = occ.addBox(0, 0, 0, 0.8, 0.5, 0.12)
    h1 = occ.addCylinder(0.25, 0.25, -0.1, 0, 0, 0.4, 0.1)
    h2 = occ.addCylinder(0.6, 0.3, -0.1, 0, 0, 0.4, 0.06)
    occ.cut([(3, b)], [(3, h1), (3, h2)])


def l_block(occ):
    a = occ.addBox(0, 0, 0, 0.6, 0.2, 0.2)
    b = occ.addBox(0, 0, 0, 0.2, 0.6, 0.2)
    occ.fuse([(3, a)], [(3, b)])


def blob(occ):
    s = [
        occ.addSphere(0, 0, 0, 0.25),
        occ.addSphere(0.25, 0.05, 0, 0.18),
        occ.addSphere(0.05, 0.2, 0.12, 0.14),
    ]
    occ.fuse([(3, s[0])], [(3, t) for t in s[1:]])


def graded_block(occ):
    occ.addBox(0, 0, 0, 0.5, 0.4, 0.3)


def torus(occ):
    occ.addTorus(0, 0, 0, 0.3, 0.09)


def tapered_rod(occ):
    occ.addCone(0, 0, 0, 0.8, 0, 0, 0.16, 0.06)


def plate2d_holes(occ):
    r = occ.addRectangle(0, 0, 0, 1.0, 0.5)
    d1 = occ.addDisk(0.3, 0.25, 0, 0.12, 0.12)
    d2 = occ.addDisk(0.72, 0.2, 0, 0.07, 0.07)
    occ.cut([(2, r)], [(2, d1), (2, d2)])


def l_plate(occ):
    a = occ.addRectangle(0, 0, 0, 0.8, 0.25)
    b = occ.addRectangle(0, 0, 0, 0.25, 0.7)
    occ.fuse([(2, a)], [(2, b)])


def notched_strip(occ):
    r = occ.addRectangle(0, 0, 0, 1.0, 0.3)
    n = occ.addRectangle(0.45, 0.2, 0, 0.1, 0.2)
    occ.cut([(2, r)], [(2, n)])


def arch(occ):
    outer = occ.addDisk(0, 0, 0, 0.6, 0.6)
    inner = occ.addDisk(0, 0, 0, 0.4, 0.4)
    quad = occ.addRectangle(0, 0, 0, 0.7, 0.7)
    ring = occ.cut([(2, outer)], [(2, inner)])[0]
    occ.intersect(ring, [(2, quad)])


def slotted_disk(occ):
    d = occ.addDisk(0, 0, 0, 0.3, 0.3)
    slot = occ.addRectangle(-0.05, -0.35, 0, 0.1, 0.3)
    occ.cut([(2, d)], [(2, slot)])


def stadium(occ):
    r = occ.addRectangle(0, 0, 0, 0.6, 0.3)
    a = occ.addDisk(0, 0.15, 0, 0.15, 0.15)
    b = occ.addDisk(0.6, 0.15, 0, 0.15, 0.15)
    occ.fuse([(2, r)], [(2, a), (2, b)])


def hexagon(occ):
    pts = [occ.addPoint(0.3 * np.cos(a), 0.3 * np.sin(a), 0) for a in np.arange(6) * np.pi / 3]
    lines = [occ.addLine(pts[i], pts[(i + 1) % 6]) for i in range(6)]
    occ.addPlaneSurface([occ.addCurveLoop(lines)])


# name -> (geometry, size, dim, graded size field (point, fine, coarse, reach) or None)
CORPUS = {
    "bar": (bar, 0.07, 3, None),
    "plate_holes": (plate_holes, 0.06, 3, None),
    "l_block": (l_block, 0.055, 3, None),
    "blob": (blob, 0.07, 3, None),
    "graded_block": (graded_block, None, 3, ((0.0, 0.0, 0.0), 0.03, 0.14, 0.6)),
    "torus": (torus, 0.06, 3, None),
    "tapered_rod": (tapered_rod, 0.06, 3, None),
    "plate2d_holes": (plate2d_holes, 0.04, 2, None),
    "l_plate": (l_plate, 0.035, 2, None),
    "notched_strip": (notched_strip, None, 2, ((0.5, 0.2, 0.0), 0.012, 0.07, 0.5)),
    "arch": (arch, 0.04, 2, None),
    "slotted_disk": (slotted_disk, 0.05, 2, None),
    "stadium": (stadium, 0.05, 2, None),
    "hexagon": (hexagon, 0.05, 2, None),
}


def main(names=None) -> None:
    for name, (build, size, dim, grade) in CORPUS.items():
        if names and name not in names:
            continue
        path = mesh(name, build, size, dim, grade)
        m = meshio.read(path)
        print(
            f"{path.name}: {len(m.points)} nodes, {sum(len(c.data) for c in m.cells)} "
            f"{m.cells[0].type}, "
            f"{path.stat().st_size / 1e3:.0f} kB"
        )


if __name__ == "__main__":
    main(sys.argv[1:])
