"""Model class "p1" with a fitted material per element (harness/stages/classes/p1_element.py).
Its adjoint gradient equals central differences of its misfit; on a synthetic truth solved
here with the P1 network of a known two-region material (harness/models/p1.py, statics) the
per-element fit recovers the regions where the one fitted pair of p1-global cannot, and never
leaves the box of the case's stiffness and compressibility; with no
information in the data the prior returns every element to the case's (E, nu); calibrate
--model p1 writes one material per tetrahedron (V0 > 0) that is the network's own."""

import json
import math

import numpy as np
import pytest

from harness.case.elasticity import isotropic
from harness.export.model_json import export
from harness.mechanics import statics
from harness.models.sms import model_spec
from harness.registry import MODEL_CLASSES
from harness.scoring import node_weights
from harness.stages.classes import p1_element as pe
from harness.stages.classes import p1_global as pg
from tests import meshes

E, NU = 1e5, 0.45
BODY = dict(length=0.3, size=0.2)  # a short coarse cylinder: 210 tetrahedra


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    """calibrate's in-memory case of a coarse gmsh cylinder (nu 0.45, validation loads, no
    reference refinement), its model class p1."""
    pytest.importorskip("gmsh")
    from harness.case.default_loads import end_loads
    from harness.case.reader import case_of
    from harness.commands.calibrate_case import case_table, regions
    from harness.commands.calibrate_settings import Settings
    from harness.io.meshfile import read_mesh

    tmp = tmp_path_factory.mktemp("p1e")
    mesh = meshes.cylinder(tmp, **BODY)
    s = Settings(mesh, E, NU, tmp / "m.vtu", rule="lloyd", max_refine=0, model="p1")
    m = read_mesh(mesh)
    table = case_table(s, 3, m.cells, mesh, end_loads(m.points, m.cells, *regions(s, m), m.groups))
    assert table["model"]["classes"] == ["p1"] and table["loads"]["validation"]
    return case_of(table, mesh, material=isotropic(E, NU, 1000.0, "stress"))


@pytest.fixture(scope="module")
def base(case):
    cls = MODEL_CLASSES.load("p1")
    return cls.build(case, cls.spec(model_spec(case)))


def _regions(base):
    """A two-region truth: E 2E, nu 0.3 on the half x < L/2, E/2, nu 0.4 on the other."""
    c = base.points[base.volume.elements].mean(axis=1)[:, 0]
    left = c < 0.5 * (base.points[:, 0].min() + base.points[:, 0].max())
    return np.where(left, 2 * E, 0.5 * E), np.where(left, 0.3, 0.4)


def _synthetic(case, base, E_t, nu_t, w_nodes=None):
    """The fitted loads' arrays with the P1 network of (E_t, nu_t) per element as their
    'reference' (solved by harness.mechanics.statics, not by the fit's own assembly)."""
    truth = pe.with_elements(base, E_t, nu_t)
    res = statics.solve(truth, case, loads=case.fit_loads)
    _, free, forces = statics.all_load_arrays(base, case)
    fit = [[ld.name for ld in case.loads].index(n) for n in res.names]
    w = node_weights(base.classes, (1.0, 1.0, 1.0)) if w_nodes is None else w_nodes
    return pg.Training.of(free[fit], forces[fit], res.u, w)


def _split(base):
    return pe.ElementSplit.of(base.points, base.volume.elements)


def test_the_adjoint_gradient_is_the_misfits_derivative(case, base):
    t = _synthetic(case, base, *_regions(base))
    split = _split(base)
    m = len(split.V)
    rng = np.random.default_rng(0)
    centre = np.repeat(pe.theta_of(E, NU, split.plane_stress), m)
    theta = centre + 0.2 * rng.standard_normal(2 * m)
    _, g = pe.misfit(split, t, theta)
    h = 1e-5
    for j in [*rng.choice(m, 4, replace=False), *(m + rng.choice(m, 4, replace=False))]:
        d = np.zeros(2 * m)
        d[j] = h
        fd = (pe.misfit(split, t, theta + d)[0] - pe.misfit(split, t, theta - d)[0]) / (2 * h)
        assert abs(g[j] - fd) <= 1e-5 * np.abs(g).max(), (j, g[j], fd)
    d = rng.standard_normal(2 * m)
    fd = (pe.misfit(split, t, theta + h * d)[0] - pe.misfit(split, t, theta - h * d)[0]) / (2 * h)
    assert g @ d == pytest.approx(fd, rel=1e-6)


