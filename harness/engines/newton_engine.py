"""NVIDIA Newton (on the CPU, float32): a springbench export (``newton-springs``) or
Newton's own tetrahedral FEM (``newton-tets``) run to static equilibrium with
``SolverSemiImplicit`` (harness/engines/settle.py).

- newton-springs: the JSON's particles (``particle_q``, ``particle_mass``), springs
  (``spring_indices``, ``spring_stiffness`` as ke, ``spring_damping`` as kd), stepped at
  ``dt_safe`` with its ``settle_damping``, and, for
  springs+volume, its volume terms as tetrahedra with k_mu = 0, k_lambda = kv (Newton's
  energy is then kv/2 V0 (J - 1)^2, the export's kv/2 (V - V0)^2 / V0 to first order); a
  volume term per node (``node_volume_*``) has no Newton counterpart and is added as forces
  by Warp kernels each step (harness/engines/newton_volume.py).
  Its particles must be the pack's nodes (calibrate the pack's mesh).
- newton-tets: Newton's tetrahedra are the stable Neo-Hookean of Smith et al. 2018 (psi =
  k_mu/2 (I_C - 3) + k_lambda/2 (J - alpha)^2 - k_mu/2 log(I_C + 1)); linearised at rest it is
  linear elasticity with Lame mu = 3/4 k_mu and lambda = k_lambda - 5/8 k_mu, so the
  adapter sets k_mu = 4/3 mu and k_lambda = lambda + 5/6 mu of the pack's E and nu (the
  Lame values themselves would make the body 4/3 as stiff in shear). Lumped masses rho V / 4.
  With a calibrated material (``--model``: a p1 or p1-global export, harness/engines/
  tet_material.py) each tetrahedron takes the JSON's ``tet_k_mu``, ``tet_k_lambda`` instead;
  the masses stay the pack's lumped rho V / 4.

Nodes held in every component get mass 0 (Newton keeps them fixed); partly held ones (the
free-traction states' minimal constraints) have their held components reset each step.
The pack's nodal forces are applied as external particle forces; gravity is off (the
forces carry the body force).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from harness.case.elasticity import lame
from harness.engines.settle import (
    float32_resolution,
    lowest_omegas,
    not_tetrahedra,
    omega_max,
    p1_scaled_stiffness,
    rayleigh_omega,
    settle,
    tetrahedra,
    unsupported,
)
from harness.engines.tet_material import material, tet_export
from harness.errors import SpringbenchError
from harness.models.masses import lumped_masses

DT_MARGIN = (
    0.8  # of the free model's explicit limit 2 / omega_max (float32 forces; no damping margin)
)


class NewtonSim:
    """One Newton model; per load: forces, holds, damping; ``advance`` / ``measure`` for settle."""

    def __init__(self, q, masses, springs=(), tets=(), dt=1e-4, extra=None):
        import warp as wp

        # before Newton initialises Warp: no
        wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)
        #                                                                   banner or module log
        # on stdout
        import newton

        self.wp, self.newton = wp, newton
        self.q0 = np.asarray(q, float)
        self.masses = np.asarray(masses, float)
        self.springs, self.tets, self.dt = springs, tets, dt
        # forces Newton has no term for: apply(q, f)
        self.extra = None if extra is None else extra()

    def load(self, ld):
        """A fresh model and state at rest for this load's holds and forces (settle.Sim)."""
        newton, wp = self.newton, self.wp
        held_nodes, held_components, force = ld.held_nodes, ld.held_components, ld.force
        full = np.zeros(len(self.q0), bool)
        full[held_nodes[held_components.all(axis=1)]] = True
        b = newton.ModelBuilder(gravity=(0.0, 0.0, 0.0))
        for i, x in enumerate(self.q0):
            b.add_particle(
                wp.vec3(*x),
                wp.vec3(0.0, 0.0, 0.0),
                0.0 if full[i] else float(self.masses[i]),
                radius=0.0,
            )
        for i, j, ke, kd in self.springs:
            b.add_spring(int(i), int(j), float(ke), float(kd), 0.0)
        for i, j, k, l, mu, lam, damp in self.tets:
            b.add_tetrahedron(
                int(i),
                int(j),
                int(k),
                int(l),
                k_mu=float(mu),
                k_lambda=float(lam),
                k_damp=float(damp),
            )
        self.model = b.finalize(device="cpu")
        self.model.particle_grid = None  # no particle contacts
        self.solver = newton.solvers.SolverSemiImplicit(self.model)
        self.s0, self.s1, self.control = (
            self.model.state(),
            self.model.state(),
            self.model.control(),
        )
        self.fext = wp.array(np.asarray(force, np.float32), dtype=wp.vec3, device="cpu")
        part = ~held_components.all(axis=1)
        self.part_nodes, self.part_mask = held_nodes[part], held_components[part]

    def set_damping(self, factor: float):
        self.factor = np.float32(factor)

    def advance(self, n: int):
        """n steps; their positions, velocities and net forces are averaged (a float32
        engine's rounding keeps its high modes trembling)."""
        wp = self.wp
        acc = [np.zeros_like(self.q0) for _ in range(3)]
        for _ in range(n):
            self.s0.clear_forces()
            wp.copy(self.s0.particle_f, self.fext)
            if self.extra is not None:
                self.extra.apply(self.s0.particle_q, self.s0.particle_f)
            self.solver.step(self.s0, self.s1, self.control, None, self.dt)
            last = self.s0
            self.s0, self.s1 = self.s1, self.s0
            v = self.s0.particle_qd.numpy()
            v *= self.factor
            if len(self.part_nodes):
                x = self.s0.particle_q.numpy()
                x[self.part_nodes] = np.where(
                    self.part_mask, self.q0[self.part_nodes], x[self.part_nodes]
                )
                v[self.part_nodes] = np.where(self.part_mask, 0.0, v[self.part_nodes])
            self.s0.particle_qd.assign(v)
            if len(self.part_nodes):
                self.s0.particle_q.assign(x)
            acc[0] += self.s0.particle_q.numpy()
            acc[1] += v
            acc[2] += last.particle_f.numpy()
        self.mean = [a / n for a in acc]

    def measure(self):
        x, v, f = self.mean
        return x - self.q0, v, f


