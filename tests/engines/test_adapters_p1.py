"""Every engine adapter against answers solved here, and every adapter broken on purpose
failing that check.

newton-tets and mujoco-flex run the P1 (linear tetrahedra) model of the body, linearised
at rest (Newton's stable Neo-Hookean with k_mu = 4/3 mu, k_lambda = lambda + 5/6 mu;
MuJoCo's flex elasticity): their equilibrium is the linear P1 FEM of tests/independent/
p1_bodies.py (scikit-fem, solved in the test) to O(peak strain). newton-springs runs a
spring network written here (one spring per edge): its equilibrium is the network's
linear statics, assembled here (a spring network is not P1 at nu != 1/4). Two bodies (a
box beam and a tapered, twisted one), nu 0.3 and 0.45, gravity sag and a tip traction.
An adapter that ignores the forces, maps the material wrongly or scales it by 1000 fails."""

from __future__ import annotations

import dataclasses
import functools
import json
import math

import numpy as np
import pytest

from harness.export.pack import Pack, PackLoad
from tests.independent import p1_bodies as P1

pytest.importorskip("newton")
pytest.importorskip("mujoco")
E, RHO = 1e5, 1000.0
NUS = (0.3, 0.45)
BODIES = {"beam": P1.beam_mesh, "taper": P1.taper_mesh}
MAX_STEPS = 10_000  # the good runs here settle in at most 5,400 steps; a broken one stops here


@functools.cache
def body(shape: str, nu: float) -> P1.Body:
    return P1.body(shape, BODIES[shape](), E, nu, RHO)


def pack_of(b: P1.Body, nu: float, loads=("sag", "tip")) -> Pack:
    """The body as a benchmark pack (the P1 answer where the pack's FEM answer goes)."""
    held = np.ones((len(b.clamped), 3), bool)
    nan = np.full(len(b.points), np.nan)
    lds = tuple(
        PackLoad(n, "heldout", b.clamped, held, b.forces[n], b.answers[n], nan) for n in loads
    )
    return Pack(b.points, {"tetra": b.tets}, E, nu, RHO, lds, None, {"peak_strain": P1.PEAK})


def spring_network(b: P1.Body, nu: float) -> tuple[dict, object]:
    """(MODEL.json keys, K) of one spring per mesh edge, k = E / (1 + nu) times the volume
    of the tetrahedra around the edge over its squared length: the JSON newton-springs
    reads and the network's linear stiffness (node-major dofs)."""
    import scipy.sparse as sp

    pairs = np.array([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)])
    e = np.sort(b.tets[:, pairs].reshape(-1, 2), axis=1)
    vol = np.abs(np.linalg.det(b.points[b.tets[:, 1:]] - b.points[b.tets[:, :1]])) / 6
    edges, inv = np.unique(e, axis=0, return_inverse=True)
    share = np.bincount(inv.ravel(), np.repeat(vol / 6, 6), len(edges))
    d = b.points[edges[:, 1]] - b.points[edges[:, 0]]
    length2 = np.sum(d * d, axis=1)
    k = E / (1 + nu) * share / length2
    blocks = k[:, None, None] * d[:, :, None] * d[:, None, :] / length2[:, None, None]
    dof = 3 * edges[:, :, None] + np.arange(3)  # (s, 2, 3)
    sign = np.array([1.0, -1.0])
    rows = np.broadcast_to(dof[:, :, None, :, None], (len(k), 2, 2, 3, 3))
    cols = np.broadcast_to(dof[:, None, :, None, :], (len(k), 2, 2, 3, 3))
    vals = (sign[:, None] * sign[None, :])[None, :, :, None, None] * blocks[:, None, None]
    n = 3 * len(b.points)
    K = sp.coo_matrix((vals.ravel(), (rows.ravel(), cols.ravel())), (n, n)).tocsr()
    masses = np.zeros(len(b.points))
    np.add.at(masses, b.tets.ravel(), np.repeat(RHO * vol / 4, 4))
    data = {
        "particle_q": b.points.tolist(),
        "particle_mass": masses.tolist(),
        "spring_indices": edges.tolist(),
        "spring_stiffness": k.tolist(),
        "dt_safe": 0.8 * 2.0 / _omegas(K, masses, np.arange(n))[-1],
        "settle_damping": {"omega_1": _omegas(K, masses, _free(b))[0]},
    }
    return data, K


def _free(b: P1.Body) -> np.ndarray:
    free = np.ones((len(b.points), 3), bool)
    free[b.clamped] = False
    return np.flatnonzero(free.ravel())


