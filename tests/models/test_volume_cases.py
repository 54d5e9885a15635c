"""Springs + volume selected by a case ([model] volume) and by ``calibrate --model``:
the volume elements tile the body, statics of the built model against a dense solve
written here, the stage's fitted rows re-scored by statics, bad values as one-line errors,
and the exported JSON (volume constants, rest volumes, node ids, stable step against a
dense eigen-solve)."""

import json

import numpy as np
import pytest

from harness import cli
from harness.case.reader import load_case
from harness.errors import CaseError
from harness.mechanics import statics
from harness.models.sms import build_network, model_spec
from harness.models.volume import case_volume, volume_gradients
from tests import meshes
from tests.models.springcases import TINY, ClosedFormRef, dense_K

BOX = (
    TINY.replace("dim = 2", "dim = 3")
    .replace('shape = "rectangle"\nsize = [2.0, 2.0]', 'shape = "box"\nsize = [2.0, 1.0, 1.0]')
    .replace("basic2d", "basic3d")
)


def _case(tmp_path, text, extra):
    f = tmp_path / "sv.toml"
    f.write_text(text.format(placement="grid", extra=extra))
    return load_case(f)


def _dense_volume_K(points, vol):
    """sum_e kv_e / V0_e g_e g_e^T, element by element."""
    dim = points.shape[1]
    K = np.zeros((points.size, points.size))
    g = volume_gradients(points, vol.elements)
    for e, nodes in enumerate(vol.elements):
        dofs = (nodes[:, None] * dim + np.arange(dim)).ravel()
        K[np.ix_(dofs, dofs)] += vol.kv[e] / vol.V0[e] * np.outer(g[e].ravel(), g[e].ravel())
    return K


@pytest.mark.parametrize("text, grid, size", [(TINY, "[3, 4]", 4.0), (BOX, "[3, 3, 3]", 2.0)])
def test_case_volume_term_tiles_the_body_and_statics_match_a_dense_solve(
    tmp_path, text, grid, size
):
    case = _case(tmp_path, text, f'grid = {grid}\nvolume = "element"\nkv = 7.0')
    spec = model_spec(case)
    net = case_volume(build_network(case, spec), case, spec)
    vol = net.volume
    assert vol.V0.sum() == pytest.approx(size, rel=1e-12) and np.all(vol.V0 > 0)
    assert np.all(vol.kv == 7.0) and net.params().shape == (net.n_springs + vol.n_elements,)
    res = statics.solve(net, case)
    K = dense_K(net.points, net.springs, net.k) + _dense_volume_K(net.points, vol)
    for name in res.names:
        free, f = statics.load_arrays(net, case, next(l for l in case.loads if l.name == name))
        u = np.zeros(net.points.size)
        u[free] = np.linalg.solve(K[np.ix_(free, free)], f[free])
        assert np.allclose(
            res.displacement(name).ravel(), u, rtol=1e-9, atol=1e-12 * np.abs(u).max()
        )
    # the volume term changes the answer (it is not silently dropped)
    springs_only = statics.solve(build_network(case, spec), case)
    assert not np.allclose(springs_only.u, res.u, rtol=1e-3)


def test_stage_fits_springs_and_volume_and_rescores(tmp_path, monkeypatch):
    from harness.stages import StageContext
    from harness.stages import sms as stage

    case = _case(
        tmp_path,
        TINY.replace('method = "none"', 'method = "gauss-newton"'),
        'grid = [4, 4]\nvolume = "shared"',
    )
    monkeypatch.setattr(stage, "_reference", lambda case, ctx: (ClosedFormRef(case), ""))
    rows = stage.run(case, StageContext(out_dir=tmp_path / "out"))
    fit = rows[-1]
    assert (
        fit["optimizer"] == "gauss-newton" and fit["volume"] == "shared" and fit["n_volumes"] == 18
    )
    assert "+volume-shared" in fit["model"]
    assert fit["n_params"] == fit["n_springs"] + 1  # one kv for the body
    assert fit["G_final"] < fit["G_initial"]
    # statics re-score = the fit's G
    assert fit["G_final"] == pytest.approx(fit["G_final_optimizer"], rel=1e-8)
    saved = np.load(tmp_path / "out" / "volume-deussen-gauss-newton.npz")
    assert saved["kv"].shape == (18,) and np.ptp(saved["kv"]) == 0


@pytest.mark.parametrize(
    "extra, field",
    [('volume = "tets"', "model.volume"), ('volume = "element"\nkv = -1.0', "model.kv")],
)
def test_bad_volume_keys_are_one_line_errors(tmp_path, extra, field):
    with pytest.raises(CaseError) as exc:
        _case(tmp_path, TINY, f"grid = [3, 3]\n{extra}")
    assert exc.value.field == field and "\n" not in str(exc.value)


def test_calibrate_exports_the_volume_term(tmp_path):
    mesh, tets = meshes.grid_bar(tmp_path)
    out = tmp_path / "bar-sv.vtu"
    assert (
        cli.main(
            (
                ["calibrate", str(mesh), "--E", "1e5", "--nu", "0.45"]
                + ["--model", "springs+volume-element", "--method", "gauss-newton"]
                + ["--max-refine", "0", "--rule", "lloyd", "--out", str(out)]
            )
        )
        == 0
    )
    d = json.loads(out.with_suffix(".json").read_text())
    el = np.asarray(d["volume_indices"])
    V0, kv = np.asarray(d["volume_rest"]), np.asarray(d["volume_stiffness"])
    q = np.asarray(d["particle_q"])
    assert (
        el.shape == (len(tets), 4)
        and len(V0) == len(kv) == len(tets)
        and d["volume_shared"] is False
    )
    a = q[el[:, 1:]] - q[el[:, :1]]
    assert np.allclose(np.linalg.det(a) / 6, V0, rtol=1e-12)  # ordered so V0 > 0
    assert V0.sum() == pytest.approx(3.0, rel=1e-12) and np.all(kv > 0)
    assert "Pa" in d["units"]["volume_stiffness"]
    # dt_stable of springs (damped) + volume (undamped): a dense eigen-solve written here
    s = np.asarray(d["spring_indices"])
    n = len(q)
    K, C = np.zeros((3 * n, 3 * n)), np.zeros((3 * n, 3 * n))
    for (i, j), k, kd in zip(s, d["spring_stiffness"], d["spring_damping"]):
        dd = (q[j] - q[i]) / np.linalg.norm(q[j] - q[i])
        for A, c in ((K, k), (C, kd)):
            for x, y, sign in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
                A[3 * x : 3 * x + 3, 3 * y : 3 * y + 3] += sign * c * np.outer(dd, dd)
    from types import SimpleNamespace

    w = 1 / np.sqrt(np.repeat(d["particle_mass"], 3))
    springs_only = np.sqrt(np.linalg.eigvalsh(K * w[:, None] * w[None, :])[-1])
    K += _dense_volume_K(q, SimpleNamespace(elements=el, V0=V0, kv=kv))
    lam, vec = np.linalg.eigh(K * w[:, None] * w[None, :])
    omega, v = np.sqrt(lam[-1]), vec[:, -1]
    zeta = v @ (C * w[:, None] * w[None, :]) @ v / (2 * omega)
    # the term counts: it moves omega_max by far more than the 1e-6 the match resolves
    assert d["omega_max"] == pytest.approx(omega, rel=1e-6) and omega > 1.0005 * springs_only
    assert d["dt_stable"] == pytest.approx(2 / omega * (np.sqrt(1 + zeta**2) - zeta), rel=1e-6)