def _solve(pack, sim, masses, dt, omegas: dict) -> dict:
    """Every load settled, damped about critically for its own ``omegas[name]``."""
    out = {}
    for ld in pack.loads:
        sim.load(ld)
        out[ld.name] = settle(
            sim, ld, masses, dt, omegas[ld.name], resolution=float32_resolution(pack.points)
        )
    return out


def _materials(pack, tets, model, data) -> tuple:
    """(E, nu, k_mu, k_lambda), each (m,) per tetrahedron: the calibrated material ``data``
    of ``model`` (a MODEL.json path), else the pack's own E and nu in Newton's terms."""
    if model is not None:
        mat = material(data, model, pack.points, tets)
        return mat.E, mat.nu, mat.k_mu, mat.k_lambda
    lam, mu = lame(pack.E, pack.nu)
    one = np.ones(len(tets))
    return pack.E * one, pack.nu * one, 4.0 / 3.0 * mu * one, (lam + 5.0 / 6.0 * mu) * one


def run_tets(pack, options=None) -> dict:
    """{load: Answer} of Newton's tetrahedral FEM on the pack's tetrahedra, of the pack's
    material or (``options['model']``) a calibrated one per tetrahedron."""
    model = (options or {}).get("model")
    # a springs export is refused on any pack
    data = None if model is None else tet_export(model, "newton-tets")
    tets = tetrahedra(pack)
    if tets is None:
        return not_tetrahedra(pack, "newton-tets")
    E, nu, k_mu, k_lambda = _materials(pack, tets, model, data)
    masses = lumped_masses(pack.points, tets, pack.density)
    A = p1_scaled_stiffness(pack.points, tets, E, nu, masses)
    dt = DT_MARGIN * 2.0 / omega_max(A)
    tet_rows = [
        (*t, km, kl, 0.0) for t, km, kl in zip(_positive(pack.points, tets), k_mu, k_lambda)
    ]
    sim = NewtonSim(pack.points, masses, tets=tet_rows, dt=dt)
    return _solve(pack, sim, masses, dt, lowest_omegas(A, pack.loads))


