"""Model class "p1-global" (harness/stages/classes/p1_global.py): one effective (E', nu')
for P1 on the model's cells. Its K(E', nu') equals scikit-fem's P1 elasticity on the same
tetrahedra; its fit recovers a known pair from a synthetic truth solved here with the plain
P1 of harness/models/p1.py; with nu' held at the case's value (the broken variant) it
cannot; on a gmsh cylinder at nu 0.45 against the FEM it beats the plain P1 on the training
states."""

import math

import numpy as np
import pytest
import skfem
from skfem.models.elasticity import lame_parameters, linear_elasticity

from harness.case.elasticity import isotropic
from harness.mechanics import statics
from harness.models.p1 import with_p1
from harness.models.sms import build_network, model_spec
from harness.scoring import node_weights
from harness.stages.classes import p1_global as pg
from tests import meshes

E, NU = 1e5, 0.45
E0, NU0 = 2 * E, 0.3  # the synthetic truth's pair


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    """calibrate's in-memory case of a gmsh cylinder (nu 0.45, validation loads, no
    reference refinement), its model class p1-global."""
    pytest.importorskip("gmsh")
    from harness.case.default_loads import end_loads
    from harness.case.reader import case_of
    from harness.commands.calibrate_case import case_table, regions
    from harness.commands.calibrate_settings import Settings
    from harness.io.meshfile import read_mesh

    tmp = tmp_path_factory.mktemp("p1g")
    mesh = meshes.cylinder(tmp)
    s = Settings(mesh, E, NU, tmp / "m.vtu", rule="lloyd", max_refine=0, model="p1-global")
    m = read_mesh(mesh)
    table = case_table(s, 3, m.cells, mesh, end_loads(m.points, m.cells, *regions(s, m), m.groups))
    assert table["model"]["classes"] == ["p1-global"] and table["loads"]["validation"]
    return case_of(table, mesh, material=isotropic(E, NU, 1000.0, "stress"))


@pytest.fixture(scope="module")
def base(case):
    cls = pg.P1_GLOBAL
    return cls.build(case, cls.spec(model_spec(case)))


def _skfem_K(base, E_, nu_):
    """scikit-fem's P1 linear elasticity on the model's tetrahedra, in node-major dofs."""
    mesh = skfem.MeshTet(base.points.T, base.volume.elements.T)
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementTetP1()))
    K = skfem.asm(linear_elasticity(*lame_parameters(E_, nu_)), basis).tocsr()
    perm = basis.nodal_dofs.T.ravel()  # node i's dofs (x, y, z)
    return K[perm][:, perm]


def test_the_lame_split_is_p1_elasticity(base):
    split = pg.lame_split(base.points, base.volume.elements)
    for E_, nu_ in [(E, NU), (E0, NU0), (3.7e4, 0.05)]:
        K, ref = split.stiffness(E_, nu_), _skfem_K(base, E_, nu_)
        assert abs(K - ref).max() <= 1e-10 * abs(ref).max()
        net = pg.with_pair(base, E_, nu_)  # the fitted network's own stiffness
        assert abs(net.volume.stiffness_matrix(net.points) - ref).max() <= 1e-10 * abs(ref).max()


@pytest.mark.parametrize("plane", ["stress", "strain"])
def test_the_lame_split_in_2d(plane):
    """Triangles: plane strain takes lambda, plane stress 2 lambda mu / (lambda + 2 mu)."""
    mesh = skfem.MeshTri.init_sqsymmetric().refined(2)
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementTriP1()))
    perm = basis.nodal_dofs.T.ravel()
    split = pg.lame_split(mesh.p.T, mesh.t.T, plane)
    lam, mu = lame_parameters(E, NU)
    a = 2 * lam * mu / (lam + 2 * mu) if plane == "stress" else lam
    ref = skfem.asm(linear_elasticity(a, mu), basis).tocsr()[perm][:, perm]
    assert abs(split.stiffness(E, NU) - ref).max() <= 1e-10 * abs(ref).max()


def _synthetic(case, base):
    """The fitted loads' arrays with the plain P1 of (E0, NU0) as their 'reference'."""
    spec = pg.P1_GLOBAL.spec(model_spec(case))
    truth = with_p1(build_network(case, spec), isotropic(E0, NU0, 1000.0, "stress"))
    res = statics.solve(truth, case, loads=case.fit_loads)
    _, free, forces = statics.all_load_arrays(base, case)
    fit = [[ld.name for ld in case.loads].index(n) for n in res.names]
    w = node_weights(base.classes, (1.0, 1.0, 1.0))
    return pg.Training.of(free[fit], forces[fit], res.u, w)


def _recovers(fit) -> bool:
    return abs(fit.E / E0 - 1) < 1e-3 and abs(fit.nu - NU0) < 1e-3


