"""The held-out study's bodies: four gmsh solids (an L-bracket, a tapered bar with a
through-hole, an elbow, a dumbbell) with physical surfaces ``clamp`` and ``load``, meshed to
about a given number of tetrahedra and read back with meshio."""

from __future__ import annotations

import math
import signal
from dataclasses import dataclass
from pathlib import Path

import numpy as np


def _prism(occ, xy, height):
    """The polygon xy (z = 0) extruded to z = height: the volume's tag."""
    ps = [occ.addPoint(x, y, 0) for x, y in xy]
    ls = [occ.addLine(ps[i], ps[(i + 1) % len(ps)]) for i in range(len(ps))]
    s = occ.addPlaneSurface([occ.addCurveLoop(ls)])
    return next(t for d, t in occ.extrude([(2, s)], 0, 0, height) if d == 3)


def _bracket(occ):
    return _prism(occ, [(0, 0), (0.4, 0), (0.4, 0.1), (0.1, 0.1), (0.1, 0.3), (0, 0.3)], 0.1)


def _taper(occ):
    bar = _prism(occ, [(0, -0.08), (0.5, -0.04), (0.5, 0.04), (0, 0.08)], 0.06)
    hole = occ.addCylinder(0.15, 0, -0.01, 0, 0, 0.08, 0.03)
    return occ.cut([(3, bar)], [(3, hole)])[0][0][1]


def _elbow(occ):
    return occ.addTorus(0, 0, 0, 0.25, 0.06, angle=2 * math.pi / 3)


def _dumbbell(occ):
    a, b = occ.addBox(0, 0, 0, 0.15, 0.15, 0.15), occ.addBox(0.45, 0, 0, 0.15, 0.15, 0.15)
    neck = occ.addCylinder(0.1, 0.075, 0.075, 0.4, 0, 0, 0.045)
    return occ.fuse([(3, a)], [(3, b), (3, neck)])[0][0][1]


def _near(*c):
    return lambda x: np.linalg.norm(np.asarray(x) - c) < 1e-3


@dataclass(frozen=True)
class Body:
    """A gmsh solid; clamp and load pick its surfaces by their centre of mass; the two
    traction directions across the load face and gravity's direction."""

    name: str
    build: object
    clamp: object
    load: object
    across: tuple
    gravity: tuple


BODIES = (
    Body(
        "bracket",
        _bracket,
        _near(0.05, 0.3, 0.05),
        _near(0.4, 0.05, 0.05),
        ((0, -1, 0), (0, 0, 1)),
        (0, -1, 0),
    ),
    Body(
        "taper",
        _taper,
        _near(0.15, 0, 0.03),
        _near(0.5, 0, 0.03),
        ((0, -1, 0), (0, 0, -1)),
        (0, 0, -1),
    ),
    Body(
        "elbow",
        _elbow,
        _near(0.25, 0, 0),
        _near(-0.125, 0.25 * math.sin(2 * math.pi / 3), 0),
        ((0, 0, -1), (-0.5, math.sin(2 * math.pi / 3), 0)),
        (0, 0, -1),
    ),
    Body(
        "dumbbell",
        _dumbbell,
        _near(0.075, 0.075, 0),
        _near(0.525, 0.075, 0.15),
        ((0, 0, -1), (0, 1, 0)),
        (0, 0, -1),
    ),
)


def make_body(body: Body, path: Path, n_tets: int) -> int:
    """Mesh ``body`` with about n_tets tetrahedra (one size correction) into the gmsh .msh
    ``path`` with physical surfaces clamp and load and the volume body; the tet count."""
    import gmsh

    h = (8.5 * 0.005 / n_tets) ** (1 / 3)
    for attempt in range(2):
        gmsh.initialize(["-noenv"])
        # gmsh's start resets it: a closed pipe would kill us
        signal.signal(signal.SIGPIPE, signal.SIG_IGN)
        try:
            for key, value in (
                ("General.Terminal", 0),
                ("General.NumThreads", 1),
                ("Mesh.RandomSeed", 0),
                ("Mesh.MeshSizeMax", h),
                ("Mesh.MeshSizeMin", h / 2),
                ("Mesh.MeshSizeFromCurvature", 12),
                ("Mesh.MshFileVersion", 4.1),
            ):
                gmsh.option.setNumber(key, value)
            gmsh.model.add(body.name)
            occ_volume = body.build(gmsh.model.occ)
            gmsh.model.occ.synchronize()
            faces = [t for _, t in gmsh.model.getBoundary([(3, occ_volume)], oriented=False)]
            centre = {t: gmsh.model.occ.getCenterOfMass(2, t) for t in faces}
            for group, pick in (("clamp", body.clamp), ("load", body.load)):
                tags = [t for t in faces if pick(centre[t])]
                if len(tags) != 1:
                    raise RuntimeError(f"{body.name}: {len(tags)} faces for group {group}")
                gmsh.model.addPhysicalGroup(2, tags, name=group)
            gmsh.model.addPhysicalGroup(3, [occ_volume], name="body")
            gmsh.model.mesh.generate(3)
            tets = len(gmsh.model.mesh.getElementsByType(4)[0])
            if attempt == 1:
                gmsh.write(str(path))
        finally:
            gmsh.finalize()
        h *= (tets / n_tets) ** (1 / 3)
    return tets


def read_body(path: Path):
    """(points (n, 3), tets (m, 4), {group: triangles (k, 3)}) of a body's .msh (meshio)."""
    import meshio

    m = meshio.read(path)
    tets = m.cells_dict["tetra"]
    used = np.unique(tets)
    index = np.full(len(m.points), -1)
    index[used] = np.arange(len(used))
    tris = m.cells_dict["triangle"]
    groups = {
        g: index[tris[s["triangle"]]]
        for g, s in m.cell_sets_dict.items()
        if "triangle" in s and not g.startswith("gmsh:")
    }
    return np.asarray(m.points[used], float), index[tets], groups
