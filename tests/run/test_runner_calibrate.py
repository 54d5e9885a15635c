"""springbench calibrate: a user's mesh -> calibrated network, exports with stated units."""

from __future__ import annotations

import json

import meshio
import numpy as np
import pytest

from harness import cli
from harness.export.vtu import read_vtu


@pytest.fixture
def tri_mesh(tmp_path):
    """A 2 x 1 rectangle, 4 x 2 squares split into triangles (counter-clockwise)."""
    x, y = np.meshgrid(np.linspace(0, 2, 5), np.linspace(0, 1, 3))
    p = np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]
    tris = []
    for j in range(2):
        for i in range(4):
            a, b, c, d = j * 5 + i, j * 5 + i + 1, (j + 1) * 5 + i + 1, (j + 1) * 5 + i
            tris += [[a, b, c], [a, c, d]]
    f = tmp_path / "plate.vtu"
    meshio.write(f, meshio.Mesh(p, [("triangle", np.array(tris))]))
    return f


def test_rule_export_matches_hand_computed_constants(tri_mesh, tmp_path, capsys):
    out = tmp_path / "m.vtu"
    E = 2.5e4
    assert (
        cli.main(
            (
                ["calibrate", str(tri_mesh), "--E", str(E), "--nu", "0.3"]
                + ["--method", "rule", "--rule", "deussen", "--out", str(out)]
                + ["--max-refine", "0"]
            )
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert "sms-mesh[deussen]" in printed and "held-out" in printed
    data = json.loads(out.with_suffix(".json").read_text())
    q = np.asarray(data["particle_q"])
    springs = np.asarray(data["spring_indices"])
    L = np.linalg.norm(q[springs[:, 1]] - q[springs[:, 0]], axis=1)
    # mesh edges: 4x3 horizontal + 5x2 vertical + 8 diagonals
    assert len(springs) == 12 + 10 + 8
    assert np.allclose(data["spring_rest_length"], L, rtol=1e-14)
    assert np.allclose(data["spring_stiffness"], E * L / 4, rtol=1e-12)  # Deussen: k = E s0 / 4
    assert np.allclose(data["spring_stiffness_times_length"], E * L**2 / 4, rtol=1e-12)
    net, _ = read_vtu(out)
    assert np.allclose(net.k, data["spring_stiffness"]) and net.n_nodes == 15
    # the moment-matched masses carry the body's mass (density 1000 kg/m^3, unit thickness)
    assert sum(data["particle_mass"]) == pytest.approx(1000 * 2 * 1, rel=1e-10)


@pytest.mark.slow
def test_lbfgs_improves_the_score(tri_mesh, tmp_path, capsys):
    out = tmp_path / "m.vtu"
    assert (
        cli.main(
            (
                ["calibrate", str(tri_mesh), "--E", "1e4", "--nu", "0.3"]
                + ["--method", "lbfgs", "--prior-weight", "0"]
                + ["--out", str(out), "--max-refine", "0"]
            )
        )
        == 0
    )  # a fit, not validated
    import pandas as pd

    df = pd.read_csv(out.with_suffix(".csv"))
    fit = df[df.optimizer == "lbfgs"].iloc[0]
    assert fit.G_final < 0.9 * fit.G_initial


def _calibrate(mesh, out, *argv):
    import pandas as pd

    assert (
        cli.main(
            (
                ["calibrate", str(mesh), "--E", "1e4", "--nu", "0.3", *argv]
                + ["--out", str(out), "--max-refine", "0"]
            )
        )
        == 0
    )
    return pd.read_csv(out.with_suffix(".csv")), json.loads(out.with_suffix(".json").read_text())


@pytest.mark.slow
def test_gauss_newton_from_the_equilibrium_gap_improves_the_score(tri_mesh, tmp_path):
    df, _ = _calibrate(
        tri_mesh, tmp_path / "m.vtu", "--method", "gauss-newton", "--init", "equilibrium-gap"
    )
    fit = df[df.optimizer == "gauss-newton"].iloc[0]
    assert fit.G_final < 0.9 * fit.G_initial
    assert (df.seed == 0).all() and isinstance(fit.opt_stop, str)  # the run is recorded


@pytest.mark.slow
def test_equilibrium_gap_improves_or_exports_the_rule_unchanged(tri_mesh, tmp_path):
    """The equation-error estimate is not min G for a FEM reference: it either lowers G or
    (when it is worse than the rule) falls back to the rule's constants, exactly those that
    ``--method rule`` exports."""
    df, data = _calibrate(
        tri_mesh, tmp_path / "m.vtu", "--method", "equilibrium-gap", "--rule", "lloyd"
    )
    _, rule = _calibrate(tri_mesh, tmp_path / "r.vtu", "--method", "rule", "--rule", "lloyd")
    fit = df[df.optimizer == "equilibrium-gap"].iloc[0]
    if fit.G_final == pytest.approx(fit.G_initial, rel=1e-12):
        assert np.array_equal(data["spring_stiffness"], rule["spring_stiffness"])
    else:
        assert fit.G_final < fit.G_initial
        assert not np.allclose(data["spring_stiffness"], rule["spring_stiffness"])


def test_init_needs_a_gradient_fit(tri_mesh, tmp_path, capsys):
    out = tmp_path / "m.vtu"
    assert (
        cli.main(
            (
                ["calibrate", str(tri_mesh), "--E", "1e4", "--nu", "0.3"]
                + ["--method", "sa", "--init", "equilibrium-gap", "--out", str(out)]
            )
        )
        == 2
    )
    err = capsys.readouterr().err
    assert "--init" in err and "gauss-newton" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


@pytest.mark.parametrize(
    "flags, expect",
    [
        (["--nu", "0.7"], "--nu: 0.7 is out of range"),
        (["--out", "model.txt"], "--out: 'model.txt' does not end in .vtu"),
        (["--budget", "0"], "--budget"),
    ],
)
def test_bad_flags_are_one_line(tri_mesh, tmp_path, capsys, flags, expect):
    argv = {"--E": "1e4", "--nu": "0.3", "--out": str(tmp_path / "m.vtu")}
    argv.update(dict(zip(flags[::2], flags[1::2])))
    code = cli.main(["calibrate", str(tri_mesh), *[x for kv in argv.items() for x in kv]])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and expect in err[0]


def test_bad_mesh_is_one_line_naming_the_mesh(tmp_path, capsys):
    from pathlib import Path

    bad = Path(__file__).resolve().parents[1] / "bad_inputs" / "meshes" / "tri_inverted.vtu"
    code = cli.main(
        ["calibrate", str(bad), "--E", "1", "--nu", "0.3", "--out", str(tmp_path / "m.vtu")]
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        code == 2
        and len(err) == 1
        and "tri_inverted.vtu" in err[0]
        and "inverted triangle" in err[0]
    )
