"""mujoco-springs against a spring network's linear statics solved here: one spring per edge
of a small tet beam, each its own stiffness (0.5-1.5 of E times its edges' volume share over
its squared length) and rest length, lumped masses; K of the springs at rest assembled here
and K u = f solved with the held components fixed. Loads: a sag and a tip force with the
clamp held, and the sag on minimal holds (partly held nodes), each sized for a largest
spring strain of PEAK, so the tendons' geometric nonlinearity is O(PEAK) of the answer. An
adapter that ignores or doubles the stiffness, drops the forces or misreads the rest lengths
fails the check; an export with a volume or kn term is refused."""

from __future__ import annotations

import dataclasses
import functools
import json

import numpy as np
import pytest

from harness.errors import SpringbenchError
from harness.export.pack import Pack, PackLoad
from tests.independent import p1_bodies as P1

pytest.importorskip("mujoco")
E, NU, RHO = 1e5, 0.3, 1000.0
PEAK = 1e-4  # the largest spring strain of every load's linear answer
# relative error allowed: 2.4-3.2e-4 measured, the tendons' geometric nonlinearity (2.1-2.8
# PEAK settled to rtol 1e-8, linear in the load from PEAK 1e-5 to 1e-3) and settle's stop
TOL = 1e-3
MAX_STEPS = 20_000  # the good runs settle in 2,200-2,400 steps; a broken one stops here


@functools.cache
def mesh() -> tuple[np.ndarray, np.ndarray]:
    """(points, tets) of a small tet beam: 45 nodes, 96 tets, 180 edges."""
    m = P1.beam_mesh(length=0.2, side=0.04, n=(4, 2, 2))
    return m.p.T.copy(), m.t.T.copy()


@functools.cache
def network() -> tuple[np.ndarray, dict]:
    """(points, MODEL.json keys) of the spring network of the module docstring."""
    points, tets = mesh()
    pairs = np.array([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)])
    vol = np.abs(np.linalg.det(points[tets[:, 1:]] - points[tets[:, :1]])) / 6
    edges, inv = np.unique(
        np.sort(tets[:, pairs].reshape(-1, 2), axis=1), axis=0, return_inverse=True
    )
    share = np.bincount(inv.ravel(), np.repeat(vol / 6, 6), len(edges))
    rest = np.linalg.norm(points[edges[:, 1]] - points[edges[:, 0]], axis=1)
    k = E * share / rest**2 * (0.5 + np.random.default_rng(1).random(len(edges)))
    masses = np.bincount(tets.ravel(), np.repeat(RHO * vol / 4, 4), len(points))
    mu = masses[edges[:, 0]] * masses[edges[:, 1]] / masses[edges].sum(axis=1)
    data = {
        "particle_q": points.tolist(),
        "particle_mass": masses.tolist(),
        "spring_indices": edges.tolist(),
        "spring_rest_length": rest.tolist(),
        "spring_stiffness": k.tolist(),
        "spring_damping": (0.02 * np.sqrt(k * mu)).tolist(),
    }
    K = stiffness(points, edges, k)
    s = 1.0 / np.sqrt(np.repeat(masses, 3))
    # half the explicit limit 2 / omega_max: a network with doubled springs still takes it
    data["dt_safe"] = 0.5 * 2.0 / np.sqrt(np.linalg.eigvalsh(K * s[:, None] * s[None, :])[-1])
    return points, data


def stiffness(points, edges, k) -> np.ndarray:
    """K (node-major dofs) of linear springs at rest: k d d^T / |d|^2 per spring."""
    K = np.zeros((points.size, points.size))
    for (i, j), ke in zip(edges, k):
        d = points[j] - points[i]
        b = ke * np.outer(d, d) / (d @ d)
        for a, c, sign in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
            K[3 * a : 3 * a + 3, 3 * c : 3 * c + 3] += sign * b
    return K


def holds(points, minimal: bool) -> tuple[np.ndarray, np.ndarray]:
    """The clamp x = 0 in every component, or minimal holds: the clamp's x, one node in
    every component, another in x and y (no rigid motion left)."""
    nodes = np.flatnonzero(points[:, 0] < 1e-12)
    held = np.ones((len(nodes), 3), bool)
    if minimal:
        held[:, 1:] = False
        a = nodes[np.argmin(points[nodes, 1] + points[nodes, 2])]
        b = nodes[np.argmin(points[nodes, 1] - points[nodes, 2])]
        held[nodes == a] = True
        held[nodes == b, 1] = True
    return nodes, held


