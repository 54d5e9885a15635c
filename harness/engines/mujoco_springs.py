"""MuJoCo (float64, CPU): a springbench export (calibrate's MODEL.json: ``particle_q``,
``particle_mass``, ``spring_indices``, ``spring_rest_length``, ``spring_stiffness``,
``spring_damping``) run natively, to static equilibrium with the Euler integrator
(harness/engines/settle.py).

One body per particle at its ``particle_q``, with the JSON's mass and a slide joint along
each free axis (x, y, z): a component a load holds gets no joint, so a node held in every
component is a site of the world. Each spring is a spatial tendon between its two
particles' sites with ``stiffness`` k, ``springlength`` the rest length (the distance at
``particle_q`` when the JSON has none) and ``damping`` kd: MuJoCo's tendon force is then
k (l - l0) + kd dl/dt along it, the export's spring. The pack's nodal forces are applied
as ``xfrc_applied`` (gravity off: the forces carry the body force); settle's
mass-proportional damping c m is the joints' damping (implicit in MuJoCo's Euler). Steps
of the JSON's ``dt_safe``, damping for its ``settle_damping`` ``omega_1`` (else each load's
Rayleigh quotient), as newton-springs. Tendons carry springs only: an export with a volume
or kn term is refused in one line. Its particles must be the pack's nodes.
"""

from __future__ import annotations

import contextlib
import math

import numpy as np

from harness.engines.newton_engine import read_model
from harness.engines.settle import rayleigh_omega, settle, unsupported
from harness.errors import SpringbenchError

# an export's keys of a term MuJoCo's tendons cannot carry: (the --model that writes it,
# where else it runs)
TERMS = {
    "volume_indices": ("springs+volume-*", ", or run it in newton-springs"),
    "node_volume_elements": ("springs+node-volume-*", ", or run it in newton-springs"),
    "kn_nodes": ("springs+kn", ""),
}


def model_of(pack, options) -> dict:
    """The export ``options['model']`` names, checked to be the pack's nodes and springs only."""
    model = (options or {}).get("model")
    if model is None:
        raise SpringbenchError(
            "mujoco-springs runs a springbench export",
            field="--model",
            fix="--model MODEL.json (from springbench calibrate on the pack's mesh)",
        )
    data = read_model(model)
    q = np.asarray(data["particle_q"], float)[:, : pack.dim]
    if q.shape != pack.points.shape or not np.allclose(
        q, pack.points, atol=1e-9 * np.ptp(pack.points)
    ):
        raise SpringbenchError(
            f"the model's {len(q)} particles are not the pack's {pack.n_nodes} nodes",
            file=str(model),
            field="--model",
            fix="calibrate the pack's own mesh (mesh.vtu in the pack), in metres",
        )
    for key, (kind, elsewhere) in TERMS.items():
        if data.get(key):
            raise SpringbenchError(
                f"a {kind} export: MuJoCo's tendons carry springs only and would drop its term",
                file=str(model),
                field=key,
                fix=f"calibrate with --model springs for mujoco-springs{elsewhere}",
            )
    if not np.all(np.asarray(data["particle_mass"], float) > 0):
        raise SpringbenchError(
            "the model has particle masses <= 0 (not runnable by dynamics)",
            file=str(model),
            field="particle_mass",
            fix="calibrate with --masses lumped",
        )
    return data


