"""Writes examples/lug.msh: the example mesh of README and docs/calibrate.md.

A lifting lug, in metres: a flat bar 80 x 30 x 10 mm whose far end is rounded
(a half-disc of radius 15 mm) and pierced by a bore of radius 6 mm, meshed with
gmsh into about 2,000 linear tetrahedra. Physical groups: ``body`` (the volume),
``base`` (the flat end x = 0, where the lug is bolted) and ``bore`` (the hole's wall,
where a pin pulls), so that ``calibrate --clamp base --load-region bore`` can use them.

    pip install gmsh && python examples/make_lug.py

gmsh is seeded and single-threaded, so the file is the same on every run.
"""

from __future__ import annotations

import sys
from pathlib import Path

LENGTH, WIDTH, THICK = 0.08, 0.03, 0.01  # m: bar length to the bore's centre, width, thickness
BORE = 0.006  # m: bore radius
SIZE = 0.0045  # m: target element size


def main(out: Path = Path(__file__).with_name("lug.msh")) -> Path:
    import gmsh

    gmsh.initialize(["-noenv"])
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.option.setNumber("Mesh.RandomSeed", 0)
        gmsh.model.add("lug")
        occ = gmsh.model.occ
        bar = occ.addBox(0, -WIDTH / 2, 0, LENGTH, WIDTH, THICK)
        head = occ.addCylinder(LENGTH, 0, 0, 0, 0, THICK, WIDTH / 2)
        hole = occ.addCylinder(LENGTH, 0, 0, 0, 0, THICK, BORE)
        body, _ = occ.fuse([(3, bar)], [(3, head)])
        body, _ = occ.cut(body, [(3, hole)])
        occ.synchronize()
        (vol,) = [t for d, t in body if d == 3]
        faces = [t for _, t in gmsh.model.getBoundary([(3, vol)], oriented=False)]
        base, bore = [], []
        for t in faces:
            x, y, _ = occ.getCenterOfMass(2, t)
            if abs(x) < 1e-9:
                base.append(t)  # the flat end x = 0
            elif abs(x - LENGTH) < 1e-6 and abs(y) < 1e-6:
                bore.append(t)  # the bore's wall (centred on the bore's axis)
        assert base and bore, (base, bore)
        gmsh.model.addPhysicalGroup(3, [vol], name="body")
        gmsh.model.addPhysicalGroup(2, base, name="base")
        gmsh.model.addPhysicalGroup(2, bore, name="bore")
        gmsh.option.setNumber("Mesh.MeshSizeMax", SIZE)
        gmsh.option.setNumber("Mesh.MeshSizeMin", SIZE / 3)
        gmsh.model.mesh.generate(3)
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.write(str(out))
        print(f"{out}: {len(gmsh.model.mesh.getElementsByType(4)[0])} tetrahedra")
    finally:
        gmsh.finalize()
    return out


if __name__ == "__main__":
    main(*(Path(a) for a in sys.argv[1:2]))
