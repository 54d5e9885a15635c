"""Shared inputs of the Bourguignon & Cani tests: where the original program's data are
(REF, RUN), its vertical fibre direction, its cube_343 mesh, and a pushed cube_333 with its
three models for the engine comparisons (engines_models)."""

from pathlib import Path

import numpy as np

from harness.io.meshfile import read_mesh
from harness.mechanics.dynamics import PROGRAM_DRAG, Loading
from harness.models.anisotropic import build_anisotropic
from harness.models.massspring import build_massspring

ROOT = Path(__file__).resolve().parents[2]
REF = ROOT.parent / "shared" / "reference-data" / "bourguignon2000"
RUN = REF / "original-run"

VERTICAL = (np.pi / 2, np.pi / 2)  # the program's EXAMPLE_1 (azi = ele = pi/2)


def cube343():
    return read_mesh(REF / "meshes/tetra/cube_343/cube.mesh")


def engines_models(kind):
    """A pushed cube_333 and its three models (classic springs, elements with and without
    volume forces), for the engine comparisons."""
    mesh = read_mesh(REF / f"meshes/{kind}/cube_333/cube.mesh.push")
    cells = mesh.cells["tetra" if kind == "tetra" else "hexahedron"]
    dt = 0.004
    ld = Loading.from_flags(mesh.flags, drag=PROGRAM_DRAG * dt)
    models = [
        build_massspring(mesh.points, cells, ks=2.5, kd=10 * dt),
        build_anisotropic(
            mesh.points,
            cells,
            azimuth=0.3,
            elevation=0.7,
            ks=[3, 2, 1, 2.5, 1.5, 0.5],
            kd=[0.04, 0.02, 0.01],
            kvs=5.0,
            kvd=0.04,
            volume=True,
        ),
        build_anisotropic(
            mesh.points,
            cells,
            azimuth=0.3,
            elevation=0.7,
            ks=[3, 2, 1, 2.5, 1.5, 0.5],
            kd=[0.04, 0.02, 0.01],
            volume=False,
            rest_angle="rest",
        ),
    ]
    return mesh, ld, dt, models
