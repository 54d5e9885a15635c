"""springs+kn selected by a case ([model] kn, the class "springs+kn") and by ``calibrate
--model springs+kn``: node volumes tile the body, statics against a dense solve written
here, the stage's fitted rows re-scored by statics, bad values as one-line errors, and the
exported JSON (constants, node volumes, stable step against a dense eigen-solve of the
documented formula)."""

import json

import numpy as np
import pytest

from harness import cli
from harness.case.reader import load_case
from harness.errors import CaseError, ModelError
from harness.mechanics import statics
from harness.models.kn import KNTerm
from harness.models.sms import build_network, model_spec
from harness.registry import MODEL_CLASSES
from harness.stages.classes.springs import of_spec
from tests import meshes
from tests.models.springcases import TINY, ClosedFormRef, dense_K

BOX = (
    TINY.replace("dim = 2", "dim = 3")
    .replace('shape = "rectangle"\nsize = [2.0, 2.0]', 'shape = "box"\nsize = [2.0, 1.0, 1.0]')
    .replace("basic2d", "basic3d")
)


def _case(tmp_path, text, extra):
    f = tmp_path / "kn.toml"
    f.write_text(text.format(placement="grid", extra=extra))
    return load_case(f)


def _dense_kn_K(q, springs, nodes, V, kn):
    """sum_a kn_a c_a c_a^T, c_a = d sqrt(V_a) / N_a sum over a's springs (i, j) of
    (u_j - u_i) . n / L (the JSON's documented energy, linearised), spring by spring."""
    n, dim = q.shape
    K = np.zeros((n * dim, n * dim))
    for a, Va, ka in zip(nodes, V, kn):
        mine = [(i, j) for i, j in springs if a in (i, j)]
        c = np.zeros(n * dim)
        for i, j in mine:
            d = q[j] - q[i]
            L = np.linalg.norm(d)
            c[j * dim : (j + 1) * dim] += d / L**2
            c[i * dim : (i + 1) * dim] -= d / L**2
        c *= dim * np.sqrt(Va) / len(mine)
        K += ka * np.outer(c, c)
    return K


@pytest.mark.parametrize(
    "text, grid, size", [(TINY, "[3, 4]", 4.0), (BOX, "[3, 3, 3]", 2.0)], ids=["2d", "3d"]
)
def test_case_kn_term_and_statics_match_a_dense_solve(tmp_path, text, grid, size):
    case = _case(tmp_path, text, f"grid = {grid}")
    kn = MODEL_CLASSES.load("springs+kn")
    spec = kn.spec(model_spec(case))
    assert of_spec(spec) == kn  # the case's own keys name the same class
    net = kn.build(case, spec)
    t = net.volume
    assert isinstance(t, KNTerm) and t.shared and t.n_elements == net.n_nodes
    assert t.V.sum() == pytest.approx(size, rel=1e-12) and np.all(t.V > 0)
    assert np.all(t.kv == t.kv[0]) and t.kv[0] > 0
    res = statics.solve(net, case)
    K = dense_K(net.points, net.springs, net.k) + _dense_kn_K(
        net.points, net.springs, t.nodes, t.V, t.kv
    )
    for name in res.names:
        free, f = statics.load_arrays(net, case, next(l for l in case.loads if l.name == name))
        u = np.zeros(net.points.size)
        u[free] = np.linalg.solve(K[np.ix_(free, free)], f[free])
        assert np.allclose(
            res.displacement(name).ravel(), u, rtol=1e-9, atol=1e-12 * np.abs(u).max()
        )
    springs_only = statics.solve(build_network(case, model_spec(case)), case)
    assert not np.allclose(springs_only.u, res.u, rtol=1e-3)  # the term is not dropped


