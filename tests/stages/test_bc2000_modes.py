"""Held-out natural frequencies of the B&C fem stage (issue 12): the linearised models'
first modes against the FEM's, with the held-out sag's clamp, checked against a dense
generalised eigen-solve written here (masses and constraints by hand)."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg as sl

from harness.case.reader import load_case
from harness.io.meshfile import read_mesh
from harness.stages import bc2000_linear as linear
from harness.stages.bc2000 import build
from harness.stages.bc2000_modes import heldout_modes

ROOT = Path(__file__).resolve().parents[2]
CASE = ROOT / "cases/bourguignon2000/fem_cube333_tetra.toml"
pytestmark = pytest.mark.skipif(not (ROOT.parent / "shared/reference-data/bourguignon2000").is_dir(),
                                reason="needs the B&C reference data")


def dense_frequencies(P, tets, rho, K, n):
    """First n frequencies (Hz) of K with lumped masses rho |tet| / 4 per vertex and the
    nodes on x = min clamped (the sag's x0 face), by a dense generalised eigen-solve."""
    x = P[tets]
    vol = np.abs(np.linalg.det(x[:, 1:] - x[:, :1])) / 6
    mass = np.zeros(len(P))
    np.add.at(mass, tets.ravel(), np.repeat(rho * vol / 4, 4))
    free = np.repeat(np.abs(P[:, 0] - P[:, 0].min()) > 1e-12, 3)
    Kf = K.toarray()[free][:, free]
    lam = sl.eigh(Kf, np.diag(np.repeat(mass, 3)[free]), eigvals_only=True)
    return np.sqrt(lam[:n]) / (2 * np.pi)


def rms(f, g):
    return float(np.sqrt(np.mean((np.asarray(f) / np.asarray(g) - 1) ** 2)))


def test_heldout_modes_against_a_dense_eigensolve():
    import reference
    case = load_case(CASE)
    assert case.heldout[0] == "sag"
    case = dataclasses.replace(case, reference=dataclasses.replace(case.reference, max_refine=0))
    ref = reference.solve(case, cache=False)
    mesh = read_mesh(case.body.file, case.body.format)
    P, tets = mesh.points, mesh.cells["tetra"]
    m = build("MT", case.section("model"), mesh, 1.0, material=case.material)
    Ks = linear.unit_stiffnesses(m)
    theta0 = linear.current_parameters(m)
    theta1 = 1.7 * theta0
    loads = linear.case_loads(P, case)
    from harness.stages.bc2000 import lumped_masses
    cols = heldout_modes(ref, case, lumped_masses(P, tets, case.material.density), loads, Ks, theta0, theta1)
    n = case.reference.modes
    f_fem = ref.frequencies(n, load="sag")
    f0, f1 = (dense_frequencies(P, tets, case.material.density, sum(t * K for t, K in zip(th, Ks)), n)
              for th in (theta0, theta1))
    np.testing.assert_allclose(f1, np.sqrt(1.7) * f0, rtol=1e-10)       # K scaled by 1.7: f by its root
    assert cols["freq_error_heldout_initial"] == pytest.approx(rms(f0, f_fem), rel=1e-9)
    assert cols["freq_error_heldout"] == pytest.approx(rms(f1, f_fem), rel=1e-9)
    assert cols["f1_ratio"] == pytest.approx(f1[0] / f_fem[0], rel=1e-9)
    assert f_fem[0] > 0 and cols["freq_error_heldout"] != cols["freq_error_heldout_initial"]


@pytest.mark.slow
def test_fem_stage_reports_heldout_modes_of_the_fitted_constants(tmp_path):
    """The stage's rows: freq_error_heldout of the fitted constants (fit_* columns),
    recomputed by the dense solve above."""
    import reference
    from harness.stages import StageContext
    from harness.stages import bc2000 as stage
    case = load_case(CASE)
    rows = stage.run(case, StageContext(out_dir=tmp_path / "out"))
    mesh = read_mesh(case.body.file, case.body.format)
    P, tets = mesh.points, mesh.cells["tetra"]
    f_fem = reference.solve(case).frequencies(case.reference.modes, load="sag")
    for row in rows:
        m = build(row["model"], case.section("model"), mesh, 1.0, material=case.material)
        theta = [row[f"fit_{k}"] for k in linear.parameter_names(m)]
        K = sum(t * K for t, K in zip(theta, linear.unit_stiffnesses(m)))
        f = dense_frequencies(P, tets, case.material.density, K, len(f_fem))
        assert row["freq_error_heldout"] == pytest.approx(rms(f, f_fem), rel=1e-8)
        assert 0 < row["freq_error_heldout"] < 1
