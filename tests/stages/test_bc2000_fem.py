"""The FEM-facing parts of the Bourguignon-Cani experiments, against independent answers:
the direction-pull measure against closed forms (an affine field, the transversely
isotropic modulus from the rotated compliance, the FEM reference under a uniform stress),
consistent nodal masses by hand, continuation through the limit point of a tripod whose
load-deflection curve is known in closed form, and the cantilever/fibre stages end to end
(slow)."""

from pathlib import Path

import numpy as np
import pytest

from harness.case.elasticity import isotropic_compliance, rotate, transversely_isotropic_compliance
from harness.io.meshfile import read_mesh
from harness.mechanics import anisotropy as an
from harness.mechanics.dynamics import Loading, jacobian
from harness.mechanics.static_path import solve_static_path
from harness.models.anisotropic import build_anisotropic
from harness.models.massspring import MassSpring

ROOT = Path(__file__).resolve().parents[2]
REF = ROOT.parent / "shared" / "reference-data" / "bourguignon2000"


def grid(n=3):
    a = np.linspace(0.0, 1.0, n)
    return np.array(np.meshgrid(a, a, a, indexing="ij")).reshape(3, -1).T


@pytest.mark.parametrize("angle", [0.0, 30.0, 45.0, 120.0, 135.0])
def test_measures_of_an_affine_field_are_its_compliance(angle):
    """u = S sigma x with sigma = s d d^T: E_d = 1 / (d S d); no drift for an isotropic S
    nor along / across the fibre, the strain across d otherwise; the transversely isotropic
    modulus formula equals 1 / (d.d : S_rotated : d.d)."""
    P = grid()
    d = an.directions_xy([angle])[0]
    sig = 2.0 * np.outer(d, d)
    voigt = lambda t: np.array([t[0, 0], t[1, 1], t[2, 2], t[1, 2], t[0, 2], t[0, 1]])
    iso = isotropic_compliance(700.0, 0.3)
    fibre = np.linalg.inv(
        rotate(
            np.linalg.inv(transversely_isotropic_compliance(4000, 1000, 0.3, 0.3, 700)),
            np.array([[1.0, 1.0, 0.0]]) / np.sqrt(2),
        )[0]
    )
    for S in (iso, fibre):
        e = S @ voigt(sig)  # engineering shears
        eps = np.array(
            [[e[0], e[5] / 2, e[4] / 2], [e[5] / 2, e[1], e[3] / 2], [e[4] / 2, e[3] / 2, e[2]]]
        )
        u = P @ eps.T + np.array([0.1, -0.2, 0.3])
        m = an.measures(P, u, d, stress=2.0)
        dd = voigt(np.outer(d, d))
        assert m["stiffness"] == pytest.approx(1.0 / (dd @ S @ dd), rel=1e-12)
        across = eps @ d - (d @ eps @ d) * d  # the strain across d, by hand
        assert m["drift"] == pytest.approx(np.linalg.norm(across) / (d @ eps @ d), abs=1e-12)
        if S is iso or angle in (45.0, 135.0):  # isotropic, or along / across the fibre
            assert m["drift"] < 1e-12
        else:
            assert m["drift"] > 1e-2
    # the last S is the fibre at 45 degrees: the closed form at angle - 45
    assert m["stiffness"] == pytest.approx(
        an.transversely_isotropic_modulus(np.deg2rad(angle - 45.0), 4000, 1000, 0.3, 700), rel=1e-12
    )


def test_pull_loads_are_self_equilibrated_and_carry_the_stress():
    P = read_mesh(REF / "meshes/tetra/cube_333/cube.mesh").points
    bbox = (P.min(0), P.max(0))
    for ang in (0.0, 30.0, 90.0):
        d = an.directions_xy([ang])[0]
        free, f = an.pull_arrays(P, bbox, an.pull_load(d, stress=2.0))
        f = f.reshape(-1, 3)
        assert np.abs(f.sum(0)).max() < 1e-12
        assert np.abs(np.cross(P - P.mean(0), f).sum(0)).max() < 1e-10
        on_x1 = np.isclose(P[:, 0], 3.0)
        np.testing.assert_allclose(f[on_x1].sum(0), 2.0 * d * d[0] * 9.0, atol=1e-12)
        assert (~free).sum() == 6


