"""springbench calibrate on meshes users bring: a cylinder, an ellipsoid, a
holed block, a holed plate, nu up to 0.49, a mesh in millimetres. Each exports positive
masses carrying rho V, damping and a stable step an explicit engine can use (checked
against a dense eigen-solve written here), and a finite held-out G."""

import json

import numpy as np
import pandas as pd
import pytest

from harness import cli
from harness.case.linear_states import gradient_states
from harness.case.loadsets import VOIGT
from tests import meshes

pytest.importorskip("gmsh")
RHO = 1000.0


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    d = tmp_path_factory.mktemp("meshes")
    return {
        "cylinder": meshes.cylinder(d),
        "ellipsoid": meshes.ellipsoid(d),
        "holed_block": meshes.holed_block(d),
        "holed_plate": meshes.holed_plate(d),
        "cylinder_mm": meshes.cylinder(d, scale=1000.0, name="cylinder_mm.vtu"),
    }


def calibrate(mesh, out, *argv, refine="0"):
    code = cli.main(
        (
            ["calibrate", str(mesh), "--E", "1e5", "--density", str(RHO)]
            + ["--out", str(out), "--max-refine", refine, *argv]
        )
    )
    assert code == 0
    return json.loads(out.with_suffix(".json").read_text()), pd.read_csv(out.with_suffix(".csv"))


def volume(q, springs, dim, mesh):
    import meshio

    m = meshio.read(mesh)
    cells = m.cells_dict["tetra" if dim == 3 else "triangle"]
    p = m.points[:, :dim][cells]
    e = p[:, 1:] - p[:, :1]
    return float(np.abs(np.linalg.det(e)).sum() / (6 if dim == 3 else 2))


def dense_step(data):
    """dt = 2/omega_max (sqrt(1 + zeta^2) - zeta) from a dense K, C and M assembled here
    (with a volume or kn term, K from the held-out judge's own statics)."""
    dim = data["dim"]
    q = np.asarray(data["particle_q"])[:, :dim]
    s = np.asarray(data["spring_indices"])
    n = len(q)
    K, C = np.zeros((n * dim, n * dim)), np.zeros((n * dim, n * dim))
    for (i, j), k, kd in zip(s, data["spring_stiffness"], data["spring_damping"]):
        d = (q[j] - q[i]) / np.linalg.norm(q[j] - q[i])
        blk = np.outer(d, d)
        for A, c in ((K, k), (C, kd)):
            for a, b, sign in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
                A[a * dim : (a + 1) * dim, b * dim : (b + 1) * dim] += sign * c * blk
    if {"volume_indices", "node_volume_elements", "kn_nodes"} & set(data):
        # a volume or kn term: its stiffness from the held-out judge's statics (written
        # without the models' code; springs and terms together, 3-D)
        from harness.bench.heldout_judge import network_stiffness

        assert dim == 3
        K = network_stiffness(data).toarray()
    m = np.repeat(data["particle_mass"], dim)
    w = 1 / np.sqrt(m)
    lam, vec = np.linalg.eigh(K * w[:, None] * w[None, :])
    omega, v = np.sqrt(lam[-1]), vec[:, -1]
    zeta = v @ (C * w[:, None] * w[None, :]) @ v / (2 * omega)
    return 2 / omega * (np.sqrt(1 + zeta**2) - zeta)


