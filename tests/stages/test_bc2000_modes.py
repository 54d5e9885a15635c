"""Held-out natural frequencies of the B&C fem stage: the linearised models'
first modes against the FEM's, with the held-out sag's clamp, checked against a dense
generalised eigen-solve written here (masses and constraints by hand)."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg as sl
import scipy.sparse as sp

from harness.case.reader import load_case
from harness.io.meshfile import read_mesh
from harness.mechanics.modal import matrix_eigenvalues, matrix_frequencies
from harness.stages import bc2000_linear as linear
from harness.stages.bc2000 import build
from harness.stages.bc2000_modes import heldout_modes

ROOT = Path(__file__).resolve().parents[2]
CASE = ROOT / "cases/bourguignon2000/fem_cube333_tetra.toml"
HEXA = ROOT / "cases/bourguignon2000/fem_cube333_hexa.toml"
needs_data = pytest.mark.skipif(
    not (ROOT.parent / "shared/reference-data/bourguignon2000").is_dir(),
    reason="needs the B&C reference data",
)


def dense_frequencies(P, tets, rho, K, n):
    """First n frequencies (Hz) of K with lumped masses rho |tet| / 4 per vertex and the
    nodes on x = min clamped (the sag's x0 face), by a dense generalised eigen-solve. K of
    the element model is not symmetric: the general solver (scipy.linalg.eig), and the
    first n eigenvalues must be real and positive."""
    x = P[tets]
    vol = np.abs(np.linalg.det(x[:, 1:] - x[:, :1])) / 6
    mass = np.zeros(len(P))
    np.add.at(mass, tets.ravel(), np.repeat(rho * vol / 4, 4))
    return _general_frequencies(P, K.toarray(), mass, n)


def _general_frequencies(P, K, mass, n):
    free = np.repeat(np.abs(P[:, 0] - P[:, 0].min()) > 1e-12, 3)
    lam = sl.eig(K[free][:, free], np.diag(np.repeat(mass, 3)[free]), right=False)
    lam = lam[np.argsort(lam.real)][:n]
    assert np.all(np.abs(lam.imag) <= 1e-9 * np.abs(lam)) and np.all(lam.real > 0)
    return np.sqrt(lam.real) / (2 * np.pi)


def rms(f, g):
    return float(np.sqrt(np.mean((np.asarray(f) / np.asarray(g) - 1) ** 2)))


@needs_data
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

    cols = heldout_modes(
        ref, case, lumped_masses(P, tets, case.material.density), loads, Ks, theta0, theta1
    )
    n = case.reference.modes
    f_fem = ref.frequencies(n, load="sag")
    f0, f1 = (
        dense_frequencies(P, tets, case.material.density, sum(t * K for t, K in zip(th, Ks)), n)
        for th in (theta0, theta1)
    )
    np.testing.assert_allclose(f1, np.sqrt(1.7) * f0, rtol=1e-10)  # K scaled by 1.7: f by its root
    assert cols["freq_error_heldout_initial"] == pytest.approx(rms(f0, f_fem), rel=1e-9)
    assert cols["freq_error_heldout"] == pytest.approx(rms(f1, f_fem), rel=1e-9)
    assert cols["f1_ratio"] == pytest.approx(f1[0] / f_fem[0], rel=1e-9)
    assert f_fem[0] > 0 and cols["freq_error_heldout"] != cols["freq_error_heldout_initial"]


@needs_data
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


def _blocks(a, b, c):
    """Block-diagonal K of 2x2 blocks [[a, b], [c, a]]: eigenvalues a +- sqrt(b c) by hand."""
    blocks = [np.array([[ai, bi], [ci, ai]]) for ai, bi, ci in zip(a, b, c)]
    return sp.block_diag(blocks).tocsr(), np.sort_complex(
        np.concatenate([a + np.sqrt((b * c).astype(complex)), a - np.sqrt((b * c).astype(complex))])
    )


@pytest.mark.parametrize("nodes", [40, 800])  # dense (80 dofs) and sparse (1600) paths
def test_matrix_eigenvalues_of_a_nonsymmetric_matrix(nodes):
    """A non-symmetric K with eigenvalues known by hand (real, then a complex pair): the
    general solver finds them in order of real part; the frequency of the non-real pair is
    Re sqrt(lambda) / 2 pi, and a symmetric K keeps the symmetric solver's answer."""
    rng = np.random.default_rng(3)
    a = rng.uniform(10, 50, nodes)
    b = rng.uniform(0.5, 2.0, nodes)
    c = b * rng.uniform(0.2, 0.9, nodes)  # b c > 0: real eigenvalues
    a[0], c[0] = 5.0, -4.0 / b[0]  # block 0: 5 +- 2i, the lowest real part
    K, exact = _blocks(a, b, c)
    exact = exact[np.lexsort((exact.imag, exact.real))]
    masses = np.ones(nodes)
    free = np.ones(2 * nodes, bool)
    lam = matrix_eigenvalues(K, masses, free, 5)
    np.testing.assert_allclose(lam, exact[:5], rtol=1e-9)
    f = matrix_frequencies(K, masses, free, 5)
    np.testing.assert_allclose(f, np.sqrt(exact[:5]).real / (2 * np.pi), rtol=1e-9)
    Ks = (K + K.T) / 2  # symmetric: eigenvalues a +- (b + c) / 2
    ev = np.sort(np.concatenate([a + (b + c) / 2, a - (b + c) / 2]))
    np.testing.assert_allclose(matrix_eigenvalues(Ks, masses, free, 5), ev[:5], rtol=1e-9)


class _FEM:
    """A stand-in reference whose frequencies are 1 Hz: f1_ratio is then the model's f1."""

    def frequencies(self, n, load=None):
        return np.ones(n)


@needs_data
def test_hexa_MT_modes_under_the_clamp_are_not_zero():
    """The hexa MT rows' f1_ratio is not 0. The element model's linearised K (the
    stage's complex-step unit stiffnesses) equals a central finite-difference Jacobian of
    its nonlinear forces; that K is not symmetric (the hexa volume springs act on the
    vertices only), has no zero singular value under the sag's x0 clamp, and the general
    eigen-solve of (K, M) written here gives real positive eigenvalues; the stage's modes
    match it. A symmetric solver, which reads one triangle of K, gives a negative lowest
    eigenvalue (read as a zero frequency)."""
    case = load_case(HEXA)
    assert case.heldout[0] == "sag"
    mesh = read_mesh(case.body.file, case.body.format)
    P, hexes = mesh.points, mesh.cells["hexahedron"]
    m = build("MT", case.section("model"), mesh, 1.0, material=case.material)
    Ks = linear.unit_stiffnesses(m)
    theta = linear.current_parameters(m)  # the program's constants (ks 2.5, kvs 5)
    K = sum(t * Kj for t, Kj in zip(theta, Ks)).toarray()
    h = 1e-6
    Kfd = np.zeros_like(K)
    for j in range(K.shape[1]):
        dx = np.zeros(K.shape[1])
        dx[j] = h
        Kfd[:, j] = -(m.forces(P + dx.reshape(-1, 3)) - m.forces(P - dx.reshape(-1, 3))).ravel() / (
            2 * h
        )
    np.testing.assert_allclose(K, Kfd, atol=1e-7 * np.abs(K).max())
    assert np.abs(Kfd - Kfd.T).max() > 1e-2 * np.abs(Kfd).max()  # not symmetric
    free = np.repeat(np.abs(P[:, 0] - P[:, 0].min()) > 1e-12, 3)
    sv = np.linalg.svd(Kfd[free][:, free], compute_uv=False)
    assert sv[-1] > 1e-4 * sv[0]  # no zero mode
    X = P[hexes]  # bricks: volume = product of the extents
    assert np.allclose(np.sort(np.abs(X - X.min(axis=1)[:, None]), axis=1)[:, :1], 0)
    vol = np.prod(X.max(axis=1) - X.min(axis=1), axis=1)
    mass = np.zeros(len(P))
    np.add.at(mass, hexes.ravel(), np.repeat(case.material.density * vol / 8, 8))
    n = case.reference.modes
    f = _general_frequencies(P, Kfd, mass, n)
    loads = linear.case_loads(P, case)
    cols = heldout_modes(_FEM(), case, mass, loads, Ks, theta, theta)
    assert cols["f1_ratio"] == pytest.approx(f[0], rel=1e-6) and cols["modes_unstable"] == 0
    assert cols["freq_error_heldout"] == pytest.approx(rms(f, np.ones(n)), rel=1e-6)
    Kf = Kfd[free][:, free]
    s = 1 / np.sqrt(np.repeat(mass, 3)[free])
    # a symmetric solver's reading
    assert sl.eigh(Kf * s[:, None] * s[None, :], eigvals_only=True)[0] < 0