def linear_answer(points, data, nodes, held, f) -> np.ndarray:
    """u of K u = f with the held components fixed (dense solve)."""
    K = stiffness(points, np.asarray(data["spring_indices"]), np.asarray(data["spring_stiffness"]))
    free = np.ones(points.shape, bool)
    free[nodes] = ~held
    d = np.flatnonzero(free.ravel())
    u = np.zeros(points.size)
    u[d] = np.linalg.solve(K[np.ix_(d, d)], f.ravel()[d])
    return u.reshape(-1, 3)


def strain(points, edges, u) -> float:
    d = points[edges[:, 1]] - points[edges[:, 0]]
    du = u[edges[:, 1]] - u[edges[:, 0]]
    return float(np.abs(np.sum(d * du, axis=1) / np.sum(d * d, axis=1)).max())


@functools.cache
def pack(peak: float = PEAK) -> Pack:
    """The network's body with its three loads, each answer the linear one solved here,
    sized for a largest spring strain of ``peak``."""
    points, data = network()
    masses, edges = np.asarray(data["particle_mass"]), np.asarray(data["spring_indices"])
    sag = np.zeros(points.shape)
    sag[:, 2] = -9.81 * masses
    tip = np.zeros(points.shape)
    tip[points[:, 0] > points[:, 0].max() - 1e-12, 1] = -1.0
    loads = []
    for name, f, minimal in (("sag", sag, False), ("tip", tip, False), ("roller", sag, True)):
        nodes, held = holds(points, minimal)
        u = linear_answer(points, data, nodes, held, f)
        s = peak / strain(points, edges, u)
        nan = np.full(len(points), np.nan)
        loads.append(PackLoad(name, "heldout", nodes, held, s * f, s * u, nan))
    return Pack(points, {"tetra": mesh()[1]}, E, NU, RHO, tuple(loads), None, {})


def run(tmp_path, data=None, peak=PEAK, loads=None) -> dict:
    """{load: Answer} of mujoco-springs on the network's JSON (or ``data``)."""
    from harness.engines import adapter

    path = tmp_path / "model.json"
    path.write_text(json.dumps(data or network()[1]))
    p = pack(peak)
    if loads is not None:
        p = dataclasses.replace(p, loads=tuple(p.load(n) for n in loads))
    return adapter("mujoco-springs")(p, {"model": path})


def error(u, truth) -> float:
    return float(np.linalg.norm(u - truth) / np.linalg.norm(truth))


def check(answers: dict):
    """Every load settled within TOL of the linear answer solved here."""
    for ld in pack().loads:
        if ld.name in answers:
            a = answers[ld.name]
            assert a.status == "settled", (ld.name, a.status, a.note)
            assert error(a.u, ld.u_fem) <= TOL, (ld.name, error(a.u, ld.u_fem))


@pytest.fixture(autouse=True)
def capped(monkeypatch):
    """settle stops at MAX_STEPS (a broken run ends in seconds)."""
    from harness.engines import mujoco_springs, settle

    monkeypatch.setattr(
        mujoco_springs, "settle", functools.partial(settle.settle, max_steps=MAX_STEPS)
    )


def test_each_load_settles_at_the_linear_answer_solved_here(tmp_path):
    answers = run(tmp_path)
    check(answers)
    for ld in pack().loads:  # a held component has no joint: it stays at rest exactly
        assert np.all(answers[ld.name].u[ld.held_nodes][ld.held_components] == 0.0), ld.name


def test_the_departure_from_linear_is_the_geometric_nonlinearity(monkeypatch, tmp_path):
    """Settled to 1e-8 (settle's rtol) the error is linear in the load (2.78e-4 at PEAK,
    2.78e-5 at PEAK / 10 measured): the tendons' large-displacement statics, no misfit."""
    from harness.engines import mujoco_springs, settle

    tight = functools.partial(settle.settle, max_steps=MAX_STEPS, rtol=1e-8)
    monkeypatch.setattr(mujoco_springs, "settle", tight)
    e = [
        error(run(tmp_path, peak=peak, loads=("tip",))["tip"].u, pack(peak).load("tip").u_fem)
        for peak in (PEAK, PEAK / 10)
    ]
    assert 8 < e[0] / e[1] < 12, e


