"""Bullet (pybullet, float64, CPU): the pack's tetrahedra as a deformable body with Bullet's
own Neo-Hookean FEM (``loadSoftBody`` of a legacy VTK file, ``useNeoHookean``), run to
static equilibrium by Bullet's implicit deformable solver (harness/engines/settle.py).

Bullet's Neo-Hookean is the stable one Newton uses (psi = k_mu/2 (I_C - 3) + k_lambda/2
(J - alpha)^2 - k_mu/2 log(I_C + 1)), so the adapter sets k_mu = 4/3 mu, k_lambda = lambda +
5/6 mu of the pack's E and nu (linear elasticity at rest). Bullet takes no nodal forces
and gives every node the same mass (the body's rho V over the node count): only a pure
body-force load (its forces the lumped masses times the load's ``gravity``) can be run,
as Bullet's gravity on those uniform masses; its answer is P1 under the uniform masses'
weight, which the note states. Nodes held in every component are anchored
(``createSoftBodyAnchor``); a load with other forces or partly held nodes is unsupported.
Sleeping is off: a body Bullet puts to sleep stops short of equilibrium.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

from harness.case.elasticity import lame
from harness.engines.settle import (
    gravity_of,
    gravity_only,
    lowest_omegas,
    no_model,
    not_tetrahedra,
    p1_scaled_stiffness,
    settle,
    tetrahedra,
    unsupported,
)
from harness.models.masses import lumped_masses

DT_OMEGA = 0.5  # the implicit step times the load's omega_1
CHECK = 50  # steps between the stopping rule's checks


def neo_hookean(E: float, nu: float) -> tuple[float, float]:
    """(k_mu, k_lambda) of Bullet's Neo-Hookean that linearise at rest to (E, nu)."""
    lam, mu = lame(E, nu)
    return 4.0 / 3.0 * mu, lam + 5.0 / 6.0 * mu


def write_vtk(path: Path, points: np.ndarray, tets: np.ndarray):
    """A legacy ASCII VTK UNSTRUCTURED_GRID of tetrahedra (cell type 10)."""
    lines = ["# vtk DataFile Version 2.0", "springbench pack", "ASCII", "DATASET UNSTRUCTURED_GRID"]
    lines.append(f"POINTS {len(points)} double")
    lines += [" ".join(f"{c:.17g}" for c in x) for x in points]
    lines.append(f"CELLS {len(tets)} {5 * len(tets)}")
    lines += ["4 " + " ".join(str(int(i)) for i in t) for t in tets]
    lines.append(f"CELL_TYPES {len(tets)}")
    lines += ["10"] * len(tets)
    path.write_text("\n".join(lines) + "\n")