@pytest.mark.slow
@pytest.mark.parametrize(
    "name,nu,method",
    [
        ("cylinder", 0.45, "lbfgs"),
        ("ellipsoid", 0.49, "rule"),
        ("holed_block", 0.3, "rule"),
        ("holed_plate", 0.45, "rule"),
    ],
)
def test_calibrate_exports_a_runnable_model(tmp_path, made, capsys, name, nu, method):
    data, df = calibrate(
        made[name],
        tmp_path / "m.vtu",
        "--nu",
        str(nu),
        "--method",
        method,
        refine="1" if method == "lbfgs" else "0",
    )
    printed = capsys.readouterr().out
    dim = data["dim"]
    mass = np.asarray(data["particle_mass"])
    assert mass.min() > 0
    assert mass.sum() == pytest.approx(
        RHO * volume(data["particle_q"], data["spring_indices"], dim, made[name]), rel=1e-10
    )
    assert data["loads_heldout"] == (
        ["sag", "tip", "tip2", "torsion", "bridge"] if dim == 3 else ["sag", "tip", "bridge"]
    )
    # the linear states (linear3d / 2d), then the clamped training states
    # a training state the FEM cannot resolve is left out and named (never both)
    fitted, dropped = data["loads_fitted"], data["training_dropped"]
    assert not set(fitted) & set(dropped)
    clamped = ["train-tip", "train-tip2", "train-torsion"] if dim == 3 else ["train-tip"]
    clamped += [
        f"train-{b}-{c}"
        for b in "xyz"[:dim]
        for c in "xyz"[:dim]
        if b != c and f"train-{b}-{c}" in fitted + dropped
    ]
    assert len(clamped) == (7 if dim == 3 else 2)  # the end states, then the sides
    clamped = [n for n in clamped if n not in dropped]
    assert len(fitted) == len(VOIGT[dim]) + len(gradient_states(dim)) + len(clamped)
    assert fitted[len(fitted) - len(clamped) :] == clamped
    per = data["G_heldout_loads"]
    assert list(per) == data["loads_heldout"] and data["G_heldout_mean"] == pytest.approx(
        np.mean(list(per.values()))
    )
    # pooled: a weighted mean of them
    assert min(per.values()) <= data["G_norm_heldout"] <= max(per.values())
    assert np.isfinite(data["G_norm_heldout"]) and np.isfinite(data["G_norm"])
    if method == "lbfgs":  # one refinement: the FEM's estimate of its own error (none without)
        assert 0 < data["reference_error_heldout"] < 0.1 and 0 < data["reference_error_fitted"] < 1
        assert data["reference_error"] == max(
            data["reference_error_heldout"], data["reference_error_fitted"]
        )
        assert (
            f"FEM error <= {100 * data['reference_error_heldout']:.3g} % on held-out loads"
            in printed
            or data["reference_error_heldout"] >= data["reference_error_fitted"]
        )
    assert data["E"] == 1e5 and data["nu"] == nu and data["density"] == RHO
    # damping: 2 zeta sqrt(k mu) per spring; the stable step from a dense eigen-solve
    s = np.asarray(data["spring_indices"])
    mu = mass[s[:, 0]] * mass[s[:, 1]] / (mass[s[:, 0]] + mass[s[:, 1]])
    np.testing.assert_allclose(
        data["spring_damping"], 0.1 * np.sqrt(np.asarray(data["spring_stiffness"]) * mu), rtol=1e-12
    )
    assert data["dt_stable"] == pytest.approx(dense_step(data), rel=1e-6)
    assert data["dt_stable_float32"] < data["dt_stable"]
    exported = df[df.exported].iloc[0]
    assert exported.G_norm_final == pytest.approx(data["G_norm"], rel=1e-12)
    assert "Held-out loads (sag, tip, " in printed and "the best rule (" in printed
    assert ("FEM error <=" if method == "lbfgs" else "FEM error not estimated") in printed
    if method == "lbfgs":
        assert exported.optimizer == "lbfgs" and exported.G_norm_final < df.iloc[0].G_norm_initial


def test_rule_prints_and_exports_the_same_constants(tmp_path, made, capsys):
    """--method rule: the exported row is the rule asked for (not the last one tried), and
    the printed verdict quotes its G."""
    data, df = calibrate(
        made["cylinder"], tmp_path / "m.vtu", "--nu", "0.3", "--method", "rule", "--rule", "deussen"
    )
    printed = capsys.readouterr().out
    row = df[df.exported].iloc[0]
    assert row.stiffness == "deussen" and row.G_norm_final == pytest.approx(
        data["G_norm"], rel=1e-12
    )
    assert f"RMS displacement error {100 * data['G_norm']:.3g} %" in printed
    L = np.asarray(data["spring_rest_length"])
    # Deussen: k = E s0 / 4
    np.testing.assert_allclose(data["spring_stiffness"], 1e5 * L / 4, rtol=1e-12)


