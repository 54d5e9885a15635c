"""Spring networks to and from VTU (meshio; docs/design.md, "Files"), so ParaView opens them:
points = rest positions (z = 0 in 2-D), one ``line`` cell block = springs, point data
``mass``, cell data ``stiffness`` (linear spring k), optional point data ``u_<load>``
(displacements, padded to 3 components). We also write point data ``class`` (G weight
class) and cell data ``group``, and field data ``dim``; a file from anyone else needs
only points, lines and ``stiffness`` (masses default to 1, classes come from the
bounding box, dim is 2 when every z is 0).
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np

from harness.errors import SpringbenchError
from harness.models.sms import make_network
from harness.outputs import staged


def _pad3(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, float)
    return np.hstack([a, np.zeros((len(a), 3 - a.shape[1]))]) if a.shape[1] < 3 else a


def write_vtu(path, network, displacements: dict | None = None) -> Path:
    """Write a spring network as VTU (ParaView), atomically.

    Parameters
    ----------
    path : str or Path
        The .vtu file.
    network : harness.models.springs.Network
        Points, springs (line cells with ``stiffness`` and ``group``), masses, classes.
    displacements : dict of str to ndarray (n, dim), optional
        Point data ``u_<load>`` per load.

    Returns
    -------
    Path
        ``path``.
    """
    import meshio

    path = Path(path)
    point_data = {
        "mass": np.asarray(network.masses, float),
        "class": np.asarray(network.classes, np.int32),
    }
    for name, u in (displacements or {}).items():
        point_data[f"u_{name}"] = _pad3(u)
    mesh = meshio.Mesh(
        _pad3(network.points),
        [("line", np.asarray(network.springs, np.int64))],
        point_data=point_data,
        cell_data={
            "stiffness": [np.asarray(network.k, float)],
            "group": [np.asarray(network.groups, np.int32)],
        },
        field_data={"dim": np.array([network.dim], np.int32)},
    )
    with staged([path]) as (tmp,):  # atomic: never half a file (e.g. disk full)
        meshio.write(tmp, mesh, file_format="vtu")
    return path


def _read_mesh(path: Path):
    """meshio's reading of ``path``, its failures as one line naming the file."""
    import meshio

    if not path.exists():
        raise SpringbenchError("file not found", file=str(path), fix="check the path")
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            return meshio.read(path)
    except (Exception, SystemExit) as exc:  # meshio exits on some broken files
        why = (
            "the file is empty"
            if path.stat().st_size == 0
            else (
                "not a mesh file meshio reads (truncated, or another format?)"
                if isinstance(exc, SystemExit)
                else f"cannot read it as a mesh ({type(exc).__name__}: {exc})"
            )
        )
        raise SpringbenchError(
            why, file=str(path), fix="give a VTU file written by 'springbench build' or meshio"
        )


def _springs(m, path: Path):
    """(springs (s, 2), stiffness (s,), group (s,) or None) of the mesh's line cells."""
    blocks = [i for i, c in enumerate(m.cells) if c.type == "line"]
    if not blocks:
        raise SpringbenchError(
            "no 'line' cells (springs)", file=str(path), fix="springs are a line cell block"
        )
    springs = np.vstack([m.cells[i].data for i in blocks])
    if "stiffness" not in m.cell_data:
        raise SpringbenchError(
            "no cell data 'stiffness'",
            file=str(path),
            fix="store the spring constants as cell data 'stiffness'",
        )
    k = np.concatenate([np.asarray(m.cell_data["stiffness"][i], float).ravel() for i in blocks])
    groups = (
        np.concatenate([np.asarray(m.cell_data["group"][i]).ravel() for i in blocks]).astype(int)
        if "group" in m.cell_data
        else None
    )
    return springs, k, groups


def _points(m, path: Path) -> np.ndarray:
    """The mesh's points in its dimension (field data ``dim``, else 2 when z is 0)."""
    pts = np.asarray(m.points, float)
    dim = (
        int(np.ravel(m.field_data["dim"])[0])
        if "dim" in m.field_data
        else (2 if np.allclose(pts[:, 2:], 0) else 3)
    )
    pts = pts[:, :dim]
    bad = np.flatnonzero(~np.isfinite(pts).all(1))
    if len(bad):
        raise SpringbenchError(
            f"non-finite coordinates at points {bad[:5].tolist()}",
            file=str(path),
            fix="fix the point coordinates",
        )
    return pts


def read_vtu(path):
    """Read a spring network written by :func:`write_vtu` (or any VTU of line cells with
    cell data ``stiffness``).

    Parameters
    ----------
    path : str or Path
        The .vtu file.

    Returns
    -------
    network : harness.models.springs.Network
    displacements : dict of str to ndarray (n, dim)
        Its ``u_<load>`` point data by load name.
    """
    path = Path(path)
    m = _read_mesh(path)
    springs, k, groups = _springs(m, path)
    pts = _points(m, path)
    masses = np.asarray(m.point_data["mass"], float).ravel() if "mass" in m.point_data else None
    classes = (
        np.asarray(m.point_data["class"]).astype(int).ravel() if "class" in m.point_data else None
    )
    if np.any(~np.isfinite(k)) or np.any(k <= 0):
        raise SpringbenchError(
            "stiffness must be positive and finite", file=str(path), field="stiffness"
        )
    try:
        net = make_network(pts, springs, k, masses, classes, groups)
    except SpringbenchError as exc:  # about this file's springs: name it
        raise SpringbenchError(
            exc.message,
            file=str(path),
            field=exc.field,
            fix=exc.fix or "springs are pairs of distinct point indices 0 .. n-1",
        ) from None
    dim = pts.shape[1]
    disp = {
        name[2:]: np.asarray(v, float)[:, :dim]
        for name, v in m.point_data.items()
        if name.startswith("u_")
    }
    return net, disp