def positive(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Tetrahedra ordered so their signed volume is positive (Bullet's inverted ones explode)."""
    e = points[tets[:, 1:]] - points[tets[:, :1]]
    neg = np.linalg.det(e) < 0
    out = tets.copy()
    out[neg, 1], out[neg, 2] = tets[neg, 2], tets[neg, 1]
    return out


@contextlib.contextmanager
def _c_output_silenced(fds=(1,)):
    """Bullet's C++ code prints its build time (stderr) and each mesh's node counts (stdout):
    those file descriptors go to /dev/null while it runs (Python errors still raise)."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(fd) for fd in fds]
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        for fd in fds:
            os.dup2(null, fd)
        yield
    finally:
        for fd, keep in zip(fds, saved):
            os.dup2(keep, fd)
        for fd in (*saved, null):
            os.close(fd)


class PybulletSim:
    """One Bullet deformable world per load: anchors and gravity of the load, Bullet's
    damping from settle's rate; ``advance`` / ``measure`` for settle."""

    def __init__(self, pack, tets, mass: float, dt: float, K):
        with _c_output_silenced((1, 2)):
            import pybullet

        self.pb, self.pack, self.tets = pybullet, pack, tets
        self.mass, self.dt, self.K = mass, dt, K
        self.node_mass = mass / pack.n_nodes
        self.client = None

    def load(self, ld):
        """Remember the load; the body is built at the first ``advance``, once its damping
        is known (Bullet fixes the damping when it loads the body) (settle.Sim)."""
        self.close()
        self.ld, self.alpha = ld, 0.0
        self.g = gravity_of(ld, lumped_masses(self.pack.points, self.tets, self.pack.density))

    def set_damping(self, factor: float):
        """Bullet scales no velocities: its Neo-Hookean damping (stiffness-proportional, C =
        alpha K) with alpha = 2 / c, c = -ln(factor) / dt (critical at omega = c when settle
        is given half the load's omega_1)."""
        c = -math.log(factor) / self.dt
        self.alpha = 2.0 / c if c > 0 else 0.0

    def _build(self):
        pb = self.pb
        self.client = pb.connect(pb.DIRECT)
        pb.resetSimulation(pb.RESET_USE_DEFORMABLE_WORLD, physicsClientId=self.client)
        k_mu, k_lambda = neo_hookean(self.pack.E, self.pack.nu)
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "body.vtk"
            write_vtk(path, self.pack.points, self.tets)
            with _c_output_silenced():
                self.body = pb.loadSoftBody(
                    str(path),
                    basePosition=[0, 0, 0],
                    scale=1,
                    mass=self.mass,
                    useNeoHookean=1,
                    NeoHookeanMu=k_mu,
                    NeoHookeanLambda=k_lambda,
                    NeoHookeanDamping=self.alpha,
                    collisionMargin=0.0,
                    useSelfCollision=0,
                    frictionCoeff=0.0,
                    useFaceContact=0,
                    physicsClientId=self.client,
                )
        self.order = self._node_order()
        ld = self.ld
        for i in ld.held_nodes[ld.held_components.all(axis=1)]:
            pb.createSoftBodyAnchor(
                self.body, int(self.order[i]), -1, -1, physicsClientId=self.client
            )
        pb.changeDynamics(
            self.body,
            -1,
            activationState=pb.ACTIVATION_STATE_DISABLE_SLEEPING,
            physicsClientId=self.client,
        )
        pb.setGravity(*self.g, physicsClientId=self.client)
        pb.setTimeStep(self.dt, physicsClientId=self.client)

    def _node_order(self) -> np.ndarray:
        """Bullet's node index of each pack node (the VTK's order when Bullet keeps it, else
        the nearest of Bullet's rest positions)."""
        x = self._raw()
        pts = self.pack.points
        if x.shape == pts.shape and np.allclose(x, pts, rtol=0, atol=1e-9 * np.ptp(pts)):
            return np.arange(len(pts))
        from scipy.spatial import cKDTree

        return cKDTree(x).query(pts)[1]

    def _raw(self) -> np.ndarray:
        pb = self.pb
        _, x = pb.getMeshData(
            self.body, -1, flags=pb.MESH_DATA_SIMULATION_MESH, physicsClientId=self.client
        )
        return np.asarray(x, float)

    def _x(self) -> np.ndarray:
        return self._raw()[self.order]

    def advance(self, n: int):
        """``n`` steps; the last three positions are kept (velocity and acceleration)."""
        if self.client is None:
            self._build()
        for _ in range(n - 2):
            self.pb.stepSimulation(physicsClientId=self.client)
        self.hist = [self._x()]
        for _ in range(2):
            self.pb.stepSimulation(physicsClientId=self.client)
            self.hist.append(self._x())

    def measure(self):
        """(u, v, f): f is estimated from Bullet's own motion, not read (pybullet gives no
        internal forces): backward Euler's M (v1 - v0) / dt = f_net - C v1 with C = alpha
        K (Bullet's damping, linearised at rest with the P1 stiffness), so f_net = M (v1 -
        v0) / dt + alpha K v1, zero at rest whatever the material."""
        x, x0, x1 = self.hist
        v0, v1 = (x0 - x) / self.dt, (x1 - x0) / self.dt
        damping = self.alpha * (self.K @ v1.ravel()).reshape(v1.shape)
        f = self.node_mass * (v1 - v0) / self.dt + damping
        held = self.ld.held_nodes[self.ld.held_components.all(axis=1)]
        f[held], v1[held] = 0.0, 0.0
        return x1 - self.pack.points, v1, f

    def close(self):
        if self.client is not None:
            self.pb.disconnect(physicsClientId=self.client)
            self.client = None


def run(pack, options=None) -> dict:
    """{load: Answer} of Bullet's FEM soft body on the pack's tetrahedra (gravity loads)."""
    no_model(options, "pybullet-fem")
    tets = tetrahedra(pack)
    if tets is None:
        return not_tetrahedra(pack, "pybullet-fem")
    tets = positive(pack.points, tets)
    lumped = lumped_masses(pack.points, tets, pack.density)
    mass = float(lumped.sum())
    uniform = np.full(pack.n_nodes, mass / pack.n_nodes)
    A = p1_scaled_stiffness(pack.points, tets, pack.E, pack.nu, uniform)
    K = (uniform[0] * A).tocsr()  # the P1 stiffness: uniform masses scale it evenly
    why = {ld.name: gravity_only(ld, lumped, "pybullet-fem", "anchors") for ld in pack.loads}
    runnable = [ld for ld in pack.loads if why[ld.name] is None]
    omegas = lowest_omegas(A, runnable)
    note = f"Bullet's node masses uniform, {mass / pack.n_nodes:.4g} kg each (rho V / n)"
    out = {}
    for ld in pack.loads:
        if why[ld.name] is not None:
            out[ld.name] = unsupported(pack, why[ld.name], "unsupported-load")
            continue
        dt = DT_OMEGA / omegas[ld.name]
        sim = PybulletSim(pack, tets, mass, dt, K)
        sim.load(ld)
        try:
            a = settle(sim, ld, uniform, dt, 0.5 * omegas[ld.name], check=CHECK)
        finally:
            sim.close()
        out[ld.name] = dataclasses.replace(a, note="; ".join(x for x in (a.note, note) if x))
    return out
