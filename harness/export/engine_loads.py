"""The loads and the settle recipe of calibrate's MODEL.json: what an engine needs to hold,
push and settle the exported network the way springbench's statics does (SI units).

- ``clamped_nodes`` {load: {"nodes": [...], "components": [[0, 1, 2], ...]}}: the held
  nodes of every fitted and held-out load and, per node, the components held at zero.
- ``loaded_nodes`` {load: [...]} and ``forces`` {load: [[fx, fy(, fz)], ...]} (N, one row
  per loaded node, in that order): the nodal forces springbench's statics applies (the
  FEM's consistent load of the tractions on the same facets, plus m g for gravity), so
  an engine that applies them needs no gravity of its own.
- ``gravity`` {load: [gx, gy(, gz)] m/s^2 or null}: the acceleration the body-force
  loads carry (already inside ``forces``).
- ``dt_safe`` (s): DT_SAFE times ``dt_stable``. Measured in NVIDIA Newton (float32,
  SolverSemiImplicit, the damping below) on a calibrated 875-tet cylinder: the held-out
  loads settle up to 0.95 dt_stable and diverge at 1.0.
- ``settle_damping`` {"c", "omega_1", "load", "velocity_factor"}: mass-proportional damping
  c = 2 omega_1 (1/s), about critical for the lowest mode of the held-out clamp
  (omega_1^2 = f.u / u.M u of the network's own static sag, a Rayleigh quotient a
  little above the lowest eigenvalue); after each step multiply every velocity by
  ``velocity_factor`` = exp(-c dt_safe). The held-out loads then settle in tens of that
  mode's periods: ~1,000-2,000 steps on the cylinder, where the springs' own kd (a few
  tenths of a percent of critical for that mode) took millions.
"""

from __future__ import annotations

import math

import numpy as np

from harness.mechanics import statics

DT_SAFE = 0.8


def _round(a) -> list:
    return [[float(f"{x:.9g}") for x in row] for row in np.asarray(a, float)]


def load_records(net, case) -> dict:
    """The JSON keys of the module docstring for every load of ``case`` on ``net``."""
    names, frees, forces = statics.all_load_arrays(net, case)
    dim = net.dim
    clamped, loaded, fs, gravity = {}, {}, {}, {}
    for name, free, f, load in zip(names, frees, forces, case.loads):
        held = ~free.reshape(-1, dim)
        rows = np.flatnonzero(held.any(axis=1))
        clamped[name] = {
            "nodes": rows.tolist(),
            "components": [np.flatnonzero(h).tolist() for h in held[rows]],
        }
        f = f.reshape(-1, dim)
        on = np.flatnonzero(np.any(f != 0, axis=1))
        loaded[name] = on.tolist()
        fs[name] = _round(f[on])
        gravity[name] = None if load.gravity is None else [float(g) for g in load.gravity]
    return {"clamped_nodes": clamped, "loaded_nodes": loaded, "forces": fs, "gravity": gravity}


def settle_recipe(net, case) -> dict | None:
    """``settle_damping`` (module docstring) from the network's static answer to its
    first held-out body-force load (else its first clamped load); None without one."""
    held = [l for l in case.loads if l.name in case.heldout]
    pick = next((l for l in held if l.gravity is not None), held[0] if held else None)
    if pick is None:
        pick = next((l for l in case.loads if l.constraints and l.family is None), None)
    if pick is None:
        return None
    res = statics.solve(net, case, [pick.name])
    u, f = res.u[0], res.forces[0]
    m = np.asarray(net.masses, float)[:, None]
    num, den = float(np.sum(f * u)), float(np.sum(m * u * u))
    if not (num > 0 and den > 0):
        return None
    omega = math.sqrt(num / den)
    c = 2.0 * omega
    return {
        "c": c,
        "omega_1": omega,
        "load": pick.name,
        "recipe": "after every step v *= velocity_factor = exp(-c dt) (mass-proportional "
        "damping c, about "
        "critical for the lowest mode); steps of dt_safe",
    }
