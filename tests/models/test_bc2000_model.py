"""Bourguignon & Cani 2000, the model's physics independent of the program (rigid motions,
resultants, hand-computed stretches, frames and fibre fields), the stage and case files,
and the linear statics, calibration and anisotropy of harness/stages/bc2000_linear.py."""

import numpy as np
import pandas as pd
import pytest

from harness.case.fibres import azimuth_elevation, named_field_angles
from harness.io.meshfile import read_mesh
from harness.models.anisotropic import build_anisotropic, frame
from harness.models.massspring import build_massspring
from tests.models.bc2000cases import REF, ROOT

pytestmark = pytest.mark.skipif(not REF.exists(), reason="shared reference data not present")


# -- physics of the model (independent of the program) -------------------------------------------


def random_rotation(rng):
    q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    return q * np.sign(np.linalg.det(q))


@pytest.mark.parametrize("kind", ["tetra", "hexa"])
def test_rigid_motion_gives_no_force(kind):
    mesh = read_mesh(REF / f"meshes/{kind}/cube_222/cube.mesh")
    cells = mesh.cells["tetra" if kind == "tetra" else "hexahedron"]
    rng = np.random.default_rng(1)
    m = build_anisotropic(
        mesh.points,
        cells,
        azimuth=rng.uniform(0, np.pi, len(cells)),
        elevation=rng.uniform(-1, 1, len(cells)),
        ks=[3, 2, 1, 2, 1, 0.5],
        kvs=4.0,
        rest_angle="rest",
    )
    x = mesh.points @ random_rotation(rng).T + rng.standard_normal(3)
    f = m.forces(x)
    assert np.abs(f).max() < 1e-12
    y = x + 0.05 * rng.standard_normal(x.shape)
    assert np.abs(m.forces(y)).max() > 1e-3


def test_axial_and_angular_forces_have_zero_resultant():
    """+G at one end and -G at the other, spread with weights summing to one."""
    mesh = read_mesh(REF / "meshes/tetra/cube_333/cube.mesh")
    rng = np.random.default_rng(2)
    m = build_anisotropic(
        mesh.points, mesh.cells["tetra"], ks=[3, 2, 1, 2, 1, 0.5], kd=0.3, volume=False
    )
    x = mesh.points + 0.1 * rng.standard_normal(mesh.points.shape)
    v = rng.standard_normal(x.shape)
    f = m.forces(x, v)
    assert np.abs(f).max() > 0.1
    np.testing.assert_allclose(f.sum(axis=0), 0, atol=1e-12)
    ms = build_massspring(mesh.points, mesh.cells["tetra"], ks=2.0, kd=0.3)
    np.testing.assert_allclose(ms.forces(x, v).sum(axis=0), 0, atol=1e-12)


def test_single_axis_stretch_by_hand():
    """One hexahedron, unit cube, only ks1 (x axis): stretching by s along x gives the
    force ks1 * s on each x face, a quarter per vertex (the bilinear weights of a face centre)."""
    mesh = read_mesh(REF / "meshes/hexa/cube_111/cube.mesh")
    C = mesh.cells["hexahedron"]
    m = build_anisotropic(
        mesh.points, C, azimuth=0.0, elevation=0.0, ks=[2.0, 0, 0, 0, 0, 0], volume=False
    )
    np.testing.assert_allclose(m.L0[0], [1, 1, 1], atol=1e-14)
    np.testing.assert_allclose(m.axes.weights, 0.25, atol=1e-14)
    s = 0.1
    x = mesh.points * [1 + s, 1, 1]
    f = m.forces(x)
    np.testing.assert_allclose(
        f[:, 0], np.where(mesh.points[:, 0] > 0.5, -1, 1) * 2.0 * s / 4, atol=1e-13
    )
    np.testing.assert_allclose(f[:, 1:], 0, atol=1e-13)


def test_program_frames():
    F = frame(np.pi / 2, np.pi / 2)[0]
    # README: +y, -z, -x
    np.testing.assert_allclose(F, [[0, 1, 0], [0, 0, -1], [-1, 0, 0]], atol=1e-15)
    F = frame(0.0, 0.0)[0]  # hexa program: x, y, z
    np.testing.assert_allclose(np.abs(F), np.eye(3), atol=1e-15)
    rng = np.random.default_rng(3)
    for a, e in rng.uniform(-1.5, 1.5, (20, 2)):
        F = frame(a, e)[0]
        np.testing.assert_allclose(F[0], azimuth_elevation(a, e)[0], atol=1e-15)
        G = F / np.linalg.norm(F, axis=1, keepdims=True)
        np.testing.assert_allclose(G @ G.T, np.eye(3), atol=1e-12)


