"""The learned stiffness rule (harness/models/learned_rule.py) and its fit
(``springbench rules fit``, harness/optimize/rule_fit.py)."""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from harness import cli
from harness.case.reader import Material
from harness.models import learned_rule as lr
from harness.models.stiffness_rules import spring_constants, vangelder
from harness.optimize import rule_fit as rules
from tests import meshes

CORPUS = Path(__file__).resolve().parents[2] / "cases" / "rules_corpus"


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    folder = tmp_path_factory.mktemp("learned")
    return {
        "cylinder": meshes.cylinder(folder),
        "ellipsoid": meshes.ellipsoid(folder),
        "holed_block": meshes.holed_block(folder),
        "ellipse": meshes.ellipse(folder, size=0.1),
    }


def _network(path):
    from harness.io.meshfile import read_mesh
    from harness.models.topology import element_pairs

    m = read_mesh(path)
    ctype = lr.SIMPLEX[m.dim]
    c = m.cells[ctype]
    pairs = np.sort(np.concatenate([c[:, [i, j]] for i, j in element_pairs(ctype)]), axis=1)
    return m.points, np.unique(pairs, axis=0), {ctype: c}


def test_zero_coefficients_are_van_gelder_and_the_shipped_ones_scale_it(made):
    pts, springs, cells = _network(made["cylinder"])
    mat = Material(E=2e5, nu=0.45, density=1.0)
    base = vangelder(pts, springs, cells, mat)
    p = len(lr.FEATURES[3])
    assert np.array_equal(lr.learned(pts, springs, cells, mat, base=base, coef=np.zeros(p)), base)
    k = spring_constants("learned", pts, springs, cells, mat)
    X = lr.design(lr.geometry(pts, springs, cells), mat.nu, 3)
    np.testing.assert_allclose(k, base * np.exp(X @ lr.coefficients(3)), rtol=1e-13)


def test_features_are_free_of_units_orientation_and_node_order(made):
    pts, springs, cells = _network(made["ellipsoid"])
    g = lr.geometry(pts, springs, cells)
    q, _ = np.linalg.qr(np.random.default_rng(1).standard_normal((3, 3)))
    perm = np.random.default_rng(2).permutation(len(pts))
    inv = np.argsort(perm)  # new index of old node i
    moved = (0.001 * pts @ q.T + 5.0)[perm]  # mm, rotated, shifted, renumbered
    cells2 = {k: inv[v][:, ::-1] for k, v in cells.items()}
    np.testing.assert_allclose(lr.geometry(moved, inv[springs][:, ::-1], cells2), g, atol=1e-10)
    # hand-checked values: a regular tetrahedron's edges, all on the surface, one cell each
    tet = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float)
    e = np.array([[i, j] for i in range(4) for j in range(i + 1, 4)])
    G = lr.geometry(tet, e, {"tetra": np.array([[0, 1, 2, 3]])})
    col = dict(zip(lr.FEATURES[3][len(lr.SCALE) :], range(G.shape[1])))
    np.testing.assert_allclose(G[:, col["log_length"]], 0, atol=1e-15)
    np.testing.assert_allclose(G[:, col["boundary"]], 1)
    np.testing.assert_allclose(G[:, col["log_cells"]], np.log(1 / lr.N_REG))
    np.testing.assert_allclose(G[:, col["dihedral"]], 0, atol=1e-14)
    np.testing.assert_allclose(G[:, col["log_quality"]], 0, atol=1e-12)


def test_the_adjoint_gradient_is_the_derivative(made):
    s = rules.sample(made["ellipse"], 0.35)
    c = np.random.default_rng(3).normal(0, 0.2, s.X.shape[1])
    for objective in rules.OBJECTIVES:
        J, g = rules.objective([s], c, objective)
        h = 1e-6
        fd = [
            (
                rules.objective([s], c + h * d, objective)[0]
                - rules.objective([s], c - h * d, objective)[0]
            )
            / (2 * h)
            for d in np.eye(len(c))
        ]
        np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-9)


def _planted(s, c):
    """The sample with its exact answers replaced by the network's under k0 exp(X c)."""
    k = s.k0 * lr.correction(s.X, c)
    groups = []
    for g in s.groups:
        U = spla.spsolve((g.B @ sp.diags(k) @ g.B.T).tocsc(), g.f.T).reshape(len(g.f.T), -1).T
        groups.append(
            dataclasses.replace(g, u=U, fixed2=np.zeros(len(U)), norm=np.linalg.norm(U, axis=1))
        )
    return dataclasses.replace(s, groups=tuple(groups))


def test_fit_recovers_planted_coefficients(made):
    """Answers made by a network with known c (at nu = NU0 the nu columns vanish): the fit
    from c = 0 finds c again."""
    s = rules.sample(made["ellipse"], lr.NU0)
    truth = np.array([0.2, 0.0, 0.0, -0.5, 0.3, -0.6, 0.4])
    planted = _planted(s, truth)
    # van Gelder is not the answer
    assert rules.objective([planted], np.zeros(len(truth)))[0] > 0.05
    res = rules.fit([planted], maxiter=300)
    assert res.after < 1e-5 * res.before
    np.testing.assert_allclose(res.coefficients, truth, atol=1e-3)


def test_shipped_coefficients_record_the_committed_corpus():
    data = json.loads(lr.COEFFICIENTS.read_text())
    files = {p.name: p for p in CORPUS.glob("*.vtu")}
    assert {c["file"] for c in data["corpus"]} == set(files)
    for c in data["corpus"]:
        assert c["sha256"] == hashlib.sha256(files[c["file"]].read_bytes()).hexdigest(), c["file"]
    for dim in (2, 3):
        d = data["dims"][str(dim)]
        assert (
            tuple(d["features"]) == lr.FEATURES[dim]
            and d["objective_after"] < d["objective_before"]
        )


@pytest.mark.slow
@pytest.mark.parametrize("name", ["cylinder", "ellipsoid", "holed_block"])
def test_the_shipped_rule_beats_van_gelder_on_tet_meshes_outside_its_corpus(made, name):
    """The linear states' closed forms on gmsh bodies the corpus does not hold, at nu 0.3
    and 0.45: the learned rule's mean error is below van Gelder's."""
    for nu in (0.3, 0.45):
        s = rules.sample(made[name], nu)
        c = lr.coefficients(3)
        before, after = rules.errors(s, np.zeros(len(c))), rules.errors(s, c)
        assert after.mean() < before.mean(), (nu, after.mean(), before.mean())


def test_rules_fit_command_writes_a_rule_calibrate_can_read(tmp_path, made, capsys):
    out = tmp_path / "rule.json"
    assert (
        cli.main(
            (
                ["rules", "fit", str(made["ellipse"]), "--nu", "0.3", "0.45"]
                + ["--maxiter", "5", "--out", str(out)]
            )
        )
        == 0
    )
    data = json.loads(out.read_text())
    c = lr.coefficients(2, out)
    assert (
        len(c) == len(lr.FEATURES[2])
        and data["dims"]["2"]["objective_after"] <= data["dims"]["2"]["objective_before"]
    )
    assert data["corpus"][0]["sha256"] == hashlib.sha256(made["ellipse"].read_bytes()).hexdigest()
    assert "van Gelder" in capsys.readouterr().out
    assert (
        cli.main(["rules", "fit", str(made["ellipse"]), "--nu", "0.3", "0.3", "--out", str(out)])
        == 2
    )
    assert "--nu" in capsys.readouterr().err
