"""drake-fem against a P1 FEM solved here: Drake's kLinear tetrahedra are P1 and its
gravity gives each node its lumped mass times g, so its sag is the P1 answer of the
pack's own forces: measured 4.5e-7 (nu 0.3) and 4.1e-7 (nu 0.45) on a 63-node beam with
the clamp a wall condition, 3.3e-4 (nu 0.3) with a clamp that takes SAP's (compliant)
fixed constraints. Its net force, estimated from its motion with its one-point mass
matrix, is the P1 residual f - K u mid-run (1.2e-10; 0.11 with lumped masses). A traction
is unsupported; an adapter that drops gravity (not settled), scales E by 1000 (0.999 off)
or leaves nu at Drake's default 0.49 (0.66 off) fails."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from harness.export.pack import Pack, PackLoad
from tests.independent import p1_bodies as P1

pytest.importorskip("pydrake")
E, RHO = 1e5, 1000.0
TOL_WALL = 1e-5  # a clamp Drake holds exactly (4.5e-7 measured)
TOL_FIXED = 1e-3  # a clamp held by SAP's fixed constraints (3.3e-4 measured)


@functools.cache
def body(nu: float) -> P1.Body:
    return P1.body("beam", P1.beam_mesh(), E, nu, RHO)


def gravity(b: P1.Body) -> np.ndarray:
    """The sag's gravity (m/s^2): its forces are rho g times each node's share of volume."""
    e = b.points[b.tets[:, 1:]] - b.points[b.tets[:, :1]]
    volume = float(np.abs(np.linalg.det(e)).sum() / 6.0)
    return np.array([0.0, 0.0, b.forces["sag"][:, 2].sum() / (RHO * volume)])


def p1_answer(b: P1.Body, nu: float, held: np.ndarray, f: np.ndarray) -> np.ndarray:
    """P1's displacement under nodal forces ``f`` with the ``held`` nodes fixed."""
    K, _ = P1.p1_stiffness(P1.beam_mesh(), E, nu)
    free = np.ones(b.points.shape, bool)
    free[held] = False
    d = np.flatnonzero(free.ravel())
    u = np.zeros(f.size)
    u[d] = spla.spsolve(K[d][:, d].tocsc(), f.ravel()[d])
    return u.reshape(-1, 3)


def pack_of(b: P1.Body, nu: float, clamp=None) -> Pack:
    """The sag (and a traction) with the body's clamp, or ``clamp`` and the P1 answer of it."""
    held = b.clamped if clamp is None else clamp
    full = np.ones((len(held), 3), bool)
    nan = np.full(len(b.points), np.nan)
    f = b.forces["sag"]
    u = b.answers["sag"] if clamp is None else p1_answer(b, nu, held, f)
    sag = PackLoad("sag", "heldout", held, full, f, u, nan, gravity(b))
    tip = PackLoad("tip", "heldout", held, full, b.forces["tip"], u, nan)
    return Pack(b.points, {"tetra": b.tets}, E, nu, RHO, (sag, tip), None, {})


def lower_clamp(b: P1.Body) -> np.ndarray:
    """The clamp's nodes below the beam's mid-height: no coordinate plane separates them."""
    z = b.points[b.clamped, 2]
    return b.clamped[z <= 0.5 * (z.min() + z.max()) + 1e-12]


def run(pack: Pack) -> dict:
    from harness.engines import adapter

    return adapter("drake-fem")(pack)


def error(u: np.ndarray, truth: np.ndarray) -> float:
    return float(np.linalg.norm(u - truth) / np.linalg.norm(truth))


@pytest.fixture(autouse=True)
def capped(monkeypatch):
    """settle stops at 2,000 steps (the good runs settle in 60: a broken one ends fast)."""
    from harness.engines import drake_fem, settle

    monkeypatch.setattr(drake_fem, "settle", functools.partial(settle.settle, max_steps=2000))


@pytest.mark.parametrize("nu", (0.3, 0.45))
def test_sag_is_p1_and_a_traction_unsupported(nu):
    answers = run(pack_of(body(nu), nu))
    sag, tip = answers["sag"], answers["tip"]
    assert sag.status == "settled", sag.note
    assert error(sag.u, body(nu).answers["sag"]) <= TOL_WALL
    assert "wall condition" in sag.note
    assert tip.status == "unsupported-load" and "gravity loads only" in tip.note
    assert np.isnan(tip.u).all()


