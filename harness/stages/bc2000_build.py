"""The models of the bc2000 stage on the original program's meshes: reading the meshes a
case names, building MS / MT0 / MT with the case's fibre field, their loading and time
step, and lumped element masses (harness/stages/bc2000.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from harness.case.fibres import named_field_angles
from harness.errors import CaseError, SpringbenchError
from harness.io.meshfile import read_mesh
from harness.mechanics.dynamics import Loading
from harness.models.anisotropic import angles_of, build_anisotropic
from harness.models.masses import lumped_masses  # noqa: F401
from harness.models.massspring import build_massspring


def _meshes(case, dyn):
    out = [(case.body.file, read_mesh(case.body.file, case.body.format))]
    for rel in dyn["meshes"]:
        p = (case.path.parent / rel).resolve()
        try:
            out.append((p, read_mesh(p)))
        except SpringbenchError as exc:
            raise CaseError(exc.message, file=str(case.path), field="dynamics.meshes", fix=exc.fix)
    return out


def _label(path: Path, mesh) -> str:
    kind = "hexa" if "hexahedron" in mesh.cells else "tetra"
    return f"{kind}/{path.parent.name}/{path.name}"


def _cells(mesh):
    return mesh.cells.get("tetra", mesh.cells.get("hexahedron"))


def fibre_angles(model: dict, points, cells, field: str | None = None, material=None):
    """(azimuth, elevation) per element from the [model] keys, else from the case's
    [material.fibre] (the FEM reference's fibre), else vertical (tetra) / x, y, z (hexa)."""
    X = points[cells]
    g = X.mean(axis=1)
    fib = getattr(material, "fibre", None)
    if (
        fib is not None
        and not any(
            model.get(k) is not None
            for k in ("direction", "azimuth_deg", "elevation_deg", "fibre_field")
        )
        and field is None
    ):
        model = dict(
            model,
            direction=fib.direction,
            azimuth_deg=fib.azimuth_deg,
            elevation_deg=fib.elevation_deg,
            fibre_field=fib.field,
            seed=fib.seed,
        )
    field = field or model.get("fibre_field")
    if model.get("direction") is not None:
        a, e = angles_of(np.tile(model["direction"], (len(cells), 1)))
        return a, e
    if model.get("azimuth_deg") is not None or model.get("elevation_deg") is not None:
        return (
            np.full(len(cells), np.deg2rad(model.get("azimuth_deg") or 0.0)),
            np.full(len(cells), np.deg2rad(model.get("elevation_deg") or 0.0)),
        )
    if field is None:
        field = "vertical" if cells.shape[1] == 4 else None
    if field is None:  # hexa program: axes along x, y, z
        return np.zeros(len(cells)), np.zeros(len(cells))
    return named_field_angles(field, g, model.get("seed", 0), model.get("fibre_origin"))


def build(name: str, model: dict, mesh, dt: float, field: str | None = None, material=None):
    """One of MS, MT0, MT on the mesh, damping converted to physical units."""
    cells = _cells(mesh)
    scale = dt if model["damping_units"] == "per-step" else 1.0
    if name == "MS":
        return build_massspring(mesh.points, cells, ks=model["ms_ks"], kd=model["ms_kd"] * scale)
    a, e = fibre_angles(model, mesh.points, cells, field, material)
    ks = model["ks"] if len(model["ks"]) == 6 else model["ks"] * 6
    kd = model["kd"] if len(model["kd"]) == 3 else model["kd"] * 3
    return build_anisotropic(
        mesh.points,
        cells,
        azimuth=a,
        elevation=e,
        ks=ks,
        kd=np.asarray(kd) * scale,
        kvs=model["kvs"],
        kvd=model["kvd"] * scale,
        volume=(name == "MT"),
        rest_angle=model["rest_angle"],
        seed=model["seed"],
    )


def loading(model: dict, dyn: dict, mesh, dt: float) -> Loading:
    return Loading.from_flags(
        mesh.flags,
        mass=model["mass"],
        gravity=dyn["gravity"],
        push=dyn["push"],
        drag=dyn["drag"] * dt,
    )


def _dt(dyn, mesh, name):
    if name != "MS" and "hexahedron" in mesh.cells and dyn["hexa_model_dt"]:
        return dyn["hexa_model_dt"]
    return dyn["dt"]