def test_every_rule_of_the_harness_is_a_row_and_can_be_exported(tmp_path, made):
    """--rule cauchy exports the harness's cauchy constants for the mesh; every rule is a
    row of the table."""
    from harness.case.reader import Material
    from harness.io.meshfile import read_mesh
    from harness.models.stiffness_rules import RULES, spring_constants

    data, df = calibrate(
        made["cylinder"], tmp_path / "m.vtu", "--nu", "0.3", "--method", "rule", "--rule", "cauchy"
    )
    rules = df[df.optimizer == "none"]  # not the plain tets row (never a candidate)
    assert set(rules.stiffness) == set(RULES) and df[df.exported].iloc[0].stiffness == "cauchy"
    assert set(df.stiffness) - set(RULES) == {"p1"}
    m = read_mesh(made["cylinder"])
    springs = np.asarray(data["spring_indices"])
    k = spring_constants("cauchy", m.points, springs, m.cells, Material(1e5, 0.3))
    np.testing.assert_allclose(data["spring_stiffness"], k, rtol=1e-12)


def test_a_mesh_in_millimetres_gives_the_same_model(tmp_path, made):
    a, _ = calibrate(made["cylinder"], tmp_path / "m.vtu", "--nu", "0.3", "--method", "rule")
    b, _ = calibrate(
        made["cylinder_mm"],
        tmp_path / "mm.vtu",
        "--nu",
        "0.3",
        "--method",
        "rule",
        "--length-unit",
        "mm",
    )
    for key in ("particle_q", "particle_mass", "spring_stiffness", "spring_damping"):
        np.testing.assert_allclose(b[key], a[key], rtol=1e-9, atol=1e-12 * np.abs(a[key]).max())
    assert b["G_norm"] == pytest.approx(a["G_norm"], rel=1e-6)
    assert b["dt_stable"] == pytest.approx(a["dt_stable"], rel=1e-6)


def test_moment_masses_are_flagged_not_silently_exported(tmp_path, made):
    data, _ = calibrate(
        made["holed_block"],
        tmp_path / "m.vtu",
        "--nu",
        "0.3",
        "--method",
        "rule",
        "--masses",
        "moments",
    )
    assert min(data["particle_mass"]) < 0 and "warning" in data and data["dt_stable"] is None


def test_a_body_in_two_pieces_is_one_line_naming_the_mesh(tmp_path, made, capsys):
    import meshio

    m = meshio.read(made["cylinder"])
    p, c = m.points, m.cells_dict["tetra"]
    two = tmp_path / "two.vtu"
    meshio.write(
        two, meshio.Mesh(np.vstack([p, p + [2.0, 0, 0]]), [("tetra", np.vstack([c, c + len(p)]))])
    )
    code = cli.main(
        ["calibrate", str(two), "--E", "1e5", "--nu", "0.3", "--out", str(tmp_path / "o.vtu")]
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        code == 2
        and "two.vtu" in err[-1]
        and "disconnected" in err[-1]
        and "springbench-calibrate" not in err[-1]
    )


def test_k_ratio_caps_the_spread_and_shows_its_price(tmp_path, made):
    # vangelder: a rule whose constants spread (uniform's, which may rank first, do not)
    rule = ("--method", "rule", "--rule", "vangelder")
    free, _ = calibrate(made["holed_block"], tmp_path / "a.vtu", "--nu", "0.3", *rule)
    data, df = calibrate(
        made["holed_block"],
        tmp_path / "b.vtu",
        "--nu",
        "0.3",
        *rule,
        "--k-ratio",
        "1.5",
    )
    k = np.asarray(data["spring_stiffness"])
    assert k.max() / np.median(k) == pytest.approx(1.5, rel=1e-12)
    k0 = np.asarray(free["spring_stiffness"])
    np.testing.assert_array_equal(k, np.minimum(k0, 1.5 * np.median(k0)))
    assert data["dt_stable"] > free["dt_stable"]
    capped, plain = (
        df[df.exported].iloc[0],
        df[(df.optimizer == "none") & df.dt_stable.notna()].iloc[0],
    )
    assert capped.optimizer == "none+k-ratio 1.5" and capped.G_norm_final == pytest.approx(
        data["G_norm"], rel=1e-12
    )
    assert (
        capped.dt_stable == pytest.approx(data["dt_stable"], rel=1e-9)
        and plain.dt_stable < capped.dt_stable
    )


def test_help_names_every_output(tmp_path, made, capsys):
    data, df = calibrate(made["holed_plate"], tmp_path / "m.vtu", "--nu", "0.3", "--method", "rule")
    capsys.readouterr()
    with pytest.raises(SystemExit):
        cli.main(["calibrate", "--help"])
    text = capsys.readouterr().out
    missing = [key for key in list(data) + list(df.columns) if key not in text and key != "dim"]
    assert not missing, missing