def _positive(points, tets):
    """Tetrahedra ordered so their signed volume is positive (Newton's rest pose)."""
    e = points[tets[:, 1:]] - points[tets[:, :1]]
    neg = np.linalg.det(e) < 0
    out = tets.copy()
    out[neg, 1], out[neg, 2] = tets[neg, 2], tets[neg, 1]
    return out


def read_model(path) -> dict:
    """A springbench springs export's JSON (calibrate's MODEL.json), checked enough to run;
    a material export for the engines' tetrahedra is refused in one line."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
        tets = isinstance(data, dict) and "tet_indices" in data
        keys = ("particle_q", "particle_mass", "spring_indices", "spring_stiffness")
        for key in () if tets else keys:
            data[key]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise SpringbenchError(
            f"not a springbench model export ({type(exc).__name__}: {exc})",
            file=str(path),
            field="--model",
            fix="give the MODEL.json `springbench calibrate` wrote",
        ) from None
    if tets:
        raise SpringbenchError(
            "a material export for the engines' own tetrahedra (calibrate --model p1-global "
            "or p1), not springs",
            file=str(path),
            field="tet_indices",
            fix="run it with newton-tets (or mujoco-flex for p1-global)",
        )
    return data


def run_springs(pack, options=None) -> dict:
    """{load: Answer} of a springbench export (``options['model']``: its JSON path) in Newton."""
    options = dict(options or {})
    if options.get("model") is None:
        raise SpringbenchError(
            "newton-springs runs a springbench export",
            field="--model",
            fix="--model MODEL.json (from springbench calibrate on the pack's mesh)",
        )
    data = read_model(options["model"])
    q = np.asarray(data["particle_q"], float)[:, : pack.dim]
    if q.shape != pack.points.shape or not np.allclose(
        q, pack.points, atol=1e-9 * np.ptp(pack.points)
    ):
        raise SpringbenchError(
            f"the model's {len(q)} particles are not the pack's {pack.n_nodes} nodes",
            file=str(options["model"]),
            field="--model",
            fix="calibrate the pack's own mesh (mesh.vtu in the pack), in metres",
        )
    if data.get("kn_nodes"):  # Newton has no term for Kot & Nagahashi's nodal volumes
        raise SpringbenchError(
            "a springs+kn export: newton-springs has no kn term and would run its springs alone",
            file=str(options["model"]),
            field="kn_nodes",
            fix="calibrate with another --model (springs, springs+node-volume-*) for Newton",
        )
    if pack.dim != 3:
        return {ld.name: unsupported(pack, "newton-springs runs 3-D models") for ld in pack.loads}
    masses = np.asarray(data["particle_mass"], float)
    kd = data.get("spring_damping") or [0.0] * len(data["spring_stiffness"])
    springs = [
        (i, j, k, d) for (i, j), k, d in zip(data["spring_indices"], data["spring_stiffness"], kd)
    ]
    tets = [
        (*t, 0.0, kv, 0.0)
        for t, kv in zip(data.get("volume_indices", []), data.get("volume_stiffness", []))
    ]
    dt = float(data.get("dt_safe") or (0.9 * data["dt_stable_float32"]))
    if not (math.isfinite(dt) and dt > 0):
        raise SpringbenchError(
            "the model has no stable time step (masses not positive?)",
            file=str(options["model"]),
            field="--model",
            fix="calibrate with --masses lumped",
        )
    sd = data.get("settle_damping") or {}
    extra = None
    if data.get("node_volume_elements"):

        def extra():
            from harness.engines.newton_volume import NodeVolumeForces

            return NodeVolumeForces(len(q), data)

    # the export's own omega_1 (its network's lowest held-out mode), else each load's own
    # Rayleigh quotient: either way a load's damping does not depend on the other loads run
    omegas = {ld.name: sd.get("omega_1") or rayleigh_omega(ld, masses) for ld in pack.loads}
    sim = NewtonSim(pack.points, masses, springs=springs, tets=tets, dt=dt, extra=extra)
    return _solve(pack, sim, masses, dt, omegas)