def _springs(change):
    """springs_of with its (pairs, k, rest, kd) passed through ``change`` first."""
    from harness.engines import mujoco_springs

    springs_of = mujoco_springs.springs_of
    return lambda data: change(*springs_of(data))


def _shuffled(pairs, k, rest, kd):
    return pairs, k, np.random.default_rng(0).permutation(rest), kd


BROKEN = {
    "stiffness ignored (uniform)": lambda p, k, r, d: (p, np.full_like(k, k.mean()), r, d),
    "stiffness doubled": lambda p, k, r, d: (p, 2 * k, r, d),
    "rest lengths shuffled": _shuffled,
    "rest lengths 1 % long": lambda p, k, r, d: (p, k, 1.01 * r, d),
}


@pytest.mark.parametrize("variant", [*BROKEN, "forces ignored"])
def test_a_broken_adapter_fails_the_check(monkeypatch, tmp_path, variant):
    import mujoco

    from harness.engines import mujoco_springs

    if variant == "forces ignored":
        load = mujoco_springs.MujocoSpringsSim.load

        def no_forces(self, ld):
            load(self, ld)
            self.d.xfrc_applied[:] = 0.0

        monkeypatch.setattr(mujoco_springs.MujocoSpringsSim, "load", no_forces)
    else:
        monkeypatch.setattr(mujoco_springs, "springs_of", _springs(BROKEN[variant]))
    previous, seen = mujoco.get_mju_user_warning(), []
    mujoco.set_mju_user_warning(seen.append)
    try:
        answers = run(tmp_path, loads=("sag",))
    finally:
        mujoco.set_mju_user_warning(previous)
    with pytest.raises(AssertionError):
        check(answers)


def test_each_body_carries_its_particles_mass_and_a_joint_per_free_component():
    """MuJoCo's mass matrix (mj_fullM) is diagonal with the JSON's particle_mass on each
    joint of the particle's body; a load's held components have none."""
    import mujoco

    from harness.engines.mujoco_springs import MujocoSpringsSim, springs_of

    points, data = network()
    masses = np.asarray(data["particle_mass"])
    sim = MujocoSpringsSim(points, masses, springs_of(data), 1e-4)
    ld = pack().load("roller")
    sim.load(ld)
    mujoco.mj_forward(sim.m, sim.d)
    full = np.zeros((sim.m.nv, sim.m.nv))
    mujoco.mj_fullM(sim.m, sim.d, full)
    assert np.array_equal(full, np.diag(np.diag(full)))
    assert np.allclose(np.diag(full)[sim.dof], masses[sim.node], rtol=1e-12)
    assert sim.m.nv == points.size - ld.held_components.sum()
    assert sim.m.ntendon == len(data["spring_indices"])


@pytest.mark.parametrize("key", ["volume_indices", "node_volume_elements", "kn_nodes"])
def test_an_export_with_a_volume_or_kn_term_is_refused(tmp_path, key):
    data = {**network()[1], key: [[0, 1, 2, 3]]}
    with pytest.raises(SpringbenchError, match="springs only") as err:
        run(tmp_path, data=data, loads=("sag",))
    assert err.value.field == key and "--model springs" in err.value.fix


def test_an_export_of_another_mesh_is_refused(tmp_path):
    data = network()[1]
    data = {**data, "particle_q": (np.asarray(data["particle_q"]) * 1e3).tolist()}
    with pytest.raises(SpringbenchError, match="not the pack's"):
        run(tmp_path, data=data, loads=("sag",))


def test_engines_run_takes_the_model_and_score_passes_it(tmp_path, capsys):
    """``springbench engines run mujoco-springs DIR --model M.json`` writes the answers and
    ``score`` gates them at G_norm 1e-3 against the linear answers in the pack."""
    from harness import cli
    from harness.export.pack import write_pack

    write_pack(pack(), tmp_path / "p")
    model, u = tmp_path / "m.json", tmp_path / "u.npz"
    model.write_text(json.dumps(network()[1]))
    argv = ["engines", "run", "mujoco-springs", tmp_path / "p", "--model", model, "--out", u]
    assert cli.main([str(a) for a in argv]) == 0
    score = ["score", "--displacements", u, tmp_path / "p", "--max-g-norm", "1e-3"]
    assert cli.main([str(a) for a in score]) == 0
    assert cli.main([str(a) for a in score[:-1] + ["1e-5"]]) == 1  # the gate is not vacuous