def test_named_fields_by_hand():
    # hemicircular: circle in the y-z plane about (y, z) = (2.5, 3); directly below the
    # centre (z = 1) the tangent is vertical, level with it (y = 0.5, z = 3) horizontal (+-z)
    g = np.array([[0.7, 2.5, 1.0], [0.7, 0.5, 3.0], [1.0, 2.5 + 1.0, 3.0 - 1.0]])
    a, e = named_field_angles("hemicircular", g)
    f = azimuth_elevation(a, e)
    np.testing.assert_allclose(np.abs(f[0]), [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(np.abs(f[1]), [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(np.abs(f[2]), [0, np.sqrt(0.5), np.sqrt(0.5)], atol=1e-12)
    # helicoidal: about the vertical axis through (1.5, 1.5): horizontal part tangent to the
    # circle, elevation +45 degrees on the z <= 1.5 side, -45 on the other
    g = np.array([[2.5, 1.0, 1.5], [1.5, 2.0, 0.5], [0.5, 2.0, 2.5]])
    a, e = named_field_angles("helicoidal", g)
    np.testing.assert_allclose(e, [np.pi / 4, np.pi / 4, -np.pi / 4])
    f = azimuth_elevation(a, e)
    radial = (g - [1.5, 0, 1.5]) * [1, 0, 1]
    np.testing.assert_allclose(np.sum(f * radial, axis=1), 0, atol=1e-12)
    a1, e1 = named_field_angles("random", g, seed=5)
    a2, e2 = named_field_angles("random", g, seed=5)
    assert (
        np.array_equal(a1, a2)
        and np.all((0 <= a1) & (a1 < np.pi))
        and np.all(np.abs(e1) <= np.pi / 2)
    )


@pytest.mark.parametrize(
    "field", ["horizontal", "diagonal", "hemicircular", "helicoidal", "random"]
)
def test_fibre_fields_give_valid_axes(field):
    mesh = read_mesh(REF / "meshes/tetra/cube_353/cube.mesh.push2")
    C = mesh.cells["tetra"]
    a, e = named_field_angles(field, mesh.points[C].mean(axis=1), seed=0)
    m = build_anisotropic(mesh.points, C, azimuth=a, elevation=e, ks=2.5)
    X = mesh.points[C]
    size = np.linalg.norm(X[:, :, None] - X[:, None], axis=-1).max(axis=(1, 2))
    assert np.all(m.L0 > 0.05 * size[:, None])  # no collapsed chord
    np.testing.assert_allclose(m.axes.weights.sum(axis=-1), 1, atol=1e-9)
    assert np.all(m.axes.weights > -1e-9)
    # each chord lies along its frame direction
    l = m.axes.points[:, 0::2] - m.axes.points[:, 1::2]
    F = frame(a, e)
    F = F / np.linalg.norm(F, axis=-1, keepdims=True)
    cos = np.abs(np.sum(l * F, axis=-1)) / np.linalg.norm(l, axis=-1)
    assert np.all(cos > 1 - 1e-6)


# -- the stage and the case files ----------------------------------------------------------------


def test_case_files_load():
    from harness.case.reader import load_case

    files = sorted((ROOT / "cases" / "bourguignon2000").glob("*.toml"))
    assert len(files) >= 6
    for f in files:
        c = load_case(f)
        assert c.section("model")["kind"] == "bc2000"


def test_volume_stage_writes_the_curves(tmp_path):
    from harness.case.reader import load_case
    from harness.stages import StageContext, bc2000

    case = load_case(ROOT / "cases/bourguignon2000/volume_cube343.toml")
    assert bc2000.applies(case)
    rows = bc2000.run(case, StageContext(out_dir=tmp_path))
    assert [r["model"] for r in rows] == ["MS", "MT0", "MT"]
    for r in rows:
        assert r["max_dev_vs_original_percent"] < 1e-3
    df = pd.read_csv(tmp_path / "volume.csv")
    assert list(df.columns) == ["t", "MS", "MT0", "MT"]
    assert len(df) == 2501 and df.t.iloc[-1] == pytest.approx(25.0)


def test_bad_bc2000_keys_are_one_line_errors(tmp_path):
    from harness.case.reader import load_case
    from harness.errors import CaseError

    src = (ROOT / "cases/bourguignon2000/volume_cube343.toml").read_text()
    src = src.replace("ks = [2.5]", "ks = [2.5, 1.0]").replace('"$M', '"../../')
    f = tmp_path / "bad.toml"
    mesh_rel = str((REF / "meshes/tetra/cube_343/cube.mesh").resolve())
    f.write_text(
        src.replace(
            'file = "../../../shared/reference-data/bourguignon2000/meshes/'
            'tetra/cube_343/cube.mesh"',
            f'file = "{mesh_rel}"',
        )
    )
    with pytest.raises(CaseError) as exc:
        load_case(f)
    assert "model.ks" in str(exc.value) and "\n" not in str(exc.value)


# -- linear statics, calibration, anisotropy (harness/stages/bc2000_linear.py) ------------------


def test_stiffness_is_linear_in_the_constants_and_the_fit_recovers_them():
    from harness.mechanics.dynamics import stiffness
    from harness.stages import bc2000_linear as linear

    mesh = read_mesh(REF / "meshes/tetra/cube_222/cube.mesh")
    P, C = mesh.points, mesh.cells["tetra"]
    true = np.array([3.0, 2.0, 1.5, 1.0, 0.7, 0.4, 2.0])
    m = build_anisotropic(P, C, azimuth=0.2, elevation=1.1, ks=true[:6], kvs=true[6])
    Ks = linear.unit_stiffnesses(m)
    K = stiffness(m)
    np.testing.assert_allclose(
        sum(t * Kj for t, Kj in zip(true, Ks)).toarray(), K.toarray(), atol=1e-10
    )
    # synthetic loads: bottom held, nodal forces on the top
    n = len(P)
    held = np.repeat(P[:, 1] < 1e-9, 3)
    rng = np.random.default_rng(0)
    f = np.zeros(3 * n)
    f[np.repeat(P[:, 1] > P[:, 1].max() - 1e-9, 3)] = rng.standard_normal(
        3 * int(np.sum(P[:, 1] > P[:, 1].max() - 1e-9))
    )
    g = np.roll(f, 3)
    g[held] = 0
    loads = linear.Loads(["a", "b"], np.array([~held, ~held]), np.array([f, g]))
    u_true = linear.solve(K, loads)
    theta, G0, G1 = linear.fit(
        Ks, true * np.array([2, 0.5, 1, 3, 1, 0.5, 1.5]), u_true, loads, np.ones(n)
    )
    assert G0 > 1e-2 and G1 < 1e-8 * G0
    np.testing.assert_allclose(theta, true, rtol=1e-5)


def test_face_pull_anisotropy_hexa_vs_tetra():
    """A regular hexa grid has the cube's symmetry: the six face pulls agree and nothing
    drifts; classic springs on a tet mesh of the same cube do not."""
    from harness.stages import bc2000_linear as linear

    hexa = read_mesh(REF / "meshes/hexa/cube_333/cube.mesh")
    H = hexa.cells["hexahedron"]
    mh = build_massspring(hexa.points, H, ks=1.0)
    rows = linear.face_pull(hexa.points, lambda d: mh.stiffness_matrix())
    k = np.array([r["stiffness"] for r in rows])
    assert np.ptp(k) < 1e-9 * k.mean() and max(r["drift"] for r in rows) < 1e-9
    tet = read_mesh(REF / "meshes/tetra/cube_333/cube.mesh")
    mt = build_massspring(tet.points, tet.cells["tetra"], ks=1.0)
    rows = linear.face_pull(tet.points, lambda d: mt.stiffness_matrix())
    k = np.array([r["stiffness"] for r in rows])
    assert np.ptp(k) > 0.01 * k.mean() and max(r["drift"] for r in rows) > 1e-3


@pytest.mark.slow
def test_fem_stage_calibration_never_worsens_G(tmp_path):
    """The FEM-scoring experiment end to end (solves the FEM reference: minutes uncached)."""
    from harness.case.reader import load_case
    from harness.stages import StageContext, bc2000

    case = load_case(ROOT / "cases/bourguignon2000/fem_cube333_tetra.toml")
    rows = bc2000.run(case, StageContext(out_dir=tmp_path))
    assert [r["model"] for r in rows] == ["MS", "MT0", "MT"]
    for r in rows:
        assert 0 < r["G_norm_initial"] < 1
        assert r["G_final"] <= r["G_initial"] * (1 + 1e-9)
    df = pd.read_csv(tmp_path / "anisotropy.csv")
    assert set(df.columns) >= {"angle", "model", "stiffness", "drift"}


def test_fem_stage_heldout_loads_are_not_fitted(tmp_path, monkeypatch):
    """Against the same reference, the case without its held-out loads fits exactly the
    same constants and G on the fitted loads; with them, G_heldout is reported. (The
    reference itself may refine further for the held-out loads: that is why it is shared.)"""
    import dataclasses

    import reference
    from harness.case.reader import load_case
    from harness.stages import StageContext, bc2000

    case = load_case(ROOT / "cases/bourguignon2000/fem_cube333_hexa.toml")
    assert case.heldout == ("sag", "tip")
    ref, solve = reference.solve(case), reference.solve

    def shared(c, *a, **k):  # the case's loads (or a subset): the one reference; pulls: their own
        return ref if {l.name for l in c.loads} <= set(ref.loads) else solve(c, *a, **k)

    monkeypatch.setattr(reference, "solve", shared)
    plain = dataclasses.replace(
        case, loads=tuple(l for l in case.loads if l.name not in case.heldout), heldout=()
    )
    with_held = bc2000.run(case, StageContext(out_dir=tmp_path / "a"))
    without = bc2000.run(plain, StageContext(out_dir=tmp_path / "b"))
    for a, b in zip(with_held, without):
        if "G_final" not in b:
            continue
        fits = [k for k in b if k.startswith("fit_")]
        assert fits and all(a[k] == pytest.approx(b[k], rel=1e-9) for k in fits)
        assert a["G_final"] == pytest.approx(b["G_final"], rel=1e-9)
        assert (
            np.isfinite(a["G_heldout"]) and np.isfinite(a["G_ref_heldout"]) and "G_heldout" not in b
        )
        # gravity is rho V shared by the nodes, as in the FEM (unit node masses gave G_heldout ~1.1)
        assert a["G_heldout"] < 0.3, a