def test_the_fit_recovers_a_known_pair_and_nu_held_fixed_cannot(case, base):
    t = _synthetic(case, base)
    split = pg.lame_split(base.points, base.volume.elements)
    fit = pg.fit_pair(split, t, E, NU)
    assert _recovers(fit), fit
    assert fit.misfit_final < 1e-6 * fit.misfit_initial
    held = pg.fit_pair(split, t, E, NU, fix_nu=True)  # the broken variant
    assert not _recovers(held) and held.misfit_final > 1e-2 > fit.misfit_final


def test_the_jacobian_is_the_misfits_derivative(case, base):
    """du/d(log E, nu) against central differences of the solves themselves."""
    t = _synthetic(case, base)
    split = pg.lame_split(base.points, base.volume.elements)
    _, du = pg._solves(split, t, E, NU)
    h = 1e-6
    for j, (dE, dn) in enumerate([(math.exp(h), 0.0), (1.0, h)]):
        up = pg._solves(split, t, E * dE, NU + dn)[0]
        dn_ = pg._solves(split, t, E / dE, NU - dn)[0]
        fd = (up - dn_) / (2 * h)
        assert np.abs(du[j] - fd).max() <= 1e-5 * np.abs(fd).max()


def test_the_stage_fit_beats_the_plain_p1_on_the_training_states(case, tmp_path, monkeypatch):
    """Against the FEM (max_refine 0): the fitted row's training error is below the plain
    P1's; its pair is softer than the case's; the exported pair is the fit's when the
    validation loads accept it, else the case's."""
    from harness.stages import StageContext
    from harness.stages import sms as stage

    monkeypatch.setenv("SPRINGBENCH_CACHE", str(tmp_path / "cache"))
    rows = stage.run(case, StageContext(out_dir=tmp_path / "out", seed=0))
    rule, fit = [r for r in rows if r["model_class"] == "p1-global"]
    assert (rule["optimizer"], fit["optimizer"]) == ("none", pg.METHOD)
    assert (rule["E_effective"], rule["nu_effective"]) == (E, NU)
    assert fit["nu_fit"] < NU and fit["G_initial_optimizer"] > fit["G_final_optimizer"]
    assert fit["G_norm_fit"] < rule["G_norm_final"]
    exported = (fit["E_fit"], fit["nu_fit"]) if fit["val_accepted"] else (E, NU)
    assert (fit["E_effective"], fit["nu_effective"]) == exported
    if fit["val_accepted"]:
        assert fit["G_norm_final"] < rule["G_norm_final"]
        assert fit["G_val_mean"] < rule["G_val_mean"]
    print(
        {
            k: (rule.get(k), fit.get(k))
            for k in ("G_norm_final", "G_norm_fit", "G_val_mean", "G_heldout_mean", "G_heldout")
        },
        fit["E_fit"],
        fit["nu_fit"],
        fit["G_initial_optimizer"],
        fit["G_final_optimizer"],
    )


def test_calibrate_exports_the_pair_for_the_engines_tetrahedra(case, tmp_path, monkeypatch):
    """``calibrate --model p1-global``: the JSON's one material per tetrahedron, Newton's
    k_mu = 4/3 mu and k_lambda = lambda + 5/6 mu of it (the Lame constants written here),
    the pair the CSV's exported row carries; a springs export engine is refused."""
    import json

    import pandas as pd

    from harness import cli

    monkeypatch.setenv("SPRINGBENCH_CACHE", str(tmp_path / "cache"))
    mesh, out = meshes.cylinder(tmp_path), tmp_path / "m.vtu"
    args = ["calibrate", str(mesh), "--E", str(E), "--nu", str(NU), "--model", "p1-global"]
    args += ["--max-refine", "0", "--quiet", "--out"]
    assert cli.main([*args, str(out)]) == 0
    data = json.loads(out.with_suffix(".json").read_text())
    row = pd.read_csv(out.with_suffix(".csv")).query("exported").iloc[0]
    E_, nu_ = data["E_effective"], data["nu_effective"]
    assert (E_, nu_) == (row["E_effective"], row["nu_effective"]) and nu_ < NU
    mu, lam = E_ / (2 * (1 + nu_)), E_ * nu_ / ((1 + nu_) * (1 - 2 * nu_))
    tets = np.asarray(data["tet_indices"])
    assert tets.shape[1] == 4 and len(tets) == len(data["tet_E"]) == len(data["tet_nu"])
    assert set(data["tet_E"]) == {E_} and set(data["tet_nu"]) == {nu_}
    assert np.allclose(data["tet_k_mu"], 4 / 3 * mu, rtol=1e-12)
    assert np.allclose(data["tet_k_lambda"], lam + 5 / 6 * mu, rtol=1e-12)
    assert data["validation_accepted"] is True and data["choice"] == "fit"
    assert cli.main([*args, str(tmp_path / "e.vtu"), "--engine", "newton-springs"]) != 0
