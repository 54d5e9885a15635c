"""harness.mechanics.dynamics against closed forms: the harmonic oscillator (period, damping, the
explicit stability limit), hanging springs (statics), analytic spring stiffness and
finite differences (Jacobians), energy behaviour, blow-up detection."""

from pathlib import Path

import numpy as np
import pytest

from harness.errors import SimulationError
from harness.mechanics.dynamics import Loading, jacobian, simulate, stable_step, stiffness
from harness.mechanics.static_path import solve_static
from harness.models.anisotropic import build_anisotropic
from harness.models.massspring import MassSpring, build_massspring

REF = Path(__file__).resolve().parents[3] / "shared" / "reference-data" / "bourguignon2000"


def spring_chain(n_masses=1, k=4.0, c=0.0, L0=1.0):
    """Node 0 fixed at the origin, masses hanging at y = -L0, -2 L0, ... (springs along y)."""
    pts = np.zeros((n_masses + 1, 3))
    pts[:, 1] = -L0 * np.arange(n_masses + 1)
    springs = np.stack([np.arange(n_masses), np.arange(1, n_masses + 1)], axis=1)
    return MassSpring(
        pts, springs, np.full(n_masses, L0), np.full(n_masses, k), np.full(n_masses, c)
    )


def chain_loading(n, m=0.5, g=0.0):
    fixed = np.zeros(n, bool)
    fixed[0] = True
    return Loading(np.full(n, m), fixed, np.array([0.0, -g, 0.0]), np.zeros((n, 3)), 0.0)


def test_stable_step_of_one_spring():
    model, ld = spring_chain(k=4.0), chain_loading(2, m=0.25)
    assert stable_step(model, ld) == pytest.approx(2.0 * np.sqrt(0.25 / 4.0), rel=1e-10)


@pytest.mark.parametrize(
    "engine,integrator", [("numba", "verlet"), ("numpy", "verlet"), ("numpy", "symplectic-euler")]
)
def test_harmonic_oscillator_period(engine, integrator):
    k, m, A = 4.0, 0.25, 0.01
    model, ld = spring_chain(k=k), chain_loading(2, m=m)
    x0 = model.points.copy()
    x0[1, 1] -= A  # stretched along the spring: exactly linear
    w = np.sqrt(k / m)
    dt = 0.01
    steps = 1000
    tr = simulate(model, ld, dt, steps, x0=x0, observe=[1], engine=engine, integrator=integrator)
    u = tr.observed[:, 0, 1] - model.points[1, 1]
    # the exact discrete solution u_n = a cos(wd t) + b sin(wd t) of the scheme started
    # with d_0 = 0 (u_1 = u_0 (1 - w^2 h^2)), and the continuous one to O(h)
    wd = 2 * np.arcsin(w * dt / 2) / dt
    a = -A
    b = (a * (1 - (w * dt) ** 2) - a * np.cos(wd * dt)) / np.sin(wd * dt)
    np.testing.assert_allclose(u, a * np.cos(wd * tr.t) + b * np.sin(wd * tr.t), atol=1e-12)
    np.testing.assert_allclose(
        u, -A * np.cos(w * tr.t), atol=A * w * dt * (1 + w * tr.t[-1] * w * dt)
    )


def test_damped_oscillator_decay_rate():
    k, m, c = 4.0, 0.25, 0.05
    model, ld = spring_chain(k=k, c=c), chain_loading(2, m=m)
    x0 = model.points.copy()
    x0[1, 1] -= 0.01
    dt = 0.001
    tr = simulate(model, ld, dt, 20000, x0=x0, observe=[1])
    u = tr.observed[:, 0, 1] - model.points[1, 1]
    peaks = np.flatnonzero((u[1:-1] < u[:-2]) & (u[1:-1] <= u[2:])) + 1  # minima (u < 0 side)
    rate = -np.polyfit(tr.t[peaks], np.log(-u[peaks]), 1)[0]
    assert rate == pytest.approx(c / (2 * m), rel=0.01)


