"""The stopping rule (harness/engines/settle.py) cannot be fooled: a body that ignores its
load, a frozen body and a slow mode the damping was not tuned for are never `settled`;
the per-load omega_1 is the lowest mode under that load's holds, computed here with
numpy's dense eigensolver on an independent scikit-fem P1 stiffness."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from harness.engines import settle as S

F = np.array([[0.0, -2.0, 1.0], [1.0, 0.5, 0.0]])  # N, on two nodes


class Springs:
    """Nodes on springs k (N/m) to the ground with masses m (kg) under the forces F (n, 3),
    stepped by symplectic Euler with the settle damping. ``load_on``: whether the dynamics
    feel F; ``report``: whether the measured net force includes F (an adapter that drops
    the load but reports the true net force, or one that drops it everywhere); ``frozen``:
    u stays at that share of the answer."""

    def __init__(self, k, m, F, load_on=True, report=True, frozen=None):
        self.k, self.m, self.F = k[:, None], m[:, None], F
        self.load_on, self.report, self.frozen = load_on, report, frozen
        self.dt = 0.2 * 2.0 / float(np.sqrt(k / m).max())
        self.u = np.zeros_like(F) if frozen is None else frozen * F / self.k
        self.v = np.zeros_like(F)
        self.damp = 1.0

    def set_damping(self, factor):
        self.damp = factor

    def advance(self, n):
        if self.frozen is not None:
            return
        f = self.F if self.load_on else 0.0
        for _ in range(n):
            self.v = self.damp * (self.v + self.dt * (f - self.k * self.u) / self.m)
            self.u = self.u + self.dt * self.v

    def measure(self):
        f = (self.F if self.report else 0.0) - self.k * self.u
        return self.u.copy(), self.v.copy(), f

    def answer(self):
        return self.F / self.k


def run(sim: Springs, omega=None, max_steps=20_000):
    """settle on the sim's load (nothing held), damped for ``omega`` (default: its slowest
    mode, a lower bound on every mode)."""
    load = SimpleNamespace(
        force=sim.F,
        u_fem=sim.answer(),
        held_nodes=np.zeros(0, int),
        held_components=np.zeros((0, 3), bool),
    )
    omega = omega or float(np.sqrt(sim.k / sim.m).min())
    return S.settle(sim, load, sim.m[:, 0], sim.dt, omega, max_steps=max_steps)


K, M = np.array([4.0e3, 1.0e3]), np.array([0.5, 0.5])


def test_the_rule_settles_a_body_at_its_equilibrium():
    a = run(Springs(K, M, F))
    assert a.status == "settled" and a.steps < 20_000
    assert np.abs(a.u - F / K[:, None]).max() <= 1e-4 * np.abs(F / K[:, None]).max()
    assert a.residual <= S.RES_TOL


@pytest.mark.parametrize("report", [True, False], ids=["reports-load", "drops-load"])
def test_a_body_that_ignores_its_load_is_never_settled(report):
    """u = 0 under a load: the true net force is the load (residual 1); an adapter that
    drops the load everywhere reports no net force, but the load did no work on u."""
    a = run(Springs(K, M, F, load_on=False, report=report))
    assert a.status == "not-settled", a
    assert np.all(a.u == 0.0) and a.residual == pytest.approx(1.0 if report else 0.0)
    assert "residual" in a.note and "bound" in a.note


@pytest.mark.parametrize("share", [0.0, 0.5, 0.99])
def test_a_frozen_body_is_never_settled(share):
    """A body stuck at a share of its answer: nothing moves, nothing falls."""
    a = run(Springs(K, M, F, frozen=share))
    assert a.status == "not-settled", a
    assert a.residual == pytest.approx(1.0 - share) and f"{1 - share:.2g}" in a.note


def test_a_slow_mode_is_not_settled_short():
    """A heavy node whose mode is 100x slower than the omega_1 the damping was tuned for,
    beside a stiff one 300x faster that sets the step (a continuum's high modes): over a
    check the heavy node creeps by ~1e-5 of its way, the net force has stalled, and it has
    not started; the residual (its share of the load's work) says so."""
    F3 = np.array([[0.0, 0.0, 1.0], [0.0, -2.0, 1.0], [1.0, 0.5, 0.0]])
    sim = Springs(np.full(3, 4.0e3), 0.5 * np.array([300.0**-2, 1.0, 100.0**2]), F3)
    a = run(sim, omega=float(np.sqrt(4.0e3 / 0.5)))
    assert a.status == "not-settled", a
    assert a.residual > S.RES_TOL
    assert np.abs(a.u - sim.answer())[2].max() > 0.9 * np.abs(sim.answer()[2]).max()


def test_omega_1_is_the_lowest_mode_under_the_loads_holds():
    """lowest_omegas: per load, the smallest omega of the P1 model with that load's held
    components removed (numpy's dense eigensolver on scikit-fem's K, here), below the
    load's own Rayleigh quotient, the same whatever other loads are asked with it."""
    from harness.models.masses import lumped_masses
    from tests.independent import p1_bodies as P1

    b = P1.body("beam", P1.beam_mesh(), 1e5, 0.3, 1000.0)
    masses = lumped_masses(b.points, b.tets, 1000.0)
    K, _ = P1.p1_stiffness(P1.beam_mesh(), 1e5, 0.3)
    clamp = SimpleNamespace(
        name="sag",
        held_nodes=b.clamped,
        held_components=np.ones((len(b.clamped), 3), bool),
        force=b.forces["sag"],
        u_fem=b.answers["sag"],
    )
    ends = np.flatnonzero(np.isin(b.points[:, 0], [0.0, b.points[:, 0].max()]))
    bridge = SimpleNamespace(
        name="bridge",
        held_nodes=ends,
        held_components=np.ones((len(ends), 3), bool),
        force=b.forces["sag"],
        u_fem=b.answers["sag"],
    )
    A = S.p1_scaled_stiffness(b.points, b.tets, 1e5, 0.3, masses)
    both = S.lowest_omegas(A, [clamp, bridge])
    assert both["sag"] == S.lowest_omegas(A, [clamp])["sag"]
    for ld in (clamp, bridge):
        free = np.flatnonzero(S.free_mask(ld).ravel())
        s = 1.0 / np.sqrt(np.repeat(masses, 3)[free])
        lam = np.linalg.eigvalsh(K[free][:, free].toarray() * s[:, None] * s[None, :])
        assert both[ld.name] == pytest.approx(np.sqrt(lam[0]), rel=1e-8)
    assert both["sag"] <= S.rayleigh_omega(clamp, masses) and both["bridge"] > 2 * both["sag"]