def test_a_clamp_no_plane_separates_is_held_by_fixed_constraints():
    from harness.engines.drake_fem import wall_of

    b = body(0.3)
    clamp = lower_clamp(b)
    assert wall_of(b.points, b.clamped) is not None and wall_of(b.points, clamp) is None
    pack = pack_of(b, 0.3, clamp)
    sag = run(pack)["sag"]
    assert sag.status == "settled", sag.note
    assert "fixed constraints" in sag.note
    assert error(sag.u, pack.loads[0].u_fem) <= TOL_FIXED
    assert error(sag.u, b.answers["sag"]) > 10 * TOL_FIXED  # the other clamp's answer: not it


def _mid_run(mass=None):
    """(measured net force, P1's f - K u at the same state, free rows) after 3 steps."""
    from harness.engines import drake_fem
    from harness.models.masses import lumped_masses

    b = body(0.3)
    pack = pack_of(b, 0.3)
    tets = drake_fem.positive(b.points, b.tets)
    M = drake_fem.drake_mass(b.points, tets, RHO) if mass is None else mass
    sim = drake_fem.DrakeSim(pack, tets, 0.01, M)
    sim.load(pack.loads[0])
    sim.set_damping(0.9)
    sim.advance(3)
    u, _, f = sim.measure()
    K, _ = P1.p1_stiffness(P1.beam_mesh(), E, 0.3)
    expected = pack.loads[0].force - (K @ u.ravel()).reshape(u.shape)
    free = np.ones(len(u), bool)
    free[b.clamped] = False
    assert np.allclose(lumped_masses(b.points, tets, RHO), np.asarray(M.sum(axis=1)).ravel())
    return f[free], expected[free]


def test_the_net_force_from_the_motion_is_the_p1_residual():
    f, expected = _mid_run()
    assert error(f, expected) <= 1e-8  # 1.2e-10 measured
    assert np.linalg.norm(expected) > 0.5 * np.linalg.norm(body(0.3).forces["sag"])


def test_a_lumped_mass_matrix_misreads_the_net_force():
    import scipy.sparse as sp

    from harness.models.masses import lumped_masses

    b = body(0.3)
    f, expected = _mid_run(sp.diags(lumped_masses(b.points, b.tets, RHO)).tocsr())
    assert error(f, expected) > 1e-2


def _broken_config(monkeypatch, change):
    from harness.engines import drake_fem

    config = drake_fem.DrakeSim._config

    def broken(self):
        c = config(self)
        change(self, c)
        return c

    monkeypatch.setattr(drake_fem.DrakeSim, "_config", broken)


def test_gravity_ignored_is_not_settled(monkeypatch):
    from harness.engines import drake_fem

    load = drake_fem.DrakeSim.load

    def no_gravity(self, ld):
        load(self, ld)
        self.g = np.zeros(3)

    monkeypatch.setattr(drake_fem.DrakeSim, "load", no_gravity)
    assert run(pack_of(body(0.3), 0.3))["sag"].status != "settled"


def test_a_stiffer_material_misses_the_p1_answer(monkeypatch):
    _broken_config(monkeypatch, lambda sim, c: c.set_youngs_modulus(1000 * sim.pack.E))
    sag = run(pack_of(body(0.3), 0.3))["sag"]
    assert error(sag.u, body(0.3).answers["sag"]) > 0.5


def test_drakes_default_poisson_ratio_misses_the_p1_answer(monkeypatch):
    from pydrake.multibody.fem import DeformableBodyConfig

    default = DeformableBodyConfig().poissons_ratio()
    _broken_config(monkeypatch, lambda sim, c: c.set_poissons_ratio(default))
    sag = run(pack_of(body(0.3), 0.3))["sag"]
    assert error(sag.u, body(0.3).answers["sag"]) > 100 * TOL_WALL


def test_a_wheel_that_crashes_on_vtk_is_refused_not_run(monkeypatch):
    import importlib.metadata

    monkeypatch.setattr(importlib.metadata, "version", lambda name: "1.51.0")
    answers = run(pack_of(body(0.3), 0.3))
    assert {a.status for a in answers.values()} == {"unsupported"}
    assert all("1.51.1" in a.note for a in answers.values())
