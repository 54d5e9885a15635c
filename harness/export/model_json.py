"""MODEL.vtu and MODEL.json of a calibrated network (``springbench calibrate``): the
network for ParaView and, for explicit engines, its particles, springs, damping, stable
step and any volume or kn term, in SI units (the keys: harness/commands/calibrate.py)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from harness.case.elasticity import lame
from harness.export.engine import spring_damping, stable_step
from harness.export.engine_loads import DT_SAFE
from harness.export.vtu import write_vtu
from harness.models.kn import KNTerm
from harness.models.p1 import P1Term
from harness.models.volume import NodeVolumeTerm


def _tets(net) -> dict:
    """The keys of a P1 model's material: tet_indices (2-D: triangles), per element E, nu
    (``info``'s E_elements, nu_elements; else its one E_effective, nu_effective on every
    element) and Newton's k_mu and k_lambda of them (harness/engines/newton_engine.py
    run_tets); E_effective and nu_effective: the pair every element shares, else null."""
    m = len(net.volume.elements)
    pair = [float(net.info.get(k, math.nan)) for k in ("E_effective", "nu_effective")]
    E = np.broadcast_to(np.asarray(net.info.get("E_elements", pair[0]), float), (m,))
    nu = np.broadcast_to(np.asarray(net.info.get("nu_elements", pair[1]), float), (m,))
    lam, mu = lame(E, nu)
    per = {"tet_E": E, "tet_nu": nu, "tet_k_mu": 4 / 3 * mu, "tet_k_lambda": lam + 5 / 6 * mu}
    out = {"tet_indices": np.asarray(net.volume.elements, int).tolist()}
    out.update({k: [x if math.isfinite(x) else None for x in v.tolist()] for k, v in per.items()})
    out.update(
        {k: v if math.isfinite(v) else None for k, v in zip(("E_effective", "nu_effective"), pair)}
    )
    return out


def _kn(vol) -> tuple[dict, dict]:
    """(units, keys) of springs + kn (harness/models/kn.py)."""
    units = dict(
        kn_node_volume="m^3 (2-D: m^2, unit thickness)",
        kn_stiffness="Pa = N/m^2 (2-D: N/m): E = sum_a kn_a/2 V_a d^2 s_a^2, s_a = mean over "
        "the springs at node a of (l - l0)/l0 (spring_indices, spring_rest_length), "
        "d = dim; each spring's tension T = sum over its two ends a of "
        "kn_a V_a d^2 s_a / (N_a l0), f_i = T (x_j - x_i)/l, f_j = -f_i",
    )
    keys = dict(
        kn_nodes=vol.nodes.tolist(),
        kn_node_volume=vol.V.tolist(),
        kn_spring_count=vol.N.astype(int).tolist(),
        kn_stiffness=vol.kv.tolist(),
        kn_shared=bool(vol.shared),
    )
    return units, keys


def _node_volume(vol) -> tuple[dict, dict]:
    """(units, keys) of springs + one volume term per node (harness/models/volume.py)."""
    units = dict(
        node_volume_rest="m^3 (2-D: m^2, unit thickness)",
        node_volume_element_rest="m^3 (2-D: m^2, unit thickness)",
        node_volume_stiffness="Pa = N/m^2 (2-D: N/m): E = sum_a kv_a/2 dV_a^2 / V0_a, "
        "dV_a = sum over the node_volume_elements e that hold node a of "
        "(V_e - V0_e) / (dim + 1); f = -dE/dx: each element's nodes "
        "get -mean over its nodes a of (kv_a dV_a / V0_a) times dV_e/dx",
    )
    keys = dict(
        node_volume_nodes=vol.nodes.tolist(),
        node_volume_rest=vol.Vn.tolist(),
        node_volume_stiffness=vol.kv.tolist(),
        node_volume_shared=bool(vol.shared),
        node_volume_elements=vol.elements.tolist(),
        node_volume_element_rest=vol.V0.tolist(),
    )
    return units, keys


def _element_volume(vol) -> tuple[dict, dict]:
    """(units, keys) of springs + volume per element (harness/models/volume.py)."""
    units = dict(
        volume_rest="m^3 (2-D: m^2, unit thickness)",
        volume_stiffness="Pa = N/m^2 (2-D: N/m): E = kv/2 (V - V0)^2 / V0, "
        "f = -kv (V - V0) / V0 dV/dx",
    )
    keys = dict(
        volume_indices=vol.elements.tolist(),
        volume_rest=vol.V0.tolist(),
        volume_stiffness=vol.kv.tolist(),
        volume_shared=bool(vol.shared),
    )
    return units, keys


P1_UNITS = dict(
    E_effective="Pa",
    tet_E="Pa",
    tet_k_mu="Pa (NVIDIA Newton's k_mu = 4/3 mu)",
    tet_k_lambda="Pa (NVIDIA Newton's k_lambda = lambda + 5/6 mu)",
)


def _term(net) -> tuple[dict, dict]:
    """(units, keys) of the network's volume, kn or material term (none: empty)."""
    vol = getattr(net, "volume", None)
    if isinstance(vol, KNTerm):
        return _kn(vol)
    if isinstance(vol, NodeVolumeTerm):
        return _node_volume(vol)
    if isinstance(vol, P1Term):  # linear simplices (model classes p1-global, p1)
        return dict(P1_UNITS), _tets(net)
    if vol is not None:
        return _element_volume(vol)
    return {}, {}