@pytest.mark.parametrize("engine", ["numba", "numpy"])
def test_blow_up_is_an_error_naming_the_step_and_the_estimate(engine):
    model, ld = spring_chain(k=4.0), chain_loading(2, m=0.25)
    x0 = model.points.copy()
    x0[1, 1] -= 0.01
    h = stable_step(model, ld)
    with pytest.raises(SimulationError) as exc:
        simulate(model, ld, 1.5 * h, 2000, x0=x0, engine=engine)
    msg = str(exc.value)
    assert "blew up at step" in msg and f"{h:.3g}" in msg
    tr = simulate(model, ld, 0.9 * h, 2000, x0=x0, engine=engine)  # just below: bounded
    # bounded (A / sqrt(1 - 0.81))
    assert np.all(np.isfinite(tr.x)) and np.abs(tr.x - model.points).max() < 0.05


def test_unknown_engine_is_an_error():
    model, ld = spring_chain(k=4.0), chain_loading(2, m=0.25)
    with pytest.raises(SimulationError, match="unknown engine 'fast'"):
        simulate(model, ld, 0.01, 10, engine="fast")


def test_backward_euler_is_stable_beyond_the_limit_and_settles_at_equilibrium():
    k, m, g = 4.0, 0.25, 9.8
    model, ld = spring_chain(k=k), chain_loading(2, m=m, g=g)
    h = 5 * stable_step(model, ld)
    tr = simulate(model, ld, h, 400, integrator="backward-euler")
    assert tr.x[1, 1] == pytest.approx(-1.0 - m * g / k, abs=1e-8)


def test_statics_of_a_hanging_chain_closed_form():
    n, k, m, g = 5, 3.0, 0.2, 9.8
    model, ld = spring_chain(n, k=k), chain_loading(n + 1, m=m, g=g)
    x = solve_static(model, ld, load_steps=3)
    below = m * np.arange(n, 0, -1)  # mass hanging below spring i
    ext = below * g / k
    np.testing.assert_allclose(np.diff(-x[:, 1]), 1.0 + ext, atol=1e-10)
    np.testing.assert_allclose(x[:, [0, 2]], 0, atol=1e-12)


def test_jacobian_of_springs_equals_the_analytic_stiffness():
    mesh_pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1.2]], float)
    cells = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    model = build_massspring(mesh_pts, cells, ks=2.0, kd=0.0)
    rng = np.random.default_rng(0)
    x = mesh_pts + 0.1 * rng.standard_normal(mesh_pts.shape)
    J = jacobian(model.forces, x, model.node_graph()).toarray()
    np.testing.assert_allclose(J, -model.stiffness_matrix(x).toarray(), atol=1e-12)


def test_jacobian_of_the_element_model_vs_central_differences():
    pts = np.array(
        [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1.2], [1.1, -0.2, 1.0]], float
    )
    cells = np.array([[0, 1, 2, 3], [1, 2, 3, 4], [1, 3, 4, 5]])
    model = build_anisotropic(
        pts, cells, azimuth=0.4, elevation=0.9, ks=[3, 2, 1, 2, 1, 0.5], kd=0.2, kvs=3.0
    )
    rng = np.random.default_rng(1)
    x = pts + 0.05 * rng.standard_normal(pts.shape)
    v = rng.standard_normal(pts.shape)
    for wrt in ("x", "v"):
        J = jacobian(model.forces, x, model.node_graph(), v=v, wrt=wrt).toarray()
        fd = np.zeros_like(J)
        eps = 1e-6
        for j in range(x.size):
            e = np.zeros(x.size)
            e[j] = eps
            e = e.reshape(x.shape)
            if wrt == "x":
                fd[:, j] = (model.forces(x + e, v) - model.forces(x - e, v)).ravel() / (2 * eps)
            else:
                fd[:, j] = (model.forces(x, v + e) - model.forces(x, v - e)).ravel() / (2 * eps)
        np.testing.assert_allclose(J, fd, atol=1e-7 * np.abs(fd).max())
        assert np.abs(J).max() > 0.1