def _omegas(K, masses, dofs) -> np.ndarray:
    """The network's angular frequencies (ascending) on ``dofs``, lumped masses."""
    s = 1.0 / np.sqrt(np.repeat(masses, 3)[dofs])
    A = K[dofs][:, dofs].toarray() * s[:, None] * s[None, :]
    return np.sqrt(np.clip(np.linalg.eigvalsh(A), 0.0, None))


def spring_body(b: P1.Body, nu: float) -> tuple[P1.Body, dict]:
    """(the body with the network's own linear statics as its answers, each load scaled so
    that answer's largest strain is PEAK as for P1; the network's MODEL.json keys)."""
    import dataclasses

    import scipy.sparse.linalg as spla

    data, K = spring_network(b, nu)
    free, forces, answers = _free(b), {}, {}
    for name, f in b.forces.items():
        u = np.zeros(f.size)
        u[free] = spla.spsolve(K[free][:, free].tocsc(), f.ravel()[free])
        scale = P1.PEAK / P1.peak_strain(b.points, b.tets, u.reshape(-1, 3))
        forces[name], answers[name] = scale * f, scale * u.reshape(-1, 3)
    return dataclasses.replace(b, forces=forces, answers=answers), data


def run(engine: str, b: P1.Body, nu: float, tmp_path, loads=("sag", "tip")):
    """({load: Answer} of the engine, {load: the answer solved here})."""
    from harness.engines import adapter

    options = None
    if engine == "newton-springs":
        b, data = spring_body(b, nu)
        path = tmp_path / f"{b.name}-{nu}.json"
        path.write_text(json.dumps(data))
        options = {"model": path}
    answers = adapter(engine)(pack_of(b, nu, loads), options)
    return answers, {n: b.answers[n] for n in loads}


def check(answers: dict, truth: dict, engine: str, points: np.ndarray):
    """Every load settled and within 3 peak strains of the answer solved here (the
    nonlinear materials' and springs' departure from linear: 0.7-1.5 of it measured), plus,
    in float32, four position spacings (the stopping rule's resolution)."""
    from harness.engines.settle import float32_resolution

    res = float32_resolution(points) if engine.startswith("newton") else 0.0
    for name, u in truth.items():
        a = answers[name]
        assert a.status == "settled", (engine, name, a.status, a.note)
        rms = math.sqrt(float(np.mean(np.sum(u * u, axis=1))))
        err = float(np.linalg.norm(a.u - u) / np.linalg.norm(u))
        assert err <= 3.0 * P1.PEAK + 4.0 * res / rms, (engine, name, err)


@pytest.fixture(autouse=True)
def capped(monkeypatch):
    """Every adapter's settle stops at MAX_STEPS (a broken run ends in seconds)."""
    from harness.engines import mujoco_flex, newton_engine, settle

    capped = functools.partial(settle.settle, max_steps=MAX_STEPS)
    monkeypatch.setattr(newton_engine, "settle", capped)
    monkeypatch.setattr(mujoco_flex, "settle", capped)


@pytest.mark.parametrize("nu", NUS)
@pytest.mark.parametrize("shape", sorted(BODIES))
@pytest.mark.parametrize("engine", ["newton-tets", "mujoco-flex", "newton-springs"])
def test_each_adapter_settles_at_the_answer_solved_here(engine, shape, nu, tmp_path):
    b = body(shape, nu)
    answers, truth = run(engine, b, nu, tmp_path)
    check(answers, truth, engine, b.points)


def _newton_rows(convert):
    """A NewtonSim whose tetrahedra rows (i, j, k, l, k_mu, k_lambda, damp) and springs
    (i, j, ke, kd) pass through ``convert(kind, row)`` first."""
    from harness.engines.newton_engine import NewtonSim

    init = NewtonSim.__init__

    def patched(self, q, masses, springs=(), tets=(), **kw):
        springs = [convert("spring", r) for r in springs]
        init(self, q, masses, springs=springs, tets=[convert("tet", r) for r in tets], **kw)

    return patched


def _raw_lame(kind, row):
    """Newton's (k_mu, k_lambda) replaced by the Lame (mu, lambda) they were made from."""
    if kind != "tet":
        return row
    *ids, k_mu, k_lambda, damp = row
    mu = 0.75 * k_mu
    return (*ids, mu, k_lambda - 5.0 / 6.0 * mu, damp)


def _times_1000(kind, row):
    """Every stiffness in kPa or kN/mm where Pa or N/m were meant."""
    if kind == "tet":
        *ids, k_mu, k_lambda, damp = row
        return (*ids, 1e3 * k_mu, 1e3 * k_lambda, damp)
    i, j, ke, kd = row
    return (i, j, 1e3 * ke, kd)


