"""Engine adapters (harness/engines/) against answers computed here: Newton's and MuJoCo's
tetrahedra against a linear P1 FEM of the same mesh solved with scikit-fem in the test
(at the pack's small strains their nonlinear materials are that to ~1e-3), and against the
pack's P2 FEM on two meshes (the error falls with the mesh size); a springbench export run
in Newton at its dt_safe with its settle_damping against springbench's own linear statics
(<= 1e-3; the twist differs by its geometric nonlinearity, halved with the load); the
stopping rule on a one-mass oscillator; one command per engine from a pack to a score; one
line for a missing engine."""

import json

import numpy as np
import pytest

from harness import cli
from harness.export.pack import read_pack
from tests import meshes
from tests.pack_solve import held_solve

pytest.importorskip("gmsh")
E, NU, RHO = 1e5, 0.3, 1000.0
LOADS = ("tip", "sag", "torsion", "bend-xy")


def pack_of(folder, size):
    mesh = meshes.cylinder(folder, size=size, name=f"cyl{size}.vtu")
    out = folder / f"pack{size}"
    assert (
        cli.main(
            (
                ["pack", str(mesh), "--E", str(E), "--nu", str(NU), "--loads", "all"]
                + ["--density", str(RHO), "--out", str(out)]
            )
        )
        == 0
    )
    return mesh, out, read_pack(out)


@pytest.fixture(scope="module")
def packs(tmp_path_factory):
    d = tmp_path_factory.mktemp("engines")
    return d, {size: pack_of(d, size) for size in (0.06, 0.04)}


def p1_answer(pack, load):
    """The linear P1 FEM of the pack's mesh under the pack's load (scikit-fem, here)."""
    import skfem
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    tets = pack.cells["tetra"]
    basis = skfem.Basis(
        skfem.MeshTet(pack.points.T.copy(), tets.T.copy()),
        skfem.ElementVector(skfem.ElementTetP1()),
    )
    K = skfem.asm(linear_elasticity(*lame_parameters(pack.E, pack.nu)), basis).tocsr()
    return held_solve(K, load, pack.points.shape)


def rel(a, b):
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


@pytest.mark.slow
@pytest.mark.parametrize("engine", ["newton-tets", "mujoco-flex"])
def test_continuum_engines_are_p1_fem_and_converge_to_the_fem(packs, engine):
    pytest.importorskip("newton" if engine.startswith("newton") else "mujoco")
    from harness.engines import adapter
    from harness.engines.settle import float32_resolution
    from harness.export.pack import Pack

    folder, by_size = packs
    errors = {}
    for size, (_, _, pack) in by_size.items():
        sub = Pack(
            pack.points,
            pack.cells,
            pack.E,
            pack.nu,
            pack.density,
            tuple(pack.load(n) for n in LOADS),
            pack.plane,
            pack.meta,
        )
        answers = adapter(engine)(sub)
        # a nonlinear material departs from its linearisation by O(strain); float32 positions
        # (Newton) resolve a displacement to their spacing, and the stopping rule allows 4 of it
        res = float32_resolution(pack.points) if engine.startswith("newton") else 0.0
        for name in LOADS:
            a = answers[name]
            assert a.status == "settled", (size, name, a)
            u = p1_answer(pack, pack.load(name))
            tol = 6.0 * pack.meta["peak_strain"] + 4.0 * res / np.sqrt(
                np.mean(np.sum(u * u, axis=1))
            )
            assert rel(a.u, u) <= tol, (size, name)  # the engine is a P1 FEM, linearised
        errors[size] = np.mean([rel(answers[n].u, pack.load(n).u_fem) for n in LOADS])
    assert errors[0.04] < 0.8 * errors[0.06], errors  # and converges towards the FEM


