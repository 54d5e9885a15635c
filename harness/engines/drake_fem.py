"""Drake (pydrake, float64, CPU): the pack's tetrahedra as a deformable body of a discrete
MultibodyPlant (``DeformableModel.RegisterDeformableBody`` of a tetrahedral VTK file) with
Drake's own FEM, run to static equilibrium by its implicit integrator and SAP solver
(harness/engines/settle.py).

Drake's material is ``kLinear`` (small-strain linear elasticity, Lame constants of E and
nu): on linear tetrahedra with its one-point quadrature that is the P1 stiffness. Its
gravity is a force density rho g per reference volume, which the same quadrature gives
each node as rho V / 4 per element: the lumped masses times g, the pack's body force. Drake
takes no nodal forces, so only a pure body-force load (a ``gravity`` whose forces are the
lumped masses times it) runs; a load with other forces or partly held nodes is
``unsupported-load``. Held nodes are fixed exactly by a wall boundary condition (zero
displacement of every vertex in an open half space) when one coordinate plane separates
them from the rest, else by SAP fixed constraints to the world (compliant: see
docs/engines.md). Damping is Drake's mass-proportional coefficient, set from settle's rate.
"""

from __future__ import annotations

import dataclasses
import math
import tempfile
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from harness.engines.pybullet_fem import positive, write_vtk
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
CHECK = 20  # steps between the stopping rule's checks
MATERIAL = "kLinear"  # Drake's MaterialModel of the body
# wheels whose bundled VTK segfaults on reading any .vtk (docs/engines.md, drake#24421)
BROKEN_WHEELS = ("1.51.0", "1.52.0")