def _units(dim: int) -> dict:
    return {
        "length": "m",
        "mass": "kg",
        "time": "s",
        "spring_stiffness": "N/m (f = k (l - l0))",
        "spring_damping": "N s/m (f = kd (v_j - v_i) . d along the spring)",
        "spring_stiffness_times_length": "N (k l0; per-length convention, f = k l0 (l - l0) / l0)",
        "E": "Pa",
        "density": "kg/m^3",
        "omega_max": "rad/s",
        "G_norm": "RMS displacement error / RMS FEM displacement (weighted, fitted loads)",
        "note": "2-D models: unit thickness" if dim == 2 else "",
    }


def _finite(data: dict) -> dict:
    """``data`` with its non-finite floats as None (JSON null)."""
    return {
        k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in data.items()
    }


def _springs(net, zeta: float) -> tuple[dict, dict]:
    """(the particles' and springs' keys, the stable step's {dt_stable, ...}; empty when a
    mass is <= 0)."""
    L = net.rest_lengths
    q = np.hstack([net.points, np.zeros((net.n_nodes, 3 - net.dim))]) if net.dim < 3 else net.points
    k = np.asarray(net.k, float)
    positive = bool(np.all(np.asarray(net.masses) > 0))
    kd = spring_damping(net.springs, k, net.masses, zeta) if positive else np.full(len(k), np.nan)
    vol = getattr(net, "volume", None)
    step = stable_step(net.points, net.springs, k, net.masses, kd, volume=vol) if positive else {}
    keys = {
        "dim": net.dim,
        "particle_q": q.tolist(),
        "particle_mass": np.asarray(net.masses, float).tolist(),
        "spring_indices": np.asarray(net.springs, int).tolist(),
        "spring_rest_length": L.tolist(),
        "spring_stiffness": k.tolist(),
        "spring_damping": kd.tolist(),
        "damping_ratio": zeta,
        "spring_stiffness_times_length": (k * L).tolist(),
    }
    return keys, step


def export(net, out: Path, meta: dict | None = None) -> dict:
    """Write a model for engines: MODEL.vtu and MODEL.json (SI units, the module docstring).

    Parameters
    ----------
    net : harness.models.springs.Network
        The spring/mass model (with its volume or kn term, if any).
    out : Path
        MODEL.vtu; the JSON goes beside it with the suffix .json.
    meta : dict, optional
        Extra keys for the JSON (material, loads, the fit's record); ``damping_ratio``
        sets the springs' damping.

    Returns
    -------
    dict
        The JSON's data.
    """

    meta = dict(meta or {})
    out.parent.mkdir(parents=True, exist_ok=True)
    write_vtu(out, net)
    springs, step = _springs(net, float(meta.pop("damping_ratio", 0.0)))
    units, term = _term(net)
    data = {
        "units": {**_units(net.dim), **units},
        **springs,
        **{key: step.get(key, math.nan) for key in ("dt_stable", "dt_stable_float32", "omega_max")},
        **_finite(meta),
        **term,
    }
    dt = step.get("dt_stable", math.nan)
    data["dt_safe"] = DT_SAFE * dt if math.isfinite(dt) else math.nan
    if isinstance(data.get("settle_damping"), dict) and math.isfinite(data["dt_safe"]):
        data["settle_damping"] = dict(
            data["settle_damping"],
            velocity_factor=math.exp(-data["settle_damping"]["c"] * data["dt_safe"]),
        )
    data = _finite(data)
    bad = int(np.sum(np.asarray(net.masses) <= 0))
    if bad:
        data["warning"] = f"{bad} particle masses <= 0: not runnable explicitly"
    out.with_suffix(".json").write_text(json.dumps(data))
    return data