def test_the_stiffness_is_the_networks(base):
    """K(a_e, mu_e) of the fit's assembly equals the stiffness of the network it exports."""
    E_t, nu_t = _regions(base)
    split = _split(base)
    a, mu = pg.coefficients(E_t, nu_t, False)
    K = split.stiffness(a, mu)
    net = pe.with_elements(base, E_t, nu_t)
    ref = net.volume.stiffness_matrix(net.points)
    assert abs(K - ref).max() <= 1e-10 * abs(ref).max()


def test_two_regions_are_recovered_per_element_and_not_by_one_pair(case, base):
    E_t, nu_t = _regions(base)
    t = _synthetic(case, base, E_t, nu_t)
    split = _split(base)
    fit = pe.fit_elements(split, t, E, NU, pe.PRIOR_WEIGHT)
    pair = pg.fit_pair(pg.lame_split(base.points, base.volume.elements), t, E, NU)
    v = split.V / split.V.sum()
    err = float(v @ np.abs(np.log(fit.E / E_t)))  # volume-weighted mean |log E' / E|
    err_pair = float(v @ np.abs(np.log(pair.E / E_t)))
    print(fit.misfit_initial, fit.misfit_final, pair.misfit_final, err, err_pair, fit.nit)
    assert fit.misfit_final < 0.1 * pair.misfit_final
    assert err < 0.25 * err_pair
    left = E_t > E
    assert np.median(fit.E[left]) > 1.5 * E > 0.75 * E > np.median(fit.E[~left])


def test_no_element_is_stiffer_or_nearer_incompressible_than_the_case(case, base):
    """A truth four times stiffer on one half and at nu = 0.49 on the other pulls the fit out
    of the box M_e <= M, nu_e <= nu (the case's): it stops on the box's faces."""
    c = base.points[base.volume.elements].mean(axis=1)[:, 0]
    left = c < 0.5 * (base.points[:, 0].min() + base.points[:, 0].max())
    t = _synthetic(case, base, np.where(left, 4 * E, E), np.where(left, NU, 0.49))
    fit = pe.fit_elements(_split(base), t, E, NU, pe.PRIOR_WEIGHT)
    a, mu = pg.coefficients(fit.E, fit.nu, False)
    a0, mu0 = pg.coefficients(E, NU, False)
    M, M0 = a + 2 * mu, a0 + 2 * mu0
    print(M.max() / M0, fit.nu.max())
    assert M.max() <= M0 * (1 + 1e-9) and fit.nu.max() <= NU + 1e-9
    assert M[left].max() > 0.999 * M0 and fit.nu[~left].max() > NU - 1e-6


def test_with_no_information_the_prior_returns_every_element_to_the_case(case, base):
    """Zero node weights: the data term is 0 whatever the material; from p1-global-like
    start (2E, 0.3) the fit goes back to (E, nu) on every element."""
    t = _synthetic(case, base, *_regions(base), w_nodes=np.zeros(base.n_nodes))
    assert not t.w.any()
    fit = pe.fit_elements(_split(base), t, E, NU, pe.PRIOR_WEIGHT, start=(2 * E, 0.3))
    assert np.abs(fit.E / E - 1).max() < 1e-4 and np.abs(fit.nu - NU).max() < 1e-4, (
        fit.E.min(),
        fit.E.max(),
        fit.nu.min(),
        fit.nu.max(),
    )