def broken_wheel() -> str | None:
    """Why the installed Drake cannot read the body (a crash, not an error), or None."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        v = version("drake")
    except PackageNotFoundError:  # pydrake built from source: no wheel
        return None
    if v in BROKEN_WHEELS:
        return (
            f'drake {v}\'s wheel crashes reading a VTK mesh: pip install "drake>=1.51.1,!=1.52.0"'
        )
    return None


def drake_mass(points: np.ndarray, tets: np.ndarray, density: float):
    """Drake's nodal mass matrix (csr, one row per node; the same for each component): the
    consistent mass at its one quadrature point, rho V / 16 between any two nodes of a
    tetrahedron; its rows sum to the lumped masses."""
    e = points[tets[:, 1:]] - points[tets[:, :1]]
    w = density * np.abs(np.linalg.det(e)) / 6.0 / 16.0
    rows = np.repeat(tets, 4, axis=1).ravel()
    cols = np.tile(tets, (1, 4)).ravel()
    n = len(points)
    return sp.csr_matrix((np.repeat(w, 16), (rows, cols)), shape=(n, n))


def wall_of(points: np.ndarray, held: np.ndarray):
    """(point, outward normal) of a coordinate half space holding exactly the ``held``
    nodes (Drake's wall condition), or None when no coordinate plane separates them."""
    mask = np.zeros(len(points), bool)
    mask[held] = True
    if not mask.any() or mask.all():
        return None
    span = float(np.ptp(points, axis=0).max())
    for axis in range(points.shape[1]):
        for sign in (1.0, -1.0):
            s = sign * points[:, axis]
            inside, outside = s[mask].max(), s[~mask].min()
            if inside < outside - 1e-9 * span:
                q = np.zeros(3)
                q[axis] = sign * 0.5 * (inside + outside)
                n = np.zeros(3)
                n[axis] = sign
                return q, n
    return None


class DrakeSim:
    """One Drake plant per load: its holds and gravity, Drake's mass damping from settle's
    rate; ``advance`` / ``measure`` for settle."""

    def __init__(self, pack, tets, dt: float, M):
        self.pack, self.tets, self.dt, self.M = pack, tets, dt, M
        self.simulator = None

    def load(self, ld):
        """Remember the load; the plant is built at the first ``advance``, once its damping
        is known (Drake fixes it when the body is registered) (settle.Sim)."""
        self.ld, self.alpha, self.simulator, self.holds = ld, 0.0, None, ""
        self.g = gravity_of(ld, lumped_masses(self.pack.points, self.tets, self.pack.density))
        self.held = ld.held_nodes[ld.held_components.all(axis=1)]

    def set_damping(self, factor: float):
        """Drake scales no velocities: its mass damping D = alpha M, alpha = -ln(factor)/dt
        (the same decay rate)."""
        self.alpha = -math.log(factor) / self.dt

    def _config(self):
        from pydrake.multibody.fem import DeformableBodyConfig, MaterialModel

        config = DeformableBodyConfig()
        config.set_youngs_modulus(self.pack.E)
        config.set_poissons_ratio(self.pack.nu)
        config.set_mass_density(self.pack.density)
        config.set_material_model(getattr(MaterialModel, MATERIAL))
        config.set_mass_damping_coefficient(self.alpha)
        config.set_stiffness_damping_coefficient(0.0)
        return config

    def _build(self):
        from pydrake.geometry import GeometryInstance, Mesh, ProximityProperties
        from pydrake.math import RigidTransform
        from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
        from pydrake.systems.analysis import Simulator
        from pydrake.systems.framework import DiagramBuilder

        builder = DiagramBuilder()
        config = MultibodyPlantConfig(time_step=self.dt, discrete_contact_approximation="sap")
        plant, _ = AddMultibodyPlant(config, builder)
        model = plant.mutable_deformable_model()
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "body.vtk"
            write_vtk(path, self.pack.points, self.tets)
            geometry = GeometryInstance(RigidTransform(), Mesh(str(path)), "body")
            geometry.set_proximity_properties(ProximityProperties())  # else SAP refuses it
            self.body = model.RegisterDeformableBody(geometry, self._config(), 1.0)
        self._hold(plant, model)
        plant.mutable_gravity_field().set_gravity_vector(self.g)
        plant.Finalize()
        self.plant, self.model = plant, model
        self.simulator = Simulator(builder.Build())
        self.context = plant.GetMyContextFromRoot(self.simulator.get_mutable_context())
        self.order = self._node_order(model.GetReferencePositions(self.body).reshape(-1, 3))
        self.steps = 0

    def _hold(self, plant, model):
        """The held nodes fixed: a wall condition when a coordinate plane separates them,
        else one SAP fixed constraint to the world per node (a sphere around it)."""
        from pydrake.geometry import Sphere
        from pydrake.math import RigidTransform

        pts = self.pack.points
        wall = wall_of(pts, self.held)
        if wall is not None:
            model.SetWallBoundaryCondition(self.body, *wall)
            self.holds = "held nodes by a wall condition (exact)"
            return
        self.holds = f"held nodes by {len(self.held)} SAP fixed constraints"
        if not len(self.held):
            return
        from scipy.spatial import cKDTree

        gap = cKDTree(pts).query(pts[self.held], k=2)[0][:, 1]
        for i, r in zip(self.held, gap):
            model.AddFixedConstraint(
                self.body,
                plant.world_body(),
                RigidTransform(),
                Sphere(0.25 * float(r)),
                RigidTransform(pts[i]),
            )

    def _node_order(self, x: np.ndarray) -> np.ndarray:
        """Drake's vertex index of each pack node (the VTK's order when Drake keeps it, else
        the nearest of Drake's reference positions)."""
        pts = self.pack.points
        if x.shape == pts.shape and np.allclose(x, pts, rtol=0, atol=1e-9 * np.ptp(pts)):
            return np.arange(len(pts))
        from scipy.spatial import cKDTree

        return cKDTree(x).query(pts)[1]

    def _state(self):
        q = self.model.GetPositions(self.context, self.body).T[self.order]
        v = self.model.GetVelocities(self.context, self.body).T[self.order]
        return q, v

    def advance(self, n: int):
        """``n`` steps; the velocity before the last one is kept (its acceleration)."""
        if self.simulator is None:
            self._build()
        self.steps += n - 1
        self.simulator.AdvanceTo(self.steps * self.dt)
        _, self.v0 = self._state()
        self.steps += 1
        self.simulator.AdvanceTo(self.steps * self.dt)
        self.x1, self.v1 = self._state()

    def measure(self):
        """(u, v, f): f estimated from Drake's own motion (it reports no internal forces):
        its step solves M (v1 - v0) / dt + alpha M v1 = f_net at the new state, so f_net is
        that left side, zero at rest whatever the material."""
        v0, v1 = self.v0, self.v1
        f = self.M @ ((v1 - v0) / self.dt + self.alpha * v1)
        f[self.held], v1 = 0.0, v1.copy()
        v1[self.held] = 0.0
        return self.x1 - self.pack.points, v1, f

    def close(self):
        self.simulator = None


def run(pack, options=None) -> dict:
    """{load: Answer} of Drake's FEM deformable body on the pack's tetrahedra (gravity
    loads)."""
    no_model(options, "drake-fem")
    tets = tetrahedra(pack)
    if tets is None:
        return not_tetrahedra(pack, "drake-fem")
    why = broken_wheel()
    if why is not None:
        return {ld.name: unsupported(pack, why) for ld in pack.loads}
    tets = positive(pack.points, tets)
    lumped = lumped_masses(pack.points, tets, pack.density)
    A = p1_scaled_stiffness(pack.points, tets, pack.E, pack.nu, lumped)
    M = drake_mass(pack.points, tets, pack.density)
    why = {ld.name: gravity_only(ld, lumped, "drake-fem", "fixes") for ld in pack.loads}
    runnable = [ld for ld in pack.loads if why[ld.name] is None]
    omegas = lowest_omegas(A, runnable)
    out = {}
    for ld in pack.loads:
        if why[ld.name] is not None:
            out[ld.name] = unsupported(pack, why[ld.name], "unsupported-load")
            continue
        dt = DT_OMEGA / omegas[ld.name]
        sim = DrakeSim(pack, tets, dt, M)
        sim.load(ld)
        a = settle(sim, ld, lumped, dt, omegas[ld.name], check=CHECK)
        sim.close()
        note = f"Drake {MATERIAL}, {sim.holds}"
        out[ld.name] = dataclasses.replace(a, note="; ".join(x for x in (a.note, note) if x))
    return out