@pytest.mark.slow
def test_newton_runs_a_springbench_export_to_its_linear_statics(packs, tmp_path):
    pytest.importorskip("newton")
    from harness.engines import adapter
    from harness.export.pack import Pack, PackLoad
    from harness.export.vtu import read_vtu

    folder, by_size = packs
    mesh, out, pack = by_size[0.06]
    assert (
        cli.main(
            (
                ["calibrate", str(mesh), "--E", str(E), "--nu", str(NU)]
                + ["--density", str(RHO), "--method", "rule"]
                + ["--out", str(tmp_path / "m.vtu")]
            )
        )
        == 0
    )
    data = json.loads((tmp_path / "m.json").read_text())
    assert (
        0 < data["dt_safe"] < data["dt_stable"]
        and 0 < data["settle_damping"]["velocity_factor"] < 1
    )
    net, _ = read_vtu(tmp_path / "m.vtu")
    from harness.models.springs import incidence, stiffness_matrix

    K = stiffness_matrix(incidence(net.points, net.springs), net.k).tocsr()
    sub = Pack(
        pack.points,
        pack.cells,
        pack.E,
        pack.nu,
        pack.density,
        tuple(pack.load(n) for n in LOADS),
        pack.plane,
        pack.meta,
    )
    answers = adapter("newton-springs")(sub, {"model": tmp_path / "m.json"})
    twist = pack.load("torsion")
    half = PackLoad(
        "torsion",
        twist.role,
        twist.held_nodes,
        twist.held_components,
        0.5 * twist.force,
        0.5 * twist.u_fem,
        twist.u_fem_error,
        twist.gravity,
        twist.kind,
    )
    halved = adapter("newton-springs")(
        Pack(
            pack.points, pack.cells, pack.E, pack.nu, pack.density, (half,), pack.plane, pack.meta
        ),
        {"model": tmp_path / "m.json"},
    )["torsion"]
    errors = {}
    for ld in [pack.load(n) for n in LOADS] + [half]:
        u = held_solve(K, ld, pack.points.shape)
        a = halved if ld is half else answers[ld.name]
        assert a.status == "settled", (ld.name, a)
        assert a.steps <= 20_000  # seconds, not hours
        errors[ld.name if ld is not half else "half"] = rel(a.u, u)
    # Newton's springs are the geometrically exact ones: the twist turns the free end by ~5e-3
    # rad, and the linear statics misses O(rotation); halving the twist halves the difference
    assert all(errors[n] <= 1e-3 for n in LOADS if n != "torsion"), errors
    assert (
        0.4 <= errors["half"] / errors["torsion"] <= 0.6
        and errors["torsion"] <= 6 * pack.meta["peak_strain"]
    ), errors


@pytest.mark.slow
def test_newton_runs_a_volume_term_per_node_to_its_linear_statics(packs, tmp_path):
    """An export with one volume term per node (calibrate --model springs+node-volume-node)
    at nu = 0.45: Newton has no such term, the adapter adds its forces by Warp kernels; its
    equilibrium is the export's linear statics (K from the JSON's keys as written in
    harness/bench/heldout_judge.py) to <= 1e-3, and the term matters (the springs alone differ)."""
    pytest.importorskip("newton")
    from harness.bench.heldout_judge import network_stiffness
    from harness.engines import adapter
    from harness.export.pack import Pack

    _, by_size = packs
    mesh, _, pack = by_size[0.06]
    assert (
        cli.main(
            (
                ["calibrate", str(mesh), "--E", str(E), "--nu", "0.45"]
                + ["--density", str(RHO), "--method", "rule"]
                + ["--model", "springs+node-volume-node", "--quiet"]
                + ["--out", str(tmp_path / "m.vtu")]
            )
        )
        == 0
    )
    data = json.loads((tmp_path / "m.json").read_text())
    assert (
        len(data["node_volume_nodes"]) == len(pack.points)
        and min(data["node_volume_stiffness"]) > 0
    )
    K = network_stiffness(data).tocsr()
    springs = network_stiffness(
        {k: v for k, v in data.items() if not k.startswith("node_volume")}
    ).tocsr()
    names = ("tip", "sag", "bend-xy")
    sub = Pack(
        pack.points,
        pack.cells,
        pack.E,
        pack.nu,
        pack.density,
        tuple(pack.load(n) for n in names),
        pack.plane,
        pack.meta,
    )
    answers = adapter("newton-springs")(sub, {"model": tmp_path / "m.json"})
    for name in names:
        u = held_solve(K, pack.load(name), pack.points.shape)
        assert answers[name].status == "settled", (name, answers[name])
        # the term matters
        assert rel(held_solve(springs, pack.load(name), pack.points.shape), u) > 0.05, name
        assert rel(answers[name].u, u) <= 1e-3, name


