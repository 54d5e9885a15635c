"""Bourguignon & Cani 2000: our model against the ORIGINAL program's data (its rest-state
axes, particle states and volume curves in shared/reference-data/bourguignon2000), and the
numpy forces against the compiled kernels (the model's own physics: test_bc2000_model.py)."""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from harness.case.fibres import named_field_angles
from harness.io.meshfile import read_mesh
from harness.mechanics.dynamics import PROGRAM_DRAG, Loading, simulate
from harness.models.anisotropic import build_anisotropic, find_axes
from harness.models.massspring import build_massspring, mesh_edges
from tests.models.bc2000cases import REF, RUN, VERTICAL, cube343, engines_models

pytestmark = pytest.mark.skipif(not REF.exists(), reason="shared reference data not present")


def volume_models(mesh, dt=0.01):
    P, C = mesh.points, mesh.cells["tetra"]
    return {
        "MS": build_massspring(P, C, ks=2.5, kd=10 * dt),
        "MT0": build_anisotropic(
            P, C, azimuth=VERTICAL[0], elevation=VERTICAL[1], ks=2.5, kd=10 * dt, volume=False
        ),
        "MT": build_anisotropic(
            P,
            C,
            azimuth=VERTICAL[0],
            elevation=VERTICAL[1],
            ks=2.5,
            kd=10 * dt,
            kvs=5.0,
            volume=True,
        ),
    }


def test_rest_axes_match_the_program():
    mesh = cube343()
    ref = pd.read_csv(RUN / "MT_cube343_axes_rest.csv").sort_values(["elem", "axis", "end"])
    a, e = named_field_angles("vertical", mesh.points[mesh.cells["tetra"]].mean(axis=1))
    ax = find_axes(mesh.points, mesh.cells["tetra"], a, e)
    assert len(ref) == ax.nodes.shape[0] * 6
    np.testing.assert_array_equal(ax.nodes.reshape(-1, 3), ref[["v0", "v1", "v2"]].values)
    np.testing.assert_allclose(
        ax.weights.reshape(-1, 3), ref[["c0", "c1", "c2"]].values, rtol=0, atol=1e-12
    )
    np.testing.assert_allclose(
        ax.points.reshape(-1, 3), ref[["px", "py", "pz"]].values, rtol=0, atol=1e-12
    )


def test_spring_count_of_the_program():
    mesh = cube343()
    assert len(mesh_edges(mesh.cells["tetra"])) == 283  # README: 283 springs
    hexa = read_mesh(REF / "meshes/hexa/cube_111/cube.mesh")
    assert len(mesh_edges(hexa.cells["hexahedron"])) == 16  # 12 edges + 4 diagonals


@pytest.fixture(scope="module")
def volume_runs():
    mesh = cube343()
    dt = 0.01
    ld = Loading.from_flags(mesh.flags, drag=PROGRAM_DRAG * dt)
    return mesh, {
        name: simulate(m, ld, dt, 2500, snapshots=(1, 10, 100, 500, 1000, 2500))
        for name, m in volume_models(mesh, dt).items()
    }


@pytest.mark.parametrize("name", ["MS", "MT0", "MT"])
def test_volume_experiment_reproduces_the_program(volume_runs, name):
    mesh, runs = volume_runs
    tr = runs[name]
    dv = tr.volume_change_percent()
    vr = np.loadtxt(REF / "original-volume/vol_results.txt", skiprows=1)
    col = ("MS", "MT0", "MT").index(name) + 1
    assert len(dv) == 2501
    np.testing.assert_allclose(dv[1:], vr[:, col], rtol=0, atol=1e-3)  # every step, percent units
    full = pd.read_csv(RUN / f"{name}_volume_fullprec.csv").dV_over_V0_percent.values
    np.testing.assert_allclose(dv, full, rtol=0, atol=1e-9)
    for step in (1, 10, 100, 500, 1000, 2500):
        r = pd.read_csv(RUN / f"{name}_step{step:04d}.csv")
        assert list(r.columns) == ["i", "x", "y", "z", "dx", "dy", "dz", "constraint"]
        x, d = tr.snapshots[step]
        np.testing.assert_array_equal(r.constraint.values, mesh.flags)
        np.testing.assert_allclose(x, r[["x", "y", "z"]].values, rtol=0, atol=1e-6)
        np.testing.assert_allclose(d, r[["dx", "dy", "dz"]].values, rtol=0, atol=1e-9)


def test_paper_claim_volume_forces_keep_volume_within_1_5_percent(volume_runs):
    _, runs = volume_runs
    peak = {k: np.abs(tr.volume_change_percent()).max() for k, tr in runs.items()}
    assert peak["MT"] < 1.5 < peak["MS"] < peak["MT0"]


