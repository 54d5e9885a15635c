"""A calibrated material for the engines' own tetrahedra (``springbench calibrate --model
p1-global`` or ``p1``; harness/export/model_json.py): MODEL.json's ``tet_indices``,
``tet_E``, ``tet_nu``, ``tet_k_mu``, ``tet_k_lambda`` (Newton's 4/3 mu and lambda + 5/6 mu)
and ``E_effective``, ``nu_effective`` (null when the elements differ), checked to be the
pack's tetrahedra and matched to them; and the record of which MODEL.json an engine ran.

The JSON's tetrahedra are the pack's when they hold the same node sets: calibrate orients
every element (V0 > 0, harness/models/volume.py ``oriented``) where the pack keeps the
mesh's cells, so rows are compared as sorted index tuples and each pack tetrahedron takes
the material of the JSON row with its four nodes.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from harness.case.elasticity import lame
from harness.errors import SpringbenchError

PER_TET = ("tet_E", "tet_nu", "tet_k_mu", "tet_k_lambda")
K_RTOL = 1e-9  # tet_k_mu, tet_k_lambda against 4/3 mu, lambda + 5/6 mu of tet_E, tet_nu
PAIR_RTOL = 1e-12  # every tet_E, tet_nu against E_effective, nu_effective
MODEL_KEY = "__model__"  # the record in an answer (.npz) of `engines run --model`
CALIBRATE = "calibrate the pack's own mesh, mesh.vtu in the pack"


@dataclass(frozen=True)
class TetMaterial:
    """Per pack tetrahedron (the pack's order): E (Pa), nu, Newton's k_mu and k_lambda
    (Pa); the export's one pair (None when its elements differ)."""

    path: Path
    E: np.ndarray
    nu: np.ndarray
    k_mu: np.ndarray
    k_lambda: np.ndarray
    E_effective: float | None
    nu_effective: float | None


def _error(path, field: str | None, message: str, fix: str) -> SpringbenchError:
    return SpringbenchError(message, file=str(path), field=field, fix=fix)


def load_json(path) -> dict:
    """MODEL.json as a dict; one line when it is no JSON object."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise _error(
            path, "--model", f"unreadable ({type(exc).__name__}: {exc})", "give a MODEL.json"
        ) from None
    if not isinstance(data, dict):
        raise _error(
            path, "--model", "not a JSON object", "give the MODEL.json springbench calibrate wrote"
        )
    return data


def tet_export(path, engine: str) -> dict:
    """The JSON at ``path``, refused in one line unless it is a material export for the
    engines' tetrahedra (a springs export has no ``tet_indices``)."""
    data = load_json(path)
    if "tet_indices" not in data:
        what = "a springs export" if "spring_indices" in data else "no material export"
        raise _error(
            path,
            "tet_indices",
            f"{what}: {engine} runs its own tetrahedra with a calibrated material",
            "run a springs export with newton-springs or mujoco-springs, or calibrate "
            "--model p1-global (or p1) for " + engine,
        )
    return data


def _array(data: dict, key: str, path, shape) -> np.ndarray:
    """``data[key]`` as a float array of ``shape`` with finite values (None: not finite)."""
    try:
        a = np.array(
            [np.nan if x is None else x for x in np.ravel(np.array(data[key], dtype=object))],
            float,
        ).reshape(shape)
    except (KeyError, TypeError, ValueError) as exc:
        raise _error(
            path, key, f"missing or not {shape} numbers ({type(exc).__name__})", CALIBRATE
        ) from None
    if not np.all(np.isfinite(a)):
        raise _error(path, key, "null or not finite", "calibrate again (a model with a material)")
    return a


def _indices(data: dict, path, n_nodes: int) -> np.ndarray:
    """``tet_indices`` (m, 4), every index a node of the pack."""
    try:
        t = np.asarray(data["tet_indices"], dtype=np.int64)
    except (TypeError, ValueError) as exc:
        raise _error(
            path, "tet_indices", f"not integers ({type(exc).__name__})", CALIBRATE
        ) from None
    if t.ndim != 2 or t.shape[1] != 4 or not len(t):
        raise _error(path, "tet_indices", f"shape {t.shape}, not (m, 4) tetrahedra", CALIBRATE)
    if t.min() < 0 or t.max() >= n_nodes:
        raise _error(
            path,
            "tet_indices",
            f"node ids {t.min()}..{t.max()}, the pack has {n_nodes} nodes",
            CALIBRATE,
        )
    return t


def _sorted_rows(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(each row's nodes sorted, the rows' lexicographic order)."""
    s = np.sort(t, axis=1)
    return s, np.lexsort(s.T[::-1])


def match(json_tets: np.ndarray, pack_tets: np.ndarray) -> np.ndarray | None:
    """``rows`` with pack tetrahedron i = JSON row rows[i] as node sets, or None when the two
    are not the same set of tetrahedra (counts, nodes, or a repeated tetrahedron)."""
    if json_tets.shape != pack_tets.shape:
        return None
    sj, oj = _sorted_rows(json_tets)
    sp, op = _sorted_rows(pack_tets)
    sj, sp = sj[oj], sp[op]
    if not np.array_equal(sj, sp) or (len(sj) > 1 and not np.any(sj[1:] != sj[:-1], axis=1).all()):
        return None
    rows = np.empty(len(op), np.int64)
    rows[op] = oj
    return rows


def signed_volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Each tetrahedron's signed volume (m^3) at ``points``."""
    return np.linalg.det(points[tets[:, 1:]] - points[tets[:, :1]]) / 6.0


def _same_nodes(data: dict, path, points: np.ndarray) -> None:
    """The export's particles (when it has them) are the pack's nodes."""
    if data.get("particle_q") is None:
        return
    q = _array(data, "particle_q", path, (-1, 3))[:, : points.shape[1]]
    if q.shape != points.shape or not np.allclose(q, points, atol=1e-9 * np.ptp(points)):
        raise _error(
            path,
            "particle_q",
            f"the model's {len(q)} particles are not the pack's {len(points)} nodes",
            CALIBRATE + ", in metres",
        )


def _checked_material(data: dict, path, m: int) -> dict:
    """The four per-tet arrays, each (m,), a material (E > 0, -1 < nu < 1/2) whose k_mu,
    k_lambda are Newton's 4/3 mu, lambda + 5/6 mu."""
    a = {key: _array(data, key, path, (m,)) for key in PER_TET}
    E, nu = a["tet_E"], a["tet_nu"]
    bad = np.flatnonzero(~((E > 0) & (nu > -1.0) & (nu < 0.5)))
    if len(bad):
        i = int(bad[0])
        raise _error(path, "tet_E", f"row {i}: E {E[i]:g}, nu {nu[i]:g} is no material", CALIBRATE)
    lam, mu = lame(E, nu)
    for key, want in (("tet_k_mu", 4.0 / 3.0 * mu), ("tet_k_lambda", lam + 5.0 / 6.0 * mu)):
        off = np.flatnonzero(np.abs(a[key] - want) > K_RTOL * np.abs(want))
        if len(off):
            i = int(off[0])
            raise _error(
                path,
                key,
                f"row {i}: {a[key][i]:.6g}, not Newton's "
                f"{'4/3 mu' if key == 'tet_k_mu' else 'lambda + 5/6 mu'} = {want[i]:.6g} "
                "of tet_E, tet_nu",
                "write the export again with springbench calibrate",
            )
    return a


def _pair(data: dict, key: str, path) -> float | None:
    value = data.get(key)
    if value is None:
        return None
    if not isinstance(value, (int, float)) or not np.isfinite(value):
        raise _error(path, key, f"{value!r} is not a number or null", CALIBRATE)
    return float(value)


def material(data: dict, path, points: np.ndarray, tets: np.ndarray) -> TetMaterial:
    """The export's material on the pack's tetrahedra ``tets`` (the pack's order), refused
    in one line unless the JSON's tetrahedra are the pack's, of positive volume."""
    _same_nodes(data, path, points)
    t = _indices(data, path, len(points))
    rows = match(t, tets)
    if rows is None:
        raise _error(
            path,
            "tet_indices",
            f"the model's {len(t)} tetrahedra are not the pack's {len(tets)} as node sets",
            CALIBRATE,
        )
    flat = np.flatnonzero(signed_volumes(points, t) <= 0)
    if len(flat):
        raise _error(
            path,
            "tet_indices",
            f"{len(flat)} tetrahedra of volume <= 0 (rows {flat[:5].tolist()})",
            CALIBRATE + ": calibrate orients every tetrahedron",
        )
    a = _checked_material(data, path, len(t))
    E_eff, nu_eff = _pair(data, "E_effective", path), _pair(data, "nu_effective", path)
    return TetMaterial(Path(path), *(a[k][rows] for k in PER_TET), E_eff, nu_eff)


def one_pair(mat: TetMaterial, engine: str) -> tuple[float, float]:
    """(E, nu) of an export with one material (``E_effective``, ``nu_effective``), refused
    in one line for an export whose elements differ: ``engine`` takes one material."""
    fix = "run it with newton-tets, or calibrate --model p1-global for " + engine
    for key, value in (("E_effective", mat.E_effective), ("nu_effective", mat.nu_effective)):
        if value is None:
            raise _error(
                mat.path,
                key,
                f"null: a per-tetrahedron export; {engine} takes one material per body",
                fix,
            )
    E, nu = float(mat.E_effective), float(mat.nu_effective)
    for key, per, one in (("tet_E", mat.E, E), ("tet_nu", mat.nu, nu)):
        if np.any(np.abs(per - one) > PAIR_RTOL * abs(one)):
            raise _error(
                mat.path,
                key,
                f"the elements differ ({per.min():.6g}..{per.max():.6g}); {engine} takes one "
                "material per body",
                fix,
            )
    return E, nu


def model_record(path) -> dict:
    """Which MODEL.json ran: its path, the first 16 hex digits of its bytes' SHA-256, the
    kind of export and its one (E, nu) pair (None where it has none)."""
    path = Path(path)
    data = load_json(path)
    kind = "tetrahedra" if "tet_indices" in data else "springs"
    pair = {k: data.get(k) for k in ("E_effective", "nu_effective")}
    return {
        "file": str(path),
        "sha256": hashlib.sha256(path.read_bytes()).hexdigest()[:16],
        "export": kind,
        **{k: float(v) if isinstance(v, (int, float)) else None for k, v in pair.items()},
    }


def describe(record: dict) -> str:
    """One line naming the model a record describes."""
    E, nu = record.get("E_effective"), record.get("nu_effective")
    pair = (
        f", E_effective {E:.6g} Pa, nu_effective {nu:.6g}"
        if E is not None and nu is not None
        else ", per-tetrahedron materials"
        if record.get("export") == "tetrahedra"
        else ""
    )
    return (
        f"model {record.get('file')} (sha256 {record.get('sha256')}, "
        f"a {record.get('export')} export{pair})"
    )