def springs_of(data: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(pairs (s, 2), k (s) N/m, rest length (s) m, kd (s) N s/m) of the export's springs."""
    pairs = np.asarray(data["spring_indices"], int).reshape(-1, 2)
    k = np.asarray(data["spring_stiffness"], float)
    q = np.asarray(data["particle_q"], float)
    rest = data.get("spring_rest_length")
    rest = (
        np.linalg.norm(q[pairs[:, 1]] - q[pairs[:, 0]], axis=1)
        if rest is None
        else np.asarray(rest, float)
    )
    kd = np.asarray(data.get("spring_damping") or np.zeros(len(k)), float)
    return pairs, k, rest, np.nan_to_num(kd)


def _xml(points, masses, springs, free) -> str:
    """MJCF of the network: a body with a slide joint per free component (``free`` (n, 3)),
    a world site for a node held in every component, a spatial tendon per spring."""
    bodies = []
    for i, (x, m, f) in enumerate(zip(points, masses, free)):
        pos = " ".join(f"{c:.17g}" for c in x)
        if not f.any():
            bodies.append(f'<site name="s{i}" pos="{pos}"/>')
            continue
        joints = "".join(
            f'<joint type="slide" axis="{" ".join("1" if a == c else "0" for a in range(3))}"/>'
            for c in np.flatnonzero(f)
        )
        bodies.append(
            f'<body name="b{i}" pos="{pos}"><inertial pos="0 0 0" mass="{m:.17g}" '
            f'diaginertia="{1e-6 * m:.17g} {1e-6 * m:.17g} {1e-6 * m:.17g}"/>{joints}'
            f'<site name="s{i}"/></body>'
        )
    pairs, k, rest, kd = springs
    tendons = "".join(
        f'<spatial stiffness="{ke:.17g}" springlength="{l0:.17g}" damping="{d:.17g}">'
        f'<site site="s{i}"/><site site="s{j}"/></spatial>'
        for (i, j), ke, l0, d in zip(pairs, k, rest, kd)
    )
    return (
        '<mujoco><option timestep="1e-4" gravity="0 0 0" integrator="Euler"/>'
        f"<worldbody>{''.join(bodies)}</worldbody><tendon>{tendons}</tendon></mujoco>"
    )


@contextlib.contextmanager
def _warnings_kept(mj, sink: list):
    """MuJoCo's warnings go to ``sink`` (else it writes MUJOCO_LOG.TXT into the cwd)."""
    previous = mj.get_mju_user_warning()
    mj.set_mju_user_warning(sink.append)
    try:
        yield
    finally:
        mj.set_mju_user_warning(previous)


class MujocoSpringsSim:
    """One MuJoCo model per load (its held components have no joint); ``advance`` /
    ``measure`` for settle."""

    def __init__(self, points, masses, springs, dt):
        import mujoco

        self.mj, self.points, self.masses = mujoco, np.asarray(points, float), masses
        self.springs, self.dt = springs, dt

    def load(self, ld):
        """A fresh model at rest under this load's holds and forces (settle.Sim)."""
        mj = self.mj
        free = np.ones(self.points.shape, bool)
        free[ld.held_nodes] = ~ld.held_components
        self.warnings = []
        with _warnings_kept(mj, self.warnings):
            self.m = mj.MjModel.from_xml_string(_xml(self.points, self.masses, self.springs, free))
        self.m.opt.timestep = self.dt
        self.d = mj.MjData(self.m)
        moving = np.flatnonzero(free.any(axis=1))  # body b is node moving[b - 1]
        jb = self.m.jnt_bodyid
        self.node = moving[jb - 1]  # per joint: its node, component, dof and qpos address
        self.comp = np.argmax(np.abs(self.m.jnt_axis), axis=1)
        self.dof, self.qadr = self.m.jnt_dofadr.copy(), self.m.jnt_qposadr.copy()
        self.force = ld.force
        self.d.xfrc_applied[1 : len(moving) + 1, :3] = ld.force[moving]

    def set_damping(self, factor: float):
        c = -math.log(factor) / self.dt
        self.m.dof_damping[self.dof] = c * self.masses[self.node]

    def unstable(self) -> bool:
        return bool(self.d.warning[self.mj.mjtWarning.mjWARN_BADQACC].number)

    def advance(self, n: int):
        with _warnings_kept(self.mj, self.warnings):
            self.mj.mj_step(self.m, self.d, nstep=n)

    def measure(self):
        u = np.zeros_like(self.points)
        v = np.zeros_like(u)
        f = np.zeros_like(u)
        if self.unstable():
            return np.full_like(u, np.nan), v, f
        self.mj.mj_forward(self.m, self.d)
        at = (self.node, self.comp)
        u[at] = self.d.qpos[self.qadr]
        v[at] = self.d.qvel[self.dof]
        f[at] = self.d.qfrc_passive[self.dof] + self.force[at]
        return u, v, f


def run(pack, options=None) -> dict:
    """{load: Answer} of a springbench export (``options['model']``: its JSON path) in MuJoCo."""
    data = model_of(pack, options)
    if pack.dim != 3:
        return {ld.name: unsupported(pack, "mujoco-springs runs 3-D models") for ld in pack.loads}
    masses = np.asarray(data["particle_mass"], float)
    dt = float(data.get("dt_safe") or 0.8 * (data.get("dt_stable") or math.nan))
    if not (math.isfinite(dt) and dt > 0):
        raise SpringbenchError(
            "the model has no stable time step",
            file=str(options["model"]),
            field="dt_safe",
            fix="calibrate with --masses lumped",
        )
    omega = (data.get("settle_damping") or {}).get("omega_1")
    sim = MujocoSpringsSim(pack.points, masses, springs_of(data), dt)
    out = {}
    for ld in pack.loads:
        sim.load(ld)
        out[ld.name] = settle(sim, ld, masses, dt, omega or rayleigh_omega(ld, masses))
    return out
