"""A benchmark pack: one body, one material and its loads as files any engine can read
(``springbench pack``), scored by ``springbench score --displacements``.

Folder layout (SI units throughout: m, N, kg, Pa, s):

- ``problem.json`` - the manifest: ``format`` = "springbench-pack", ``format_version``,
  ``units``, ``dim``, ``mesh`` (file name), ``n_nodes``, ``cells`` ({meshio type: count}),
  ``material`` ({E, nu, density, plane}), ``loads`` (a list, one entry per load: ``name``,
  ``role`` "fitted" or "heldout", ``kind``, ``gravity`` (m/s^2 vector or null), ``file``
  (its arrays), ``n_held``, ``force_total`` (N), ``u_fem_max`` (m), ``u_fem_error_max``
  (m)), ``load_set`` ("judged": the held-out loads that judge an engine, or "all") and
  where it came from (``source``, ``springbench`` version).
- ``mesh.vtu`` - the mesh the loads live on: points (m) and volume cells; node ids are
  row numbers of ``points``.
- ``loads/<name>.npz`` - per load: ``held_nodes`` (h,) int, ``held_components`` (h, dim)
  bool (which displacement components are held at zero), ``force`` (n, dim) N (the nodal
  forces: the FEM's consistent load of the tractions on the same facets plus the body
  force, rho g integrated against the linear hats = lumped masses times g), ``u_fem``
  (n, dim) m (the FEM displacement at every node) and ``u_fem_error`` (n,) m (the FEM's own
  error estimate at every node; NaN where none).
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness.errors import SpringbenchError
from harness.outputs import atomic_write

FORMAT = "springbench-pack"
FORMAT_VERSION = 1


@dataclass(frozen=True)
class PackLoad:
    """One load of a pack: what is held, what pushes, and the FEM's answer."""

    name: str
    role: str  # "fitted" or "heldout"
    held_nodes: np.ndarray  # (h,) int node ids
    held_components: np.ndarray  # (h, dim) bool: component held at zero displacement
    force: np.ndarray  # (n, dim) N, every node's external force
    u_fem: np.ndarray  # (n, dim) m
    u_fem_error: np.ndarray  # (n,) m, NaN where not estimated
    gravity: np.ndarray | None = None  # (dim,) m/s^2 when the load includes a body force
    kind: str = ""  # e.g. "traction", "gravity", "traction+gravity"


@dataclass(frozen=True)
class Pack:
    """A body (mesh points and volume cells), its material and its loads."""

    points: np.ndarray  # (n, dim) m
    cells: dict  # meshio cell type -> (m, k) int
    E: float  # Pa
    nu: float
    density: float  # kg/m^3
    loads: tuple[PackLoad, ...]
    plane: str | None = None  # 2-D: "stress" or "strain"
    meta: dict = field(default_factory=dict)

    @property
    def dim(self) -> int:
        return int(self.points.shape[1])

    @property
    def n_nodes(self) -> int:
        return int(self.points.shape[0])

    def load(self, name: str) -> PackLoad:
        return next(ld for ld in self.loads if ld.name == name)


UNITS = {
    "length": "m",
    "force": "N",
    "mass": "kg",
    "stress": "Pa",
    "density": "kg/m^3",
    "acceleration": "m/s^2",
    "displacement": "m",
}


DIGEST_KEY = "__pack_digest__"  # the pack's digest in an answer (.npz) of `engines run`


