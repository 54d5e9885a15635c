"""pybullet-fem against a P1 FEM solved here: Bullet gives every node the same mass and
takes gravity only, so its sag is the linear P1 answer under the uniform masses' weight
(rho V / n per node), to the Neo-Hookean's departure from linear at the load's peak
strain (1.09 PEAK measured on this beam at nu 0.3 and 0.45, 1e-5 at PEAK / 100: linear in
the load). A traction is unsupported; an adapter that drops gravity or gives Bullet the raw
Lame constants fails."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from harness.export.pack import Pack, PackLoad
from tests.independent import p1_bodies as P1

pytest.importorskip("pybullet")
E, RHO = 1e5, 1000.0
TOL = 1.5 * P1.PEAK  # the nonlinear material's departure from linear P1 (1.09 PEAK measured)


@functools.cache
def body(nu: float) -> P1.Body:
    return P1.body("beam", P1.beam_mesh(), E, nu, RHO)


def volume(b: P1.Body) -> float:
    e = b.points[b.tets[:, 1:]] - b.points[b.tets[:, :1]]
    return float(np.abs(np.linalg.det(e)).sum() / 6.0)


def gravity(b: P1.Body) -> np.ndarray:
    """The sag's gravity (m/s^2): its forces are rho g times each node's share of volume."""
    return np.array([0.0, 0.0, b.forces["sag"][:, 2].sum() / (RHO * volume(b))])


def pack_of(b: P1.Body, nu: float) -> Pack:
    held = np.ones((len(b.clamped), 3), bool)
    nan = np.full(len(b.points), np.nan)
    sag = PackLoad(
        "sag", "heldout", b.clamped, held, b.forces["sag"], b.answers["sag"], nan, gravity(b)
    )
    tip = PackLoad("tip", "heldout", b.clamped, held, b.forces["tip"], b.answers["tip"], nan)
    return Pack(b.points, {"tetra": b.tets}, E, nu, RHO, (sag, tip), None, {})


def uniform_sag(b: P1.Body, nu: float) -> np.ndarray:
    """P1's answer under gravity on uniform node masses rho V / n (Bullet's)."""
    K, _ = P1.p1_stiffness(P1.beam_mesh(), E, nu)
    f = np.zeros(b.points.shape)
    f[:] = RHO * volume(b) / len(b.points) * gravity(b)
    free = np.ones(b.points.shape, bool)
    free[b.clamped] = False
    d = np.flatnonzero(free.ravel())
    u = np.zeros(f.size)
    u[d] = spla.spsolve(K[d][:, d].tocsc(), f.ravel()[d])
    return u.reshape(-1, 3)


def run(nu: float) -> dict:
    from harness.engines import adapter

    return adapter("pybullet-fem")(pack_of(body(nu), nu))


def error(u: np.ndarray, truth: np.ndarray) -> float:
    return float(np.linalg.norm(u - truth) / np.linalg.norm(truth))


@pytest.fixture(autouse=True)
def capped(monkeypatch):
    """settle stops at 2,000 steps (the good runs settle in 100: a broken one ends fast)."""
    from harness.engines import pybullet_fem, settle

    monkeypatch.setattr(pybullet_fem, "settle", functools.partial(settle.settle, max_steps=2000))


@pytest.mark.parametrize("nu", (0.3, 0.45))
def test_sag_is_p1_with_uniform_masses_and_a_traction_unsupported(nu):
    answers = run(nu)
    sag, tip = answers["sag"], answers["tip"]
    assert sag.status == "settled", sag.note
    assert error(sag.u, uniform_sag(body(nu), nu)) <= TOL
    assert error(sag.u, body(nu).answers["sag"]) > 10 * TOL  # the lumped masses' P1: not it
    assert "uniform" in sag.note and "kg" in sag.note
    assert tip.status == "unsupported-load" and "gravity loads only" in tip.note
    assert np.isnan(tip.u).all()


def test_gravity_ignored_is_not_settled(monkeypatch):
    from harness.engines import pybullet_fem

    load = pybullet_fem.PybulletSim.load

    def no_gravity(self, ld):
        load(self, ld)
        self.g = np.zeros(3)

    monkeypatch.setattr(pybullet_fem.PybulletSim, "load", no_gravity)
    sag = run(0.3)["sag"]
    assert sag.status != "settled"


def test_raw_lame_constants_miss_the_p1_answer(monkeypatch):
    from harness.case.elasticity import lame
    from harness.engines import pybullet_fem

    monkeypatch.setattr(pybullet_fem, "neo_hookean", lambda E, nu: lame(E, nu)[::-1])
    sag = run(0.3)["sag"]
    assert error(sag.u, uniform_sag(body(0.3), 0.3)) > 10 * TOL
