"""MuJoCo (float64, CPU): the pack's tetrahedra as a 3-D flex (``flexcomp type="direct"``,
``dof="full"``: three slide joints per vertex) with MuJoCo's own elasticity
(``<elasticity young poisson>``), run to static equilibrium with the Euler integrator
(harness/engines/settle.py).

Nodes held in every component are ``<pin>``-ned; partly held ones have their held joints
reset each step. The pack's nodal forces are applied as ``xfrc_applied`` on the vertex
bodies (gravity off: the forces carry the body force); each vertex body gets its lumped
mass rho V / 4 and the joint damping c m (mass-proportional, implicit in MuJoCo's Euler).
MuJoCo 4 integrates flex elasticity explicitly (its implicit integrators refuse it): the
step starts at DT_START of the P1 model's limit 2 / omega_max and halves whenever MuJoCo
reports an unstable step (measured on gmsh cylinders: 0.2 of it stable, 0.4 not).

With a calibrated material (``--model``: a p1-global export, harness/engines/tet_material.py)
the flex's young and poisson are its ``E_effective``, ``nu_effective`` (a flex has one
material; a per-tetrahedron export whose elements differ is refused); the masses stay the
pack's lumped rho V / 4.
"""

from __future__ import annotations

import math

import numpy as np

from harness.engines.settle import (
    Answer,
    lowest_omegas,
    not_tetrahedra,
    omega_max,
    p1_scaled_stiffness,
    settle,
    tetrahedra,
)
from harness.engines.tet_material import material, one_pair, tet_export
from harness.models.masses import lumped_masses

DT_START = 0.2
HALVINGS = 4


def _xml(points, tets, held_full, E, nu) -> str:
    pts = " ".join(f"{x:.17g}" for x in points.ravel())
    el = " ".join(str(int(i)) for i in tets.ravel())
    pin = f'<pin id="{" ".join(str(int(i)) for i in held_full)}"/>' if len(held_full) else ""
    return (
        f'<mujoco><option timestep="1e-4" gravity="0 0 0" integrator="Euler"/><worldbody>'
        f'<flexcomp name="body" type="direct" dim="3" dof="full" point="{pts}" '
        f'element="{el}" mass="1" '
        'radius="0.0001"><contact contype="0" conaffinity="0" selfcollide="none"/><edge '
        'equality="false"/>'
        f'<elasticity young="{E:.17g}" poisson="{nu:.17g}" damping="0"/>{pin}</flexcomp>'
        f"</worldbody></mujoco>"
    )


class MujocoSim:
    """One MuJoCo model per load (its pins), ``advance`` / ``measure`` for settle."""

    def __init__(self, pack, tets, masses, dt, E=None, nu=None):
        import mujoco

        self.mj, self.pack, self.tets, self.masses, self.dt = mujoco, pack, tets, masses, dt
        # the flex's material: the pack's unless a calibrated one is given
        self.E = pack.E if E is None else E
        self.nu = pack.nu if nu is None else nu

    def load(self, ld):
        """A fresh model at rest under this load's pins, holds and forces (settle.Sim)."""
        mj = self.mj
        full = ld.held_nodes[ld.held_components.all(axis=1)]
        previous, self.warnings = mj.get_mju_user_warning(), []
        # else MuJoCo writes MUJOCO_LOG.TXT into the cwd
        mj.set_mju_user_warning(self.warnings.append)
        try:
            self.m = mj.MjModel.from_xml_string(
                _xml(self.pack.points, self.tets, full, self.E, self.nu)
            )
        finally:
            mj.set_mju_user_warning(previous)
        self.d = mj.MjData(self.m)
        self.m.opt.timestep = self.dt
        self.vb = self.m.flex_vertbodyid.copy()
        self.free_nodes = np.flatnonzero(self.vb > 0)
        bodies = self.vb[self.free_nodes]
        # (k, 3) each vertex's joints
        self.dof = self.m.body_dofadr[bodies][:, None] + np.arange(3)[None, :]
        self.m.body_mass[bodies] = self.masses[self.free_nodes]
        mj.mj_setConst(self.m, self.d)  # else the mass matrix keeps flexcomp's uniform masses
        self.d.xfrc_applied[bodies, :3] = ld.force[self.free_nodes]
        part = ~ld.held_components.all(axis=1)
        pos = {int(n): k for k, n in enumerate(self.free_nodes)}
        rows = [pos[int(n)] for n in ld.held_nodes[part]]
        self.hold = self.dof[rows][ld.held_components[part]] if rows else np.zeros(0, int)
        self.qpos_of = self.m.jnt_qposadr[self.m.dof_jntid[self.dof]]

    def set_damping(self, factor: float):
        c = -math.log(factor) / self.dt
        self.m.dof_damping[self.dof] = c * self.masses[self.free_nodes][:, None]

    def unstable(self) -> bool:
        return bool(self.d.warning[self.mj.mjtWarning.mjWARN_BADQACC].number)

    def advance(self, n: int):
        mj = self.mj
        if not len(self.hold):
            mj.mj_step(self.m, self.d, nstep=n)
            return
        qa = self.m.jnt_qposadr[self.m.dof_jntid[self.hold]]
        for _ in range(n):
            mj.mj_step(self.m, self.d)
            self.d.qpos[qa] = 0.0
            self.d.qvel[self.hold] = 0.0

    def measure(self):
        u = np.zeros_like(self.pack.points)
        v = np.zeros_like(u)
        f = np.zeros_like(u)
        if self.unstable():
            return np.full_like(u, np.nan), v, f
        self.mj.mj_forward(self.m, self.d)
        u[self.free_nodes] = self.d.qpos[self.qpos_of]
        v[self.free_nodes] = self.d.qvel[self.dof]
        f[self.free_nodes] = (
            self.d.qfrc_passive[self.dof] + self.d.xfrc_applied[self.vb[self.free_nodes], :3]
        )
        return u, v, f


def _material(pack, tets, model, data) -> tuple[float, float]:
    """(E, nu) of the flex: ``model``'s one calibrated pair (``data`` its JSON), else the
    pack's."""
    if model is None:
        return pack.E, pack.nu
    return one_pair(material(data, model, pack.points, tets), "mujoco-flex")


def run(pack, options=None) -> dict:
    """{load: Answer} of MuJoCo's flex on the pack's tetrahedra, of the pack's material or
    (``options['model']``) a calibrated one."""
    model = (options or {}).get("model")
    # a springs export is refused on any pack
    data = None if model is None else tet_export(model, "mujoco-flex")
    tets = tetrahedra(pack)
    if tets is None:
        return not_tetrahedra(pack, "mujoco-flex")
    E, nu = _material(pack, tets, model, data)
    masses = lumped_masses(pack.points, tets, pack.density)
    A = p1_scaled_stiffness(pack.points, tets, E, nu, masses)
    limit, omegas, out = 2.0 / omega_max(A), lowest_omegas(A, pack.loads), {}
    for ld in pack.loads:
        dt = DT_START * limit
        for _ in range(HALVINGS + 1):
            sim = MujocoSim(pack, tets, masses, dt, E, nu)
            sim.load(ld)
            ans = settle(sim, ld, masses, dt, omegas[ld.name])
            if ans.status != "diverged":
                break
            dt *= 0.5
        out[ld.name] = (
            ans
            if ans.status != "diverged"
            else Answer(
                ans.u,
                "diverged",
                ans.steps,
                ans.sim_time,
                ans.wall,
                note=f"unstable down to dt {dt:.3g} s",
            )
        )
    return out