def test_stage_fits_springs_and_kn_and_rescores(tmp_path, monkeypatch):
    from harness.stages import StageContext
    from harness.stages import sms as stage

    case = _case(
        tmp_path,
        TINY.replace('method = "none"', 'method = "gauss-newton"'),
        'grid = [4, 4]\nclasses = ["springs", "springs+kn"]',
    )
    monkeypatch.setattr(stage, "_reference", lambda case, ctx: (ClosedFormRef(case), ""))
    rows = stage.run(case, StageContext(out_dir=tmp_path / "out"))
    fit = [r for r in rows if r["model_class"] == "springs+kn"][-1]
    assert fit["optimizer"] == "gauss-newton" and fit["kn"] == "shared" and fit["n_kn"] == 16
    assert "+kn-shared" in fit["model"]
    assert fit["n_params"] == fit["n_springs"] + 1  # one kn for the body
    assert fit["G_final"] < fit["G_initial"]
    # statics re-score = the fit's G
    assert fit["G_final"] == pytest.approx(fit["G_final_optimizer"], rel=1e-8)
    saved = np.load(tmp_path / "out" / "springs+kn" / "kn-deussen-gauss-newton.npz")
    assert saved["kv"].shape == (16,) and np.ptp(saved["kv"]) == 0


def test_bad_kn_keys_are_one_line_errors(tmp_path):
    with pytest.raises(CaseError) as exc:
        _case(tmp_path, TINY, 'grid = [3, 3]\nkn = "tets"')
    assert exc.value.field == "model.kn" and "\n" not in str(exc.value)
    case = _case(tmp_path, TINY, 'grid = [3, 3]\nkn = "shared"\nvolume = "shared"')
    with pytest.raises(ModelError) as exc:
        of_spec(model_spec(case)).build(case, model_spec(case))
    assert (
        exc.value.field == "model.kn"
        and "\n" not in str(exc.value)
        and exc.value.file.endswith("kn.toml")
    )


def test_calibrate_exports_the_kn_term(tmp_path):
    mesh, tets = meshes.grid_bar(tmp_path)
    out = tmp_path / "bar-kn.vtu"
    assert (
        cli.main(
            (
                ["calibrate", str(mesh), "--E", "1e5", "--nu", "0.45"]
                + ["--model", "springs+kn", "--method", "gauss-newton"]
                + ["--max-refine", "0", "--rule", "lloyd", "--loads", "homogeneous"]
                + ["--k-ratio", "100", "--out", str(out)]
            )
        )
        == 0
    )
    d = json.loads(out.with_suffix(".json").read_text())
    q, s = np.asarray(d["particle_q"]), np.asarray(d["spring_indices"])
    nodes, V, kn = (
        np.asarray(d["kn_nodes"]),
        np.asarray(d["kn_node_volume"]),
        np.asarray(d["kn_stiffness"]),
    )
    assert d["kn_shared"] is True and len(nodes) == len(q) and np.ptp(kn) == 0 and kn[0] > 0
    assert V.sum() == pytest.approx(3.0, rel=1e-12)
    assert np.array_equal(d["kn_spring_count"], np.bincount(s.ravel(), minlength=len(q))[nodes])
    assert "Pa" in d["units"]["kn_stiffness"]
    # dt_stable of springs (damped) + kn (undamped): a dense eigen-solve written here
    n = len(q)
    K, C = np.zeros((3 * n, 3 * n)), np.zeros((3 * n, 3 * n))
    for (i, j), k, kd in zip(s, d["spring_stiffness"], d["spring_damping"]):
        dd = (q[j] - q[i]) / np.linalg.norm(q[j] - q[i])
        for A, c in ((K, k), (C, kd)):
            for x, y, sign in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
                A[3 * x : 3 * x + 3, 3 * y : 3 * y + 3] += sign * c * np.outer(dd, dd)
    w = 1 / np.sqrt(np.repeat(d["particle_mass"], 3))
    springs_only = np.sqrt(np.linalg.eigvalsh(K * w[:, None] * w[None, :])[-1])
    K += _dense_kn_K(q, s, nodes, V, kn)
    lam, vec = np.linalg.eigh(K * w[:, None] * w[None, :])
    omega, v = np.sqrt(lam[-1]), vec[:, -1]
    zeta = v @ (C * w[:, None] * w[None, :]) @ v / (2 * omega)
    # the term counts: its share of omega_max is small (the top mode is a stiff spring's) but far
    # above 1e-9
    assert d["omega_max"] == pytest.approx(omega, rel=1e-9) and omega > (1 + 1e-7) * springs_only
    assert d["dt_stable"] == pytest.approx(2 / omega * (np.sqrt(1 + zeta**2) - zeta), rel=1e-6)