def test_fem_reference_under_pulls_matches_the_closed_form():
    """The FEM reference of a transversely isotropic cube (fibre at 45 degrees in x-y) under
    the direction pulls: E_d equals the closed-form modulus (uniform stress: exact)."""
    import dataclasses

    from harness.case.reader import load_case
    from reference import solve

    case = load_case(ROOT / "cases/bourguignon2000/fem_cube333_tetra_fibre.toml")
    angles = [0.0, 45.0, 100.0]
    loads = tuple(an.pull_load(d, name=f"p{i}") for i, d in enumerate(an.directions_xy(angles)))
    sub = dataclasses.replace(
        case, loads=loads, reference=dataclasses.replace(case.reference, max_refine=0)
    )
    ref = solve(sub, cache=False)
    P = read_mesh(REF / "meshes/tetra/cube_333/cube.mesh").points
    f = case.material.fibre
    for a, l, d in zip(angles, loads, an.directions_xy(angles)):
        m = an.measures(P, ref.displacement(P, l.name), d)
        exact = an.transversely_isotropic_modulus(
            np.deg2rad(a - 45.0), f.E_fibre, f.E_cross, f.nu_fibre, f.G_fibre
        )
        assert m["stiffness"] == pytest.approx(exact, rel=1e-8)


def test_lumped_masses_by_hand():
    from harness.stages.bc2000 import lumped_masses

    cube = np.array(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
        float,
    )
    np.testing.assert_allclose(
        lumped_masses(2 * cube, np.arange(8)[None], 3.0), np.full(8, 3.0 * 8 / 8)
    )
    tet = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    np.testing.assert_allclose(lumped_masses(tet, np.arange(4)[None], 6.0), np.full(4, 0.25))
    mesh = read_mesh(REF / "meshes/tetra/beam_336/cube.mesh")
    assert lumped_masses(mesh.points, mesh.cells["tetra"], 2.0).sum() == pytest.approx(2.0 * 54.0)


def tripod(h=0.3, a=1.0, k=10.0):
    """Three springs from an apex at height h to supports on a circle of radius a."""
    ang = np.deg2rad([0.0, 120.0, 240.0])
    pts = np.vstack([np.stack([a * np.cos(ang), np.zeros(3), a * np.sin(ang)], 1), [[0.0, h, 0.0]]])
    springs = np.array([[3, 0], [3, 1], [3, 2]])
    L0 = np.linalg.norm(pts[3] - pts[:3], axis=1)
    return MassSpring(pts, springs, L0, np.full(3, k), np.zeros(3))


def tripod_force(w, h=0.3, a=1.0, k=10.0):
    """Downward load that holds the apex at deflection w (closed form, 3 bars)."""
    L0, L = np.hypot(a, h), np.hypot(a, h - w)
    return 3 * k * (L0 - L) * (h - w) / L


