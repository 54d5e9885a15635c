"""calibrate's row of the plain linear tetrahedra with the user's (E, nu) on the mesh ("your
engine's own body at this mesh"): its held-out errors against a P1 solve written here (its
own assembly from the shape-function gradients, the JSON's clamps and forces, the FEM's
displacements of MODEL-heldout.vtu), and never a candidate: with the lowest errors of all
rows it is neither exported nor the best rule of the verdict."""

from __future__ import annotations

import json

import meshio
import numpy as np
import pandas as pd
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from harness import cli
from harness.commands import calibrate_run
from tests import meshes

pytest.importorskip("gmsh")
E, NU = 1e5, 0.3
TETS = "tets[E, nu]"


@pytest.fixture(scope="module")
def cylinder(tmp_path_factory):
    return meshes.cylinder(tmp_path_factory.mktemp("cyl"))  # r 0.1, length 0.5 along x


def calibrate(mesh, out, capsys, *argv):
    code = cli.main(
        ["calibrate", str(mesh), "--E", str(E), "--nu", str(NU), "--out", str(out)]
        + ["--max-refine", "0", "--quiet", *argv]
    )
    captured = capsys.readouterr()
    assert code == 0, captured.err
    data = json.loads(out.with_suffix(".json").read_text())
    return captured.out, data, pd.read_csv(out.with_suffix(".csv"))


def p1_stiffness(x: np.ndarray, tets: np.ndarray) -> sp.csr_matrix:
    """Linear tetrahedra, isotropic (E, NU): K[a i, b j] = sum_e V_e (lambda g_ai g_bj +
    mu (g_aj g_bi + delta_ij g_a . g_b)), g_a the gradient of node a's shape function."""
    lam, mu = E * NU / ((1 + NU) * (1 - 2 * NU)), E / (2 * (1 + NU))
    A = np.concatenate([np.ones((len(tets), 4, 1)), x[tets]], axis=2)  # rows (1, x, y, z)
    inv = np.linalg.inv(A)  # column a: the coefficients of N_a
    g = np.transpose(inv[:, 1:, :], (0, 2, 1))  # (m, 4 nodes, 3)
    V = np.abs(np.linalg.det(A)) / 6
    eye = np.eye(3)
    Ke = V[:, None, None, None, None] * (
        lam * np.einsum("mai,mbj->maibj", g, g)
        + mu * np.einsum("maj,mbi->maibj", g, g)
        + mu * np.einsum("mak,mbk,ij->maibj", g, g, eye)
    )
    dof = tets[:, :, None] * 3 + np.arange(3)  # (m, 4, 3)
    r = np.broadcast_to(dof[:, :, :, None, None], Ke.shape)
    c = np.broadcast_to(dof[:, None, None, :, :], Ke.shape)
    n = 3 * len(x)
    return sp.csr_matrix((Ke.ravel(), (r.ravel(), c.ravel())), shape=(n, n))


def heldout_errors(out) -> dict:
    """{held-out load: ||u_p1 - u_fem|| / ||u_fem||} of the P1 solve here (weights 1:1:1)."""
    data = json.loads(out.with_suffix(".json").read_text())
    pic = meshio.read(out.with_name(out.stem + "-heldout.vtu"))
    x, tets = pic.points[:, :3], pic.cells_dict["tetra"]
    K = p1_stiffness(x, tets)
    errors = {}
    for name in data["loads_heldout"]:
        f = np.zeros_like(x)
        f[data["loaded_nodes"][name]] = data["forces"][name]
        held = np.zeros(x.shape, bool)
        clamp = data["clamped_nodes"][name]
        for node, comps in zip(clamp["nodes"], clamp["components"]):
            held[node, comps] = True
        free = ~held.ravel()
        u = np.zeros(x.size)
        u[free] = spla.spsolve(K[free][:, free].tocsc(), f.ravel()[free])
        u_fem = pic.point_data[f"u_fem/{name}"][:, :3]
        errors[name] = np.linalg.norm(u.reshape(-1, 3) - u_fem) / np.linalg.norm(u_fem)
    return errors


def test_tets_row_matches_a_p1_solve_written_here(cylinder, tmp_path, capsys):
    out = tmp_path / "m.vtu"
    said, data, df = calibrate(cylinder, out, capsys, "--method", "rule")
    row = df[df.model == TETS]
    assert len(row) == 1 and not row.exported.iloc[0] and row.stiffness.iloc[0] == "p1"
    row = row.iloc[0]
    errors = heldout_errors(out)
    mean = float(np.mean(list(errors.values())))
    assert row.G_heldout_mean == pytest.approx(mean, rel=1e-8)
    assert data["G_heldout_mean_tets"] == pytest.approx(mean, rel=1e-8)
    # the sentence says it, the table shows it, beside the rules and never marked exported
    assert f"at this mesh: {100 * mean:.3g} % held-out error" in said
    line = next(ln for ln in said.splitlines() if ln.lstrip().startswith(TETS))
    assert "*" not in line and "not-a-candidate" in line


def test_tets_row_equals_the_p1_global_rule_row(cylinder, tmp_path, capsys):
    """--model p1-global's rule row "p1" (the P1 class's own build and stage scoring) is
    the same body: the same errors; that calibration adds no row of its own."""
    _, _, df = calibrate(cylinder, tmp_path / "r.vtu", capsys, "--method", "rule")
    _, data, p1 = calibrate(cylinder, tmp_path / "g.vtu", capsys, "--model", "p1-global")
    tets = df[df.model == TETS].iloc[0]
    rule = p1[p1.optimizer == "none"].iloc[0]
    for col in ("G_norm_final", "G_fit_score", "G_heldout", "G_heldout_mean", "dt_stable"):
        assert tets[col] == pytest.approx(rule[col], rel=1e-8), col
    assert TETS not in set(p1.model) and data["G_heldout_mean_tets"] is None


@pytest.mark.parametrize("argv", [("--method", "rule"), ("--prior-weight", "1")])
def test_never_a_candidate_even_when_it_is_best(cylinder, tmp_path, capsys, monkeypatch, argv):
    """The tets row made the best on every score there is: the export, the best rule of the
    verdict and the fitted sentence's best rule stay the springs'."""
    made = calibrate_run.plain_tets_row

    def best(*a, **k):
        row = made(*a, **k)
        for col in list(row):
            if col.startswith(("G_heldout", "G_norm", "G_fit_score", "G_val_mean")):
                row[col] = 1e-9
        return row

    monkeypatch.setattr(calibrate_run, "plain_tets_row", best)
    said, data, df = calibrate(cylinder, tmp_path / "m.vtu", capsys, *argv)
    tets = df[df.model == TETS].iloc[0]
    assert tets.G_heldout_mean == pytest.approx(1e-9) and not tets.exported
    exported = df[df.exported].iloc[0]
    assert exported.model != TETS and exported.stiffness != "p1"
    springs = df[(df.optimizer == "none") & (df.model != TETS)]
    best_rule = springs.loc[springs.G_heldout_mean.idxmin()]
    assert data["best_rule_heldout"]["rule"] == best_rule.stiffness
    assert data["best_rule_heldout"]["G_heldout_mean"] == pytest.approx(best_rule.G_heldout_mean)
    assert data["G_heldout_mean_tets"] == pytest.approx(1e-9)
    assert "(p1)" not in said and ", p1," not in said