@pytest.mark.slow
@pytest.mark.parametrize(
    "engine", ["newton-tets", "mujoco-flex", "newton-springs", "mujoco-springs", "pybullet-fem"]
)
def test_one_command_per_engine_from_pack_to_score(packs, tmp_path, capsys, engine):
    """From a pack of a gmsh mesh no other test shares, one command runs the engine and one
    scores it; the gate exits 0 above the engine's error and 1 below it (and at 1e-9); the
    JUnit file parses and holds one test case per load. PyBullet takes gravity loads only."""
    from xml.etree import ElementTree

    from harness.registry import ENGINES

    pytest.importorskip(ENGINES.about[engine][0])
    folder, by_size = packs
    mesh, out, _ = by_size[0.06]
    loads = "sag,bridge" if engine == "pybullet-fem" else "tip,sag"
    extra = []
    if engine in ("newton-springs", "mujoco-springs"):  # the rule's export: springs alone
        assert (
            cli.main(
                (
                    ["calibrate", str(mesh), "--E", str(E), "--nu", str(NU)]
                    + ["--density", str(RHO), "--method", "rule", "--max-refine", "0"]
                    + ["--out", str(tmp_path / "m.vtu")]
                )
            )
            == 0
        )
        extra = ["--model", str(tmp_path / "m.json")]
    u, table, report = tmp_path / "u.npz", tmp_path / "g.csv", tmp_path / "junit.xml"
    assert (
        cli.main(["engines", "run", engine, str(out), "--loads", loads, "--out", str(u), *extra])
        == 0
    )
    assert (
        cli.main(
            (
                ["score", "--displacements", str(u), str(out), "--loads", loads]
                + ["--out", str(table)]
            )
        )
        == 0
    )
    import pandas as pd

    g = pd.read_csv(table).set_index("load").G_norm
    worst = float(g.drop("total").max())
    gate = ["score", "--displacements", str(u), str(out), "--loads", loads]
    gate += ["--junit", str(report)]
    assert cli.main([*gate, "--max-g-norm", str(1.5 * worst)]) == 0
    assert cli.main([*gate, "--max-g-norm", str(0.5 * worst)]) == 1
    assert cli.main([*gate, "--max-g-norm", "1e-9"]) == 1
    cases = ElementTree.parse(report).getroot().iter("testcase")
    assert sorted(c.get("name") for c in cases) == sorted(loads.split(","))


def test_a_missing_engine_is_one_line_naming_the_extra(monkeypatch, tmp_path, capsys):
    import importlib.util

    real = importlib.util.find_spec

    def no_mujoco(name, *a, **k):
        return None if name == "mujoco" else real(name, *a, **k)

    monkeypatch.setattr(importlib.util, "find_spec", no_mujoco)
    from harness.engines import adapter
    from harness.errors import SpringbenchError

    with pytest.raises(SpringbenchError) as exc:
        adapter("mujoco-flex")
    assert "mujoco" in exc.value.message and "[engines]" in exc.value.fix
    with pytest.raises(SpringbenchError, match="unknown engine"):
        adapter("no-such-engine")


class Oscillator:
    """One node on a spring (k, m) under a force F, stepped by symplectic Euler; its
    measured net force carries ``floor`` |F| across F (no work on the static answer F / k:
    a float32 engine's rounding, rough and doing next to no work on the smooth answer),
    shrinking by ``fade`` per step (constant; a slow creep, fading)."""

    def __init__(self, k, m, F, dt, floor=0.0, fade=1.0):
        self.k, self.m, self.F, self.dt, self.floor, self.fade = k, m, F, dt, floor, fade
        self.u = np.zeros((1, 3))
        self.v = np.zeros((1, 3))
        self.damp = 1.0
        across = np.cross(F, [[1.0, 0.0, 0.0]])
        self.across = across / np.linalg.norm(across) * np.linalg.norm(F)

    def set_damping(self, factor):
        self.damp = factor

    def advance(self, n):
        for _ in range(n):
            self.v = self.damp * (self.v + self.dt * (self.F - self.k * self.u) / self.m)
            self.u = self.u + self.dt * self.v
        self.floor *= self.fade**n

    def measure(self):
        return self.u.copy(), self.v.copy(), self.F - self.k * self.u + self.floor * self.across


@pytest.mark.parametrize(
    "floor, fade, status",
    [(0.0, 1.0, "settled"), (0.3, 1.0, "settled"), (0.3, 1.0 - 1e-4, "not-settled")],
)
def test_settle_stops_at_equilibrium_or_at_a_stalled_residual_of_a_still_body(floor, fade, status):
    from types import SimpleNamespace

    from harness.engines.settle import rayleigh_omega, settle

    k, m, F = 4.0e3, 0.5, np.array([[0.0, -2.0, 1.0]])
    load = SimpleNamespace(
        force=F, u_fem=F / k, held_nodes=np.zeros(0, int), held_components=np.zeros((0, 3), bool)
    )
    omega = rayleigh_omega(load, np.array([m]))
    assert omega == pytest.approx(np.sqrt(k / m))  # the exact mode of one mass on one spring
    dt = 0.2 * 2.0 / omega
    a = settle(
        Oscillator(k, m, F, dt, floor, fade), load, np.array([m]), dt, omega, max_steps=20_000
    )
    assert a.status == status  # a residual still falling 2 % per check is no floor
    if status == "settled":
        assert np.abs(a.u - F / k).max() <= 1e-4 * np.abs(F / k).max()
        assert a.force_residual == pytest.approx(floor, abs=1e-2) and a.residual <= 1e-3
        assert ("stalled" in a.note) == (floor > 0)