def test_continuation_passes_the_limit_point_of_a_tripod():
    """Shallow tripod under a downward apex load above its limit load: load stepping
    cannot pass the limit point; the continuation reports it at the closed-form limit and
    lands on the snapped-through equilibrium at the full load."""
    model = tripod()
    w = np.linspace(0, 0.6, 200001)
    Pw = tripod_force(w)
    P_limit = Pw[: len(w) // 2].max()
    P = 1.5 * P_limit
    fixed = np.array([True, True, True, False])
    push = np.zeros((4, 3))
    push[3, 1] = -P
    ld = Loading(np.ones(4), fixed, np.zeros(3), push)
    res = solve_static_path(model, ld, load_steps=4)
    assert res.folds and res.folds[0] == pytest.approx(P_limit / P, rel=2e-3)
    assert res.x is not None and "limit point" in res.status
    assert tripod_force(0.3 - res.x_limit[3, 1]) == pytest.approx(P_limit, rel=1e-2)
    w_end = 0.3 - res.x[3, 1]
    assert tripod_force(w_end) == pytest.approx(P, rel=1e-8) and w_end > 0.6  # the far branch
    np.testing.assert_allclose(res.x[3, [0, 2]], 0.0, atol=1e-9)


def test_continuation_status_without_regaining_the_load():
    """With too few continuation steps the status is one line, never a traceback: before
    the fold 'stalled' below the closed-form limit load, after it 'limit point' at it."""
    model = tripod()
    P_limit = tripod_force(np.linspace(0, 0.3, 100001)).max()
    push = np.zeros((4, 3))
    push[3, 1] = -1.5 * P_limit
    ld = Loading(np.ones(4), np.array([True, True, True, False]), np.zeros(3), push)
    res = solve_static_path(model, ld, load_steps=4, arc_steps=1)
    assert res.x is None and res.status.startswith("stalled") and not res.folds
    assert 0.5 < res.load_factor < 1 / 1.5
    res = solve_static_path(model, ld, load_steps=4, arc_steps=5)
    assert res.x is None and res.status.startswith("limit point")
    assert res.folds[0] == pytest.approx(1 / 1.5, rel=2e-3) and res.x_limit is not None


def test_hexa_model_jacobian_at_a_large_deformation_vs_central_differences():
    """The Newton/continuation tangent of the hexa element model (axes + radial volume
    springs) far from rest, as on the bent beam: complex step = central differences."""
    mesh = read_mesh(REF / "meshes/hexa/cube_333/cube.mesh")
    m = build_anisotropic(
        mesh.points, mesh.cells["hexahedron"], azimuth=0.0, elevation=0.0, ks=5.0, kvs=5.0
    )
    rng = np.random.default_rng(3)
    x = mesh.points + 0.3 * rng.standard_normal(mesh.points.shape)
    J = jacobian(m.forces, x, m.node_graph()).toarray()
    eps = 1e-6
    fd = np.zeros_like(J)
    for j in range(x.size):
        e = np.zeros(x.size)
        e[j] = eps
        e = e.reshape(x.shape)
        fd[:, j] = (m.forces(x + e) - m.forces(x - e)).ravel() / (2 * eps)
    np.testing.assert_allclose(J, fd, atol=1e-7 * np.abs(fd).max())


def test_turned_frames_equal_the_program_frames_when_they_coincide():
    """Explicit frames: the frame (x, y, z) turned by 90 degrees about z is (y, -x, z), the
    same axis lines as the vertical fibre's frame (y, -z, -x): same axes, same forces."""
    mesh = read_mesh(REF / "meshes/tetra/cube_333/cube.mesh")
    T = mesh.cells["tetra"]
    a = build_anisotropic(mesh.points, T, azimuth=np.pi / 2, elevation=np.pi / 2, ks=2.0, kvs=1.0)
    b = build_anisotropic(
        mesh.points, T, frames=np.array([[0.0, 1, 0], [-1, 0, 0], [0, 0, 1]]), ks=2.0, kvs=1.0
    )
    x = mesh.points + 0.05 * np.random.default_rng(0).standard_normal(mesh.points.shape)
    # (an axis through an edge is nudged by a random 1e-6, as in the program)
    np.testing.assert_allclose(np.sort(a.L0, axis=1), np.sort(b.L0, axis=1), rtol=1e-5)
    fa, fb = a.forces(x), b.forces(x)
    np.testing.assert_allclose(fa, fb, atol=1e-5 * np.abs(fa).max())


@pytest.mark.slow
def test_cantilever_stage_against_fem(tmp_path):
    """The cantilever rows end to end: the FEM tip deflection against Timoshenko beam
    theory (bending + shear, kappa = 5/6: an independent estimate for this stubby 3 x 3 x 6
    beam, within 10 %), the ratio columns consistent, hexa MT's limit point reported, not
    raised (the small-load limit of the statics: the next test)."""
    from harness.case.reader import load_case
    from harness.stages import StageContext, bc2000

    case = load_case(ROOT / "cases/bourguignon2000/cantilever_beam336.toml")
    rows = bc2000.run(case, StageContext(out_dir=tmp_path))
    assert len(rows) == 4
    mat, L, a = case.material, 6.0, 3.0
    q = mat.density * 0.098 * a * a  # weight per length, 1 % of g
    G = mat.E / (2 * (1 + mat.nu))
    timoshenko = q * L**4 / (8 * mat.E * a**4 / 12) + q * L**2 / (2 * 5 / 6 * G * a * a)
    assert rows[0]["tip_deflection_fem"] == pytest.approx(-timoshenko, rel=0.1)
    for r in rows:
        assert r["ref_error_estimate"] < 0.05 and r["tip_deflection_fem"] < 0
        assert r["tip_ratio"] == pytest.approx(r["tip_deflection_linear"] / r["tip_deflection_fem"])
        assert "small strain" in r["comparison"] and r["static_status"]
    hexa_mt = rows[3]
    assert hexa_mt["mesh"].startswith("hexa") and "limit point" in hexa_mt["static_status"]


def test_linearised_model_is_the_small_load_limit_of_the_statics():
    """tip_deflection_linear_program_load is the derivative of the nonlinear statics."""
    from harness.case.reader import load_case
    from harness.stages import bc2000

    case = load_case(ROOT / "cases/bourguignon2000/cantilever_beam336.toml")
    model, dyn = dict(case.section("model")), dict(case.section("dynamics"))
    mesh = read_mesh(REF / "meshes/tetra/beam_336/cube.mesh")
    m = bc2000.build("MT", model, mesh, 0.01)
    ld = bc2000.loading(model, dyn, mesh, 0.01)
    tip = np.flatnonzero(mesh.points[:, 2] >= 6 - 1e-9)
    lin = bc2000._static_columns(
        m,
        Loading(ld.mass * 1e-4, ld.fixed, ld.gravity, ld.push * 1e-4),
        tip,
        mesh.points,
        arc_steps=0,
    )
    assert lin["tip_deflection_static"] == pytest.approx(
        lin["tip_deflection_linear_program_load"], rel=1e-3
    )


@pytest.mark.parametrize("kind,cell", [("tetra", "tetra"), ("hexa", "hexahedron")])
def test_element_tangent_equals_the_coloured_complex_step(kind, cell):
    """tangent_stiffness (element by element) = -jacobian (whole mesh, coloured) far from
    rest, and the assembled element forces are the model's forces."""
    mesh = read_mesh(REF / f"meshes/{kind}/cube_333/cube.mesh")
    m = build_anisotropic(
        mesh.points,
        mesh.cells[cell],
        azimuth=0.3,
        elevation=0.7,
        ks=[3, 2, 1, 2, 1, 0.5],
        kvs=2.0,
        rest_angle="rest",
    )
    x = mesh.points + 0.2 * np.random.default_rng(5).standard_normal(mesh.points.shape)
    A = -jacobian(m.forces, x, m.node_graph()).toarray()
    B = m.tangent_stiffness(x).toarray()
    np.testing.assert_allclose(B, A, atol=1e-12 * np.abs(A).max())
    f = np.zeros_like(x)
    np.add.at(f, m.cells.ravel(), m.element_forces(x[m.cells]).reshape(-1, 3))
    np.testing.assert_allclose(f, m.forces(x), atol=1e-12 * np.abs(f).max())


def test_pull_on_a_body_without_corner_nodes_is_a_one_line_error():
    """A mesh that does not reach the box corners cannot hold the pulls: ModelError, not a
    traceback."""
    from harness.errors import SpringbenchError

    P = np.array([[0.5, 0.0, 0.0], [1.0, 0.5, 0.0], [0.0, 1.0, 0.5], [0.5, 0.5, 1.0]])
    with pytest.raises(SpringbenchError, match="corner x0y0z0"):
        an.pull_arrays(P, (P.min(0), P.max(0)), an.pull_load((1.0, 0.0, 0.0)))


def test_cantilever_load_without_force_is_a_case_error(tmp_path):
    """A [loads] case with no force is a one-line CaseError before any solve (not NaN tip
    ratios)."""
    from harness.case.reader import load_case
    from harness.errors import CaseError
    from harness.stages import StageContext, bc2000

    text = (ROOT / "cases/bourguignon2000/cantilever_beam336.toml").read_text()
    text = text.replace('traction = [{ part = "z1", vector = [0.0, 0.0, 0.01] }]', "")
    text = text.replace("../../../shared", str(ROOT.parent / "shared"))
    p = tmp_path / "cantilever.toml"
    p.write_text(text)
    # load_case sees it now
    with pytest.raises(CaseError, match="load 'stretch' (has no force|is zero)"):
        bc2000.run(load_case(p), StageContext(out_dir=tmp_path))


def test_inverted_elements_by_hand():
    """One of two tets mirrored through its base plane is inside out; a hex with one
    corner pushed through the opposite face has a negative sub-tetrahedron."""
    from types import SimpleNamespace

    from harness.stages.bc2000 import inverted_elements

    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, -1]], float)
    m = SimpleNamespace(points=pts, cells=np.array([[0, 1, 2, 3], [0, 2, 1, 4]]))
    assert inverted_elements(m, pts) == 0
    x = pts.copy()
    x[3, 2] = -0.5  # the apex of the first tet through its base
    assert inverted_elements(m, x) == 1
    cube = np.array(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
        float,
    )
    h = SimpleNamespace(points=cube, cells=np.arange(8)[None])
    assert inverted_elements(h, cube) == 0 and inverted_elements(h, 2.0 * cube) == 0
    y = cube.copy()
    y[6, 2] = -0.5
    assert inverted_elements(h, y) == 1