def pack_digest(pack: Pack) -> str:
    """16 hex digits of SHA-256 over the mesh, material and every load's holds and forces:
    the same for a pack and its copies, different for another clamp, load or mesh."""
    import hashlib

    h = hashlib.sha256()
    arrays = [pack.points, *(pack.cells[k] for k in sorted(pack.cells))]
    for ld in sorted(pack.loads, key=lambda ld: ld.name):
        h.update(ld.name.encode() + b"\0")
        arrays += [ld.held_nodes, ld.held_components, ld.force]
    h.update(repr((sorted(pack.cells), pack.E, pack.nu, pack.density, pack.plane)).encode())
    for a in arrays:
        a = np.asarray(a)
        a = a.astype({"b": np.uint8, "i": np.int64, "u": np.int64}.get(a.dtype.kind, np.float64))
        h.update(repr((a.dtype.str, a.shape)).encode() + np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def _bad(message: str, file, fix: str, field: str | None = None):
    raise SpringbenchError(message, file=str(file), field=field, fix=fix)


def write_pack(pack: Pack, out_dir) -> Path:
    """Write a benchmark pack: mesh.vtu, loads/<name>.npz and problem.json (written
    last), each file atomically.

    Parameters
    ----------
    pack : Pack
        The mesh, material and loads (held nodes, nodal forces, FEM displacements and
        their error estimates).
    out_dir : str or Path
        The pack's folder (made if missing).

    Returns
    -------
    Path
        problem.json, the manifest.
    """
    import meshio

    out = Path(out_dir)
    (out / "loads").mkdir(parents=True, exist_ok=True)
    mesh_path = out / "mesh.vtu"
    tmp = out / ".mesh.tmp.vtu"
    meshio.write(
        tmp,
        meshio.Mesh(
            np.asarray(pack.points, float), [(k, np.asarray(v, int)) for k, v in pack.cells.items()]
        ),
    )
    tmp.replace(mesh_path)
    entries = []
    for ld in pack.loads:
        buf = io.BytesIO()
        np.savez_compressed(
            buf,
            held_nodes=np.asarray(ld.held_nodes, np.int64),
            held_components=np.asarray(ld.held_components, bool),
            force=np.asarray(ld.force, float),
            u_fem=np.asarray(ld.u_fem, float),
            u_fem_error=np.asarray(ld.u_fem_error, float),
        )
        rel = f"loads/{ld.name}.npz"
        atomic_write(out / rel, buf.getvalue(), "--out")
        err = np.asarray(ld.u_fem_error, float)
        entries.append(
            {
                "name": ld.name,
                "role": ld.role,
                "kind": ld.kind,
                "gravity": None if ld.gravity is None else [float(g) for g in ld.gravity],
                "file": rel,
                "n_held": int(len(ld.held_nodes)),
                "force_total": [float(x) for x in np.asarray(ld.force).sum(axis=0)],
                "u_fem_max": float(np.linalg.norm(ld.u_fem, axis=1).max()),
                "u_fem_error_max": float(np.nanmax(err)) if np.isfinite(err).any() else None,
            }
        )
    manifest = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "units": UNITS,
        "dim": pack.dim,
        "mesh": "mesh.vtu",
        "n_nodes": pack.n_nodes,
        "cells": {k: int(len(v)) for k, v in pack.cells.items()},
        "material": {
            "E": float(pack.E),
            "nu": float(pack.nu),
            "density": float(pack.density),
            "plane": pack.plane,
        },
        "loads": entries,
        **{k: v for k, v in pack.meta.items() if k not in ("loads", "format")},
    }
    path = out / "problem.json"
    atomic_write(path, (json.dumps(manifest, indent=1) + "\n").encode(), "--out")
    return path