def test_beam336_MT0_reproduces_vol_txt():
    mesh = read_mesh(REF / "meshes/tetra/beam_336/cube.mesh")
    dt = 0.01
    m = build_anisotropic(
        mesh.points,
        mesh.cells["tetra"],
        azimuth=VERTICAL[0],
        elevation=VERTICAL[1],
        ks=5.0,
        kd=10 * dt,
        volume=False,
    )
    tr = simulate(
        m, Loading.from_flags(mesh.flags, drag=PROGRAM_DRAG * dt), dt, 753, snapshots=(100, 753)
    )
    dv = tr.volume_change_percent()
    orig = np.loadtxt(REF / "original-volume/vol.txt", skiprows=1)
    np.testing.assert_allclose(orig[:, 0], tr.t[1:], atol=1e-9)
    # vol.txt has 6 significant digits and the authors' own re-run differs from it by 7e-6 %
    np.testing.assert_allclose(dv[1:], orig[:, 2], rtol=0, atol=2e-5)
    full = pd.read_csv(RUN / "BEAMvol_MT0_beam336_volume_fullprec.csv").dV_over_V0_percent.values
    np.testing.assert_allclose(dv, full, rtol=0, atol=1e-9)
    for step in (100, 753):
        r = pd.read_csv(RUN / f"BEAMvol_MT0_beam336_step{step:04d}.csv")
        np.testing.assert_allclose(
            tr.snapshots[step][0], r[["x", "y", "z"]].values, rtol=0, atol=1e-6
        )


# -- the numpy forces (used by the other integrators, statics, Jacobians) vs the kernel ------------


@pytest.mark.parametrize("kind", ["tetra", "hexa"])
def test_numpy_and_compiled_engines_agree(kind):
    mesh, ld, dt, models = engines_models(kind)
    for m in models:
        a = simulate(m, ld, dt, 200, engine="numba", snapshots=(200,))
        b = simulate(m, ld, dt, 200, engine="numpy", integrator="verlet", snapshots=(200,))
        assert np.abs(a.x - mesh.points).max() > 1e-3  # it moved
        np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-10)
        np.testing.assert_allclose(a.volume, b.volume, rtol=1e-12)
        c = simulate(m, ld, dt, 200, engine="numba", threads=2)
        assert np.array_equal(a.x, c.x)  # two threads: the same bits


def test_kernels_leave_no_rounding_to_llvm():
    """The same-bits contract of the two-thread loop needs every compiled copy of a block
    kernel to round alike. With fastmath={"contract"} LLVM chose per copy which products
    to fuse, and numba keeps several copies (one per caller's module; a cached caller
    brings its own): run_serial loaded from the cache and run_threads compiled in the
    process then differed in the last bits of the hexa volume model. Fusions are explicit
    fma() calls instead."""
    from harness.models.bc2000 import codegen

    src = codegen.source()
    assert "fastmath" not in src
    assert src.count("fma(") > 100


_CACHE_HISTORY = """
import sys, hashlib
import numpy as np
sys.path.insert(0, {root!r})
from tests.models.bc2000cases import engines_models
from harness.mechanics.dynamics import simulate
mesh, ld, dt, models = engines_models("hexa")
for m in models:
    for t in sys.argv[1]:
        x = simulate(m, ld, dt, 50, engine="numba", threads=int(t)).x
        print(t, hashlib.sha1(x.tobytes()).hexdigest())
"""


@pytest.mark.slow
def test_two_threads_same_bits_whatever_the_cache_history(tmp_path):
    """The condition of the flaky failure (minutes: compiles the kernels twice): a fresh
    numba cache filled by a process that ran only the serial loop, then a process that
    loads run_serial from it and compiles run_threads itself."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba-cache"))
    script = _CACHE_HISTORY.format(root=str(Path(__file__).resolve().parents[2]))

    def run(order):
        out = subprocess.run(
            [sys.executable, "-c", script, order],
            env=env,
            capture_output=True,
            text=True,
            timeout=1800,
        )
        assert out.returncode == 0, out.stderr[-3000:]
        return [line.split() for line in out.stdout.splitlines()]

    first = run("1")  # fills the cache with run_serial only
    second = run("12")  # run_serial from the cache, run_threads compiled here
    assert len(first) == 3 and len(second) == 6
    for k in range(3):
        assert second[2 * k][1] == second[2 * k + 1][1] == first[k][1], k


def test_parallel_spring_kernel_matches_numpy():
    """Springs in random order and orientation, a count that is not a whole number of
    blocks, 1-3 threads; called twice (the per-thread buffers must be left zero)."""
    from harness.bench.dynamics import lattice
    from harness.models.bc2000.parallel import SB, spring_forces, spring_plan
    from harness.models.massspring import MassSpring

    rng = np.random.default_rng(7)
    pts, sp = lattice(6)
    sp = sp[rng.permutation(len(sp))]
    flip = rng.random(len(sp)) < 0.5
    sp[flip] = sp[flip, ::-1]
    sp = sp[: len(sp) - 5]
    assert len(sp) % SB != 0
    L0 = np.linalg.norm(pts[sp[:, 0]] - pts[sp[:, 1]], axis=1) * rng.uniform(0.9, 1.1, len(sp))
    m = MassSpring(pts, sp, L0, rng.uniform(1, 3, len(sp)), rng.uniform(0, 0.2, len(sp)))
    x = pts + 0.05 * rng.standard_normal(pts.shape)
    v = rng.standard_normal(pts.shape)
    ref = m.forces(x, v)
    for T in (1, 2, 3):
        plan = spring_plan(sp, m.ks, m.kd, m.L0, len(pts), T)
        for _ in range(2):
            f = np.full_like(pts, np.nan)
            spring_forces(plan, x, v, f)
            np.testing.assert_allclose(f, ref, rtol=0, atol=1e-12 * np.abs(ref).max())
    with pytest.raises(ValueError, match="C-contiguous"):  # a strided f would be silently lost
        spring_forces(plan, x, v, np.zeros((len(pts), 6))[:, :3])