def _break(monkeypatch, engine: str, variant: str):
    """Patch the adapter of ``engine`` into the broken ``variant``."""
    from harness.engines import mujoco_flex
    from harness.engines.newton_engine import NewtonSim

    if engine.startswith("newton") and variant in ("forces ignored", "forces in kN"):
        load, scale = NewtonSim.load, 0.0 if variant == "forces ignored" else 1e-3
        monkeypatch.setattr(
            NewtonSim,
            "load",
            lambda self, ld: load(self, dataclasses.replace(ld, force=scale * ld.force)),
        )
    elif engine.startswith("newton"):
        convert = {"raw Lame": _raw_lame, "E x 1000": _times_1000}[variant]
        monkeypatch.setattr(NewtonSim, "__init__", _newton_rows(convert))
    elif variant == "forces ignored":
        load = mujoco_flex.MujocoSim.load

        def no_forces(self, ld):
            load(self, ld)
            self.d.xfrc_applied[:] = 0.0

        monkeypatch.setattr(mujoco_flex.MujocoSim, "load", no_forces)
    else:
        xml = mujoco_flex._xml
        scale = {"young = shear modulus": lambda E, nu: E / (2 * (1 + nu)), "E x 1000": None}
        young = scale[variant] or (lambda E, nu: 1e3 * E)
        monkeypatch.setattr(
            mujoco_flex, "_xml", lambda p, t, h, E, nu: xml(p, t, h, young(E, nu), nu)
        )


@pytest.mark.parametrize(
    "engine, variant",
    [
        ("newton-tets", "forces ignored"),
        ("newton-tets", "raw Lame"),
        ("newton-tets", "E x 1000"),
        ("newton-tets", "forces in kN"),
        ("newton-springs", "forces ignored"),
        ("newton-springs", "E x 1000"),
        ("mujoco-flex", "forces ignored"),
        ("mujoco-flex", "young = shear modulus"),
        ("mujoco-flex", "E x 1000"),
    ],
)
def test_a_broken_adapter_fails_the_check(monkeypatch, tmp_path, engine, variant):
    import mujoco

    b, nu = body("beam", 0.3), 0.3
    _break(monkeypatch, engine, variant)
    previous, seen = mujoco.get_mju_user_warning(), []
    mujoco.set_mju_user_warning(seen.append)  # else MuJoCo logs the unstable steps in the cwd
    try:
        answers, truth = run(engine, b, nu, tmp_path, loads=("sag",))
    finally:
        mujoco.set_mju_user_warning(previous)
    with pytest.raises(AssertionError):
        check(answers, truth, engine, b.points)


@pytest.mark.parametrize("engine", ["newton-tets", "mujoco-flex"])
def test_a_load_settles_the_same_alone_or_with_others(engine, tmp_path):
    """The damping and the stopping rule of a load depend on that load only: ``engines run
    --loads`` gives each load the same answer, bit for bit, whatever else runs."""
    b = body("taper", 0.45)
    both, _ = run(engine, b, 0.45, tmp_path, loads=("sag", "tip"))
    for name in ("sag", "tip"):
        alone = run(engine, b, 0.45, tmp_path, loads=(name,))[0][name]
        assert alone.steps == both[name].steps and np.array_equal(alone.u, both[name].u), name


def test_mujoco_vertices_carry_the_lumped_masses():
    """MuJoCo's mass matrix (mj_fullM) is diagonal with rho V / 4 per vertex, summed here
    from the tetrahedra's volumes: the masses the damping and omega_1 are computed for."""
    import mujoco

    from harness.engines.mujoco_flex import MujocoSim

    b = body("taper", 0.3)
    pack = pack_of(b, 0.3, loads=("sag",))
    vol = np.abs(np.linalg.det(b.points[b.tets[:, 1:]] - b.points[b.tets[:, :1]])) / 6
    masses = np.bincount(b.tets.ravel(), np.repeat(RHO * vol / 4, 4), len(b.points))
    sim = MujocoSim(pack, b.tets, masses, 1e-4)
    sim.load(pack.load("sag"))
    mujoco.mj_forward(sim.m, sim.d)
    full = np.zeros((sim.m.nv, sim.m.nv))
    mujoco.mj_fullM(sim.m, sim.d, full)
    assert np.array_equal(full, np.diag(np.diag(full)))
    want = np.repeat(masses[sim.free_nodes], 3)
    assert np.allclose(np.diag(full)[sim.dof.ravel()], want, rtol=1e-12)
