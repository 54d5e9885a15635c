"""The shapes study's bodies: eight gmsh solids a user brings and no test has (rounded,
holed, thin, curved), each with the Poisson ratio it is calibrated at, meshed to about a
given number of tetrahedra and written as VTU."""

from __future__ import annotations

import signal
from dataclasses import dataclass
from pathlib import Path

import numpy as np


def _ellipsoid(occ):
    v = occ.addSphere(0, 0, 0, 1.0)
    occ.dilate([(3, v)], 0, 0, 0, 0.2, 0.1, 0.07)
    return v


def _torus(occ):
    return occ.addTorus(0, 0, 0, 0.2, 0.05)


def _holed_plate(occ):
    plate = occ.addBox(0, 0, 0, 0.4, 0.2, 0.03)
    hole = occ.addCylinder(0.2, 0.1, -0.01, 0, 0, 0.05, 0.05)
    return occ.cut([(3, plate)], [(3, hole)])[0][0][1]


def _hollow_ball(occ):
    ball, core = occ.addSphere(0, 0, 0, 0.1), occ.addSphere(0, 0, 0, 0.07)
    return occ.cut([(3, ball)], [(3, core)])[0][0][1]


def _prism(occ, yz, length):
    """The polygon yz (in the x = 0 plane) extruded along x: the volume's tag."""
    ps = [occ.addPoint(0, y, z) for y, z in yz]
    ls = [occ.addLine(ps[i], ps[(i + 1) % len(ps)]) for i in range(len(ps))]
    s = occ.addPlaneSurface([occ.addCurveLoop(ls)])
    return next(t for d, t in occ.extrude([(2, s)], length, 0, 0) if d == 3)


def _wedge(occ):
    return _prism(occ, [(0, 0), (0.12, 0), (0, 0.06)], 0.5)


def _t_beam(occ):
    t = [(-0.06, 0.1), (0.06, 0.1), (0.06, 0.08), (0.01, 0.08), (0.01, 0), (-0.01, 0)]
    return _prism(occ, t + [(-0.01, 0.08), (-0.06, 0.08)], 0.6)


def _frustum(occ):
    return occ.addCone(0, 0, 0, 0.5, 0, 0, 0.08, 0.04)


@dataclass(frozen=True)
class Shape:
    """A solid, the Poisson ratio it is studied at and its size in tetrahedra."""

    name: str
    build: object
    nu: float
    n_tets: int


SHAPES = (
    Shape("ellipsoid-fine", _ellipsoid, 0.3, 2200),
    Shape("ellipsoid", _ellipsoid, 0.45, 750),
    Shape("torus", _torus, 0.3, 2500),
    Shape("holed-plate", _holed_plate, 0.3, 1500),
    Shape("hollow-ball", _hollow_ball, 0.45, 2500),
    Shape("wedge", _wedge, 0.45, 1000),
    Shape("t-beam", _t_beam, 0.49, 1500),
    Shape("frustum", _frustum, 0.49, 1200),
)


def _options(h: float) -> None:
    import gmsh

    for key, value in (
        ("General.Terminal", 0),
        ("General.NumThreads", 1),
        ("Mesh.RandomSeed", 0),
        ("Mesh.MeshSizeMax", h),
        ("Mesh.MeshSizeMin", h / 3),
        ("Mesh.MeshSizeFromCurvature", 12),
    ):
        gmsh.option.setNumber(key, value)


def make_shape(shape: Shape, path: Path) -> int:
    """Mesh ``shape`` with about its n_tets tetrahedra (one size correction) into the VTU
    ``path``; the tet count."""
    import gmsh
    import meshio

    h = 0.03
    for attempt in range(2):
        gmsh.initialize(["-noenv"])
        # gmsh's start resets it: a closed pipe would kill us
        signal.signal(signal.SIGPIPE, signal.SIG_IGN)
        try:
            _options(h)
            gmsh.model.add(shape.name)
            shape.build(gmsh.model.occ)
            gmsh.model.occ.synchronize()
            gmsh.model.mesh.generate(3)
            tags, coords, _ = gmsh.model.mesh.getNodes()
            _, nodes = gmsh.model.mesh.getElementsByType(4)
        finally:
            gmsh.finalize()
        tets = len(nodes) // 4
        h *= (tets / shape.n_tets) ** (1 / 3)
    index = np.zeros(int(tags.max()) + 1, int)
    index[tags.astype(int)] = np.arange(len(tags))
    cells = index[nodes.astype(int)].reshape(-1, 4)
    used = np.unique(cells)  # gmsh keeps the geometry's construction points as nodes
    renumber = np.zeros(len(tags), int)
    renumber[used] = np.arange(len(used))
    points = coords.reshape(-1, 3)[used]
    meshio.write(path, meshio.Mesh(points, [("tetra", renumber[cells])]))
    return tets


def mirror(path: Path, out: Path) -> None:
    """The VTU ``path`` reflected across the mid-plane of its longest axis (the axis
    calibrate clamps at its low end), every tetrahedron's orientation kept positive: the
    same mesh held and loaded at its other end."""
    import meshio

    m = meshio.read(path)
    p = np.array(m.points, float)
    a = int(np.argmax(np.ptp(p, axis=0)))
    p[:, a] = p[:, a].min() + p[:, a].max() - p[:, a]
    tets = np.array(m.cells_dict["tetra"])[:, [1, 0, 2, 3]]  # a reflection flips each sign
    meshio.write(out, meshio.Mesh(p, [("tetra", tets)]))