def test_the_export_writes_each_elements_material(base, tmp_path):
    """MODEL.json's tet_k_mu, tet_k_lambda per tetrahedron give back each element's elastic
    tensor in the network (its Cholesky factors), 3-D Voigt: D = lambda m m^T + mu diag(2, 2,
    2, 1, 1, 1); E_effective null when the elements differ, the pair when they share it."""
    E_t, nu_t = _regions(base)
    net = pe.with_elements(base, E_t, nu_t)
    data = export(net, tmp_path / "m.vtu")
    mu = 0.75 * np.asarray(data["tet_k_mu"])
    lam = np.asarray(data["tet_k_lambda"]) - 5 / 6 * mu
    m = np.r_[np.ones(3), np.zeros(3)]
    D = lam[:, None, None] * np.outer(m, m) + mu[:, None, None] * np.diag([2.0] * 3 + [1.0] * 3)
    L = net.volume.L
    assert np.abs(D - L @ np.transpose(L, (0, 2, 1))).max() <= 1e-9 * np.abs(D).max()
    assert data["tet_E"] == E_t.tolist() and data["tet_nu"] == nu_t.tolist()
    assert data["E_effective"] is None and data["nu_effective"] is None
    one = export(
        pe.with_elements(base, np.full(len(E_t), E), np.full(len(E_t), NU)), tmp_path / "o.vtu"
    )
    assert (one["E_effective"], one["nu_effective"]) == (E, NU)


def _volumes(points, tets):
    p = np.asarray(points)[np.asarray(tets)]
    return np.linalg.det(p[:, 1:] - p[:, :1]) / 6


def test_calibrate_exports_a_material_per_tetrahedron(tmp_path, monkeypatch):
    """``calibrate --model p1``: tet_indices with V0 > 0, per tetrahedron E, nu and Newton's
    k_mu = 4/3 mu, k_lambda = lambda + 5/6 mu of them (Lame constants written here); the
    fitted materials differ from element to element, so E_effective is null; the CSV's
    exported row is the validated fit."""
    import pandas as pd

    from harness import cli

    pytest.importorskip("gmsh")
    monkeypatch.setenv("SPRINGBENCH_CACHE", str(tmp_path / "cache"))
    mesh, out = meshes.cylinder(tmp_path, **BODY), tmp_path / "m.vtu"
    args = ["calibrate", str(mesh), "--E", str(E), "--nu", str(NU), "--model", "p1"]
    assert cli.main([*args, "--max-refine", "0", "--quiet", "--out", str(out)]) == 0
    data = json.loads(out.with_suffix(".json").read_text())
    row = pd.read_csv(out.with_suffix(".csv")).query("exported").iloc[0]
    tets = np.asarray(data["tet_indices"])
    q = np.asarray(data["particle_q"])
    assert tets.shape[1] == 4 and (_volumes(q, tets) > 0).all()
    E_, nu_ = np.asarray(data["tet_E"]), np.asarray(data["tet_nu"])
    assert len(E_) == len(nu_) == len(tets) and ((nu_ >= 0) & (nu_ <= 0.499)).all()
    mu, lam = E_ / (2 * (1 + nu_)), E_ * nu_ / ((1 + nu_) * (1 - 2 * nu_))
    assert np.allclose(data["tet_k_mu"], 4 / 3 * mu, rtol=1e-12)
    assert np.allclose(data["tet_k_lambda"], lam + 5 / 6 * mu, rtol=1e-12)
    assert data["choice"] == row["choice"] == "fit" and data["validation_accepted"] is True
    assert E_.max() > 1.01 * E_.min() and data["E_effective"] is None
    assert row["G_norm_final"] < row["G_norm_initial"]
    assert data["prior_weight"] == pe.PRIOR_WEIGHT
    print(row["G_norm_initial"], row["G_norm_final"], row["G_heldout_mean"], E_.min(), E_.max())
    assert not math.isnan(row["G_val_mean"])