def test_symplectic_euler_energy_stays_bounded():
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1.2]], float)
    cells = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    model = build_massspring(pts, cells, ks=2.0, kd=0.0)
    ld = Loading(np.full(5, 0.1), np.zeros(5, bool), np.zeros(3), np.zeros((5, 3)), 0.0)
    rng = np.random.default_rng(2)
    x0 = pts + 0.05 * rng.standard_normal(pts.shape)
    h = 0.01 * stable_step(model, ld, x0)  # h omega_max = 0.02: O(h omega) shadow-energy wobble
    tr = simulate(
        model,
        ld,
        h,
        3000,
        x0=x0,
        snapshots=range(0, 3001, 100),
        energy=True,
        integrator="symplectic-euler",
        engine="numpy",
    )
    e = tr.energy
    assert e[0] > 0
    assert np.abs(e - e[0]).max() < 0.02 * e[0]
    assert abs(e[:15].mean() - e[15:].mean()) < 0.002 * e[0]  # no drift


@pytest.mark.skipif(not REF.exists(), reason="shared reference data not present")
def test_statics_equals_the_end_of_a_damped_run():
    from harness.io.meshfile import read_mesh

    mesh = read_mesh(REF / "meshes/tetra/cube_222/cube.mesh")
    model = build_anisotropic(
        mesh.points,
        mesh.cells["tetra"],
        azimuth=np.pi / 2,
        elevation=np.pi / 2,
        ks=20.0,
        kd=0.5,
        kvs=10.0,
    )
    ld = Loading.from_flags(mesh.flags, gravity=(0, -9.8, 0), drag=0.05)
    dt = 0.5 * stable_step(model, ld)
    xs = solve_static(model, ld, load_steps=2)
    tr = simulate(model, ld, dt, 4000)
    assert np.abs(xs - mesh.points).max() > 1e-3
    np.testing.assert_allclose(tr.x, xs, atol=1e-7)
    K = stiffness(model, xs)
    assert K.shape == (3 * len(xs), 3 * len(xs))


def test_generated_kernels_are_up_to_date():
    from harness.models.bc2000 import codegen

    path = Path(codegen.__file__).with_name("kernels.py")
    assert path.read_text() == codegen.source(), "run python -m harness.models.bc2000.codegen"


def test_parallel_spring_kernel_matches_numpy():
    from harness.bench.dynamics import lattice
    from harness.models.bc2000.parallel import node_index, spring_forces_parallel

    pts, sp = lattice(5)
    rng = np.random.default_rng(4)
    L0 = np.linalg.norm(pts[sp[:, 0]] - pts[sp[:, 1]], axis=1)
    m = MassSpring(pts, sp, L0, rng.uniform(1, 3, len(sp)), rng.uniform(0, 0.2, len(sp)))
    x = pts + 0.05 * rng.standard_normal(pts.shape)
    v = rng.standard_normal(pts.shape)
    ptr, idx, sign = node_index(sp[:, 0], sp[:, 1], len(pts))
    f = np.empty_like(pts)
    spring_forces_parallel(
        x,
        v,
        sp[:, 0].copy(),
        sp[:, 1].copy(),
        m.ks,
        m.kd,
        m.L0,
        np.empty((len(sp), 3)),
        ptr,
        idx,
        sign,
        f,
    )
    np.testing.assert_allclose(f, m.forces(x, v), atol=1e-12)
    assert np.abs(f).max() > 0.1


@pytest.mark.skipif(not REF.exists(), reason="shared reference data not present")
def test_two_thread_tetra_kernel_gives_the_same_bits():
    from harness.io.meshfile import read_mesh

    mesh = read_mesh(REF / "meshes/tetra/cube_343/cube.mesh")
    m = build_anisotropic(
        mesh.points,
        mesh.cells["tetra"],
        azimuth=np.pi / 2,
        elevation=np.pi / 2,
        ks=2.5,
        kd=0.1,
        kvs=5.0,
    )
    ld = Loading.from_flags(mesh.flags, drag=5e-5)
    a = simulate(m, ld, 0.01, 200)
    b = simulate(m, ld, 0.01, 200, threads=2)
    assert np.array_equal(a.x, b.x) and np.abs(a.x - mesh.points).max() > 0.01