def _manifest(folder: Path) -> dict:
    """The pack's problem.json, its format and version checked."""
    man_path = folder / "problem.json"
    if not man_path.is_file():
        _bad(
            "no problem.json here: not a benchmark pack",
            folder,
            "give the folder `springbench pack` wrote",
        )
    try:
        man = json.loads(man_path.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        _bad(f"not JSON ({exc})", man_path, "write the pack again with `springbench pack`")
    if not isinstance(man, dict) or man.get("format") != FORMAT:
        _bad(
            f"format is {man.get('format') if isinstance(man, dict) else man!r}, not {FORMAT!r}",
            man_path,
            "give a pack written by `springbench pack`",
            "format",
        )
    if man.get("format_version") != FORMAT_VERSION:
        _bad(
            f"format_version {man.get('format_version')!r}; this springbench reads "
            f"{FORMAT_VERSION}",
            man_path,
            "write the pack again with this version of `springbench pack`",
            "format_version",
        )
    return man


LOAD_ARRAYS = ("held_nodes", "held_components", "force", "u_fem", "u_fem_error")


def _load(folder: Path, e: dict, n: int, dim: int) -> PackLoad:
    """One load of the manifest's list, its arrays checked against the mesh's n nodes."""
    f = folder / str(e.get("file", ""))
    try:
        z = np.load(f)
        arrays = {k: z[k] for k in LOAD_ARRAYS}
    except (OSError, KeyError, ValueError) as exc:
        _bad(
            f"load {e.get('name')!r}: unreadable ({type(exc).__name__}: {exc})",
            f,
            "write the pack again with `springbench pack`",
        )
    h = len(arrays["held_nodes"])
    shapes = {
        "force": (n, dim),
        "u_fem": (n, dim),
        "u_fem_error": (n,),
        "held_components": (h, dim),
    }
    for key, shape in shapes.items():
        if arrays[key].shape != shape:
            _bad(
                f"{key} has shape {arrays[key].shape}, expected {shape}",
                f,
                "write the pack again",
                key,
            )
    for key in ("force", "u_fem"):
        if not np.all(np.isfinite(arrays[key])):
            _bad(f"{key} holds NaN or infinite values", f, "write the pack again", key)
    if h and (arrays["held_nodes"].min() < 0 or arrays["held_nodes"].max() >= n):
        _bad("held_nodes outside the mesh's nodes", f, "write the pack again", "held_nodes")
    g = e.get("gravity")
    return PackLoad(
        str(e["name"]),
        str(e.get("role", "")),
        arrays["held_nodes"].astype(int),
        arrays["held_components"].astype(bool),
        arrays["force"].astype(float),
        arrays["u_fem"].astype(float),
        arrays["u_fem_error"].astype(float),
        None if g is None else np.asarray(g, float),
        str(e.get("kind", "")),
    )


def read_pack(folder) -> Pack:
    """Read a benchmark pack, every array checked against its manifest.

    Parameters
    ----------
    folder : str or Path
        The pack's folder or its problem.json.

    Returns
    -------
    Pack

    Raises
    ------
    SpringbenchError
        One line naming the file and the fix (missing file, wrong shape, bad manifest).
    """
    import meshio

    folder = Path(folder)
    if folder.name == "problem.json":
        folder = folder.parent
    man = _manifest(folder)
    try:
        mesh = meshio.read(folder / man["mesh"])
        dim, n = int(man["dim"]), int(man["n_nodes"])
        mat = man["material"]
        E, nu, rho = float(mat["E"]), float(mat["nu"]), float(mat["density"])
        entries = list(man["loads"])
    except (KeyError, TypeError, ValueError, OSError) as exc:
        _bad(
            f"incomplete or unreadable pack ({type(exc).__name__}: {exc})",
            folder / "problem.json",
            "write the pack again with `springbench pack`",
        )
    points = np.asarray(mesh.points, float)[:, :dim]
    if points.shape != (n, dim):
        _bad(
            f"the mesh has {len(points)} nodes, the manifest says {n}",
            folder / man["mesh"],
            "write the pack again with `springbench pack`",
            "n_nodes",
        )
    loads = tuple(_load(folder, e, n, dim) for e in entries)
    cells = {c.type: np.asarray(c.data, int) for c in mesh.cells}
    meta = {
        k: v for k, v in man.items() if k in ("source", "springbench", "peak_strain", "load_set")
    }
    return Pack(points, cells, E, nu, rho, loads, mat.get("plane"), meta)


def named_loads(text: str, names) -> list[str]:
    """The loads a ``--loads a,b`` value names, each one of the pack's ``names``; a one-line
    error naming --loads otherwise."""
    want = [n.strip() for n in text.split(",") if n.strip()]
    bad = [n for n in want if n not in names]
    if bad or not want:
        raise SpringbenchError(
            f"the pack has no load '{bad[0] if bad else text}'",
            field="--loads",
            fix=f"some of {', '.join(names)}",
        )
    return want
