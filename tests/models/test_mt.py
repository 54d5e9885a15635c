"""Model class "mt" (harness/models/mt.py): Bourguignon & Cani's element model on a spring
model's own cells. Its linear stiffness against central differences of the compiled force
kernels of the original program's rule (harness/models/bc2000/kernels.py, generated code:
not the numpy element forces the class differentiates by complex step); its constants as
moduli (the quadratic form of each unit stiffness under a homogeneous stretch, shear and
dilation of one element, by hand); the stage's rows on the nu-sweep box (finite G and
G_heldout, the fit never worse than its start, the stored theta re-scored by a dense solve
written here), the 2-D skip row, the stable step against a dense eigen-solve, and the fit
recovering its own constants on a synthetic reference."""

import numpy as np
import pytest

from harness.case.reader import load_case
from harness.mechanics import statics
from harness.models.bc2000 import kernels
from harness.models.bc2000.pack import kernel_arrays
from harness.models.mt import PARAMS, MTTerm, size_factors
from harness.models.sms import model_spec
from harness.paths import ROOT
from harness.registry import MODEL_CLASSES
from harness.stages import StageContext
from harness.stages import sms as stage
from harness.stages.classes.mt import fit_theta

SWEEP = ROOT / "cases" / "nu_sweep"


def _mt(case):
    """The case's network of model class "mt" (the stage's build)."""
    mt = MODEL_CLASSES.load("mt")
    return mt.build(case, mt.spec(model_spec(case)))


def _case(tmp_path, body, classes='["mt"]', **replace):
    """A nu-sweep case file with other classes (and other lines), quick mode."""
    text = (SWEEP / f"{body}_nu0.45.toml").read_text()
    lines = [
        f"classes = {classes}" if line.startswith("classes = ") else line
        for line in text.splitlines()
    ]
    text = "\n".join(lines) + "\n"
    for a, b in replace.items():
        text = text.replace(a, b)
    f = tmp_path / f"{body}.toml"
    f.write_text(text)
    if body == "cylinder":
        (tmp_path / "cylinder.vtu").write_bytes((SWEEP / "cylinder.vtu").read_bytes())
    return load_case(f)


def _kernel_forces(model, x):
    """Internal forces (n, 3) of the compiled kernel of the program's rule at positions x."""
    _, tet, hexa = kernel_arrays(model, 1.0)
    f = np.zeros(x.size)
    run = kernels.tet_forces if not model.is_hex else kernels.hex_forces
    run(
        np.ascontiguousarray(x, float).ravel(),
        np.zeros(x.size),
        f,
        *(tet if not model.is_hex else hexa),
    )
    return f.reshape(x.shape)


@pytest.mark.parametrize("body", ["box", "cylinder"])
def test_class_stiffness_is_the_central_difference_of_the_compiled_kernels(tmp_path, body):
    case = _case(tmp_path, body)
    net = _mt(case)
    theta = {"box": [700.0, 300.0, 900.0], "cylinder": [7e4, 3e4, 9e4]}[body]  # any theta
    net = net.with_k(np.concatenate([net.k, theta]))
    K = net.stiffness_matrix().toarray()
    model = net.volume.model()
    x0 = net.points
    size = np.ptp(x0, axis=0).max()
    h = 1e-6 * size
    # rest is force-free
    assert np.abs(_kernel_forces(model, x0)).max() <= 1e-12 * np.abs(K).max() * size
    rng = np.random.default_rng(0)
    cols = rng.choice(x0.size, size=min(60, x0.size), replace=False)
    for j in cols:
        e = np.zeros(x0.size)
        e[j] = h
        e = e.reshape(x0.shape)
        fd = -(_kernel_forces(model, x0 + e) - _kernel_forces(model, x0 - e)).ravel() / (2 * h)
        assert np.abs(K[:, j] - fd).max() <= 1e-6 * np.abs(K).max(), j
    # and it is not symmetric (the reason the class has its own fit)
    assert np.abs(K - K.T).max() > 1e-3 * np.abs(K).max()


def _element(kind, seed):
    """One tetrahedron (perturbed) or hexahedron (a box 0.7 x 1 x 1.3: the program's
    bilinear end weights are exact on rectangular faces only), positive orientation."""
    rng = np.random.default_rng(seed)
    if kind == "tet":
        P = np.array(
            [[0, 0, 0], [1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]]
        ) + 0.04 * rng.standard_normal((4, 3))
    else:
        P = np.array(
            [
                [0, 0, 0],
                [1, 0, 0],
                [1, 1, 0],
                [0, 1, 0],
                [0, 0, 1],
                [1, 0, 1],
                [1, 1, 1],
                [0, 1, 1],
            ],
            float,
        )
        P = P * [0.7, 1.0, 1.3] + rng.standard_normal(3)
    return P, np.arange(len(P))[None, :]


@pytest.mark.parametrize("kind", ["tet", "hex"])
def test_theta_are_moduli_of_one_element_by_hand(kind):
    """u^T K_j u of one element under a homogeneous strain about its centre: stretch
    eps along x -> theta_a eps^2 V, engineering shear gamma_xy -> theta_s gamma^2 V
    (the program's couple stores ks (L1 + L2)/2 gamma^2), dilation eps -> theta_v (3 eps)^2 V."""
    P, cells = _element(kind, 1)
    term = MTTerm.build(P, cells, [1.0, 1.0, 1.0])
    g = P.mean(axis=0)
    from scipy.spatial import ConvexHull

    V = ConvexHull(P).volume  # both elements are convex: an independent volume
    assert size_factors(term.body)[0, 0] * term.body.L0[0, 0] ** 2 == pytest.approx(V, rel=1e-12)
    eps, gam = 1e-3, 2e-3
    strains = {
        0: np.diag([eps, 0, 0]),
        1: np.array([[0, gam / 2, 0], [gam / 2, 0, 0], [0, 0, 0]]),
        2: eps * np.eye(3),
    }
    expect = {0: eps**2 * V, 1: gam**2 * V, 2: 9 * eps**2 * V}
    for j, S in strains.items():
        u = ((P - g) @ S.T).ravel()
        assert u @ (term.units[j] @ u) == pytest.approx(expect[j], rel=1e-9), PARAMS[j]
    # each unit term has the rigid motions in its null space (translations, small rotations)
    W = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 0]]) * 1e-3
    for u in (np.tile([0.3, -0.2, 0.5], len(P)), (P @ W.T).ravel()):
        for Kj in term.units:
            assert np.abs(Kj @ u).max() <= 1e-9 * np.abs(Kj).max() * np.abs(u).max()


def test_stage_rows_on_the_nu_sweep_box(tmp_path):
    case = _case(tmp_path, "box")
    out = tmp_path / "out"
    rows = stage.run(case, StageContext(out_dir=out))
    assert [(r["model_class"], r["optimizer"]) for r in rows] == [
        ("mt", "none"),
        ("mt", "least-squares"),
    ]
    start, fitted = rows
    for r in rows:
        assert np.isfinite(r["G_norm_final"]) and np.isfinite(r["G_heldout"]) and r["n_nodes"] == 45
        assert r["n_elements"] == 16  # the 4 x 2 x 2 grid's hexahedra
        assert (
            np.isfinite(r["freq_error_final"])
            and np.isfinite(r["dt_stable"])
            and np.isnan(r["k_spread"])
        )
        assert "cauchy_misfit" not in r
    assert fitted["G_final"] <= start["G_final"] * (1 + 1e-9) and fitted["n_params"] == 3
    # the stored theta, re-scored: a dense solve of the element model's K (complex step of
    # the numpy element forces, assembled here) on the case's loads
    d = np.load(out / "mt" / "mt-mt-least-squares.npz")
    theta = d["theta"]
    assert [fitted[f"mt_{k}"] for k in PARAMS] == list(theta)
    net = _mt(case)
    model = net.volume.model(theta)
    assert np.allclose(model.ks, d["ks"]) and np.allclose(model.kvs, d["kvs"])
    K = model.tangent_stiffness().toarray()
    deformed = np.load(out / "mt" / "deformed-mt-least-squares.npz")
    for load in case.loads:
        free, f = statics.load_arrays(net, case, load)
        u = np.zeros(f.size)
        u[free] = np.linalg.solve(K[np.ix_(free, free)], f[free])
        assert np.allclose(
            deformed[f"u_{load.name}"].ravel(), u, rtol=0, atol=1e-9 * np.abs(u).max()
        )
    # dt_stable: 2 / omega_max of M^-1/2 K_sym M^-1/2 (the free body), dense here
    s = 1 / np.sqrt(np.repeat(net.masses, 3))
    lam = np.linalg.eigvalsh(s[:, None] * (0.5 * (K + K.T)) * s[None, :]).max()
    assert fitted["dt_stable"] == pytest.approx(2 / np.sqrt(lam), rel=1e-9)


def test_plate_row_says_there_is_no_2d_element(tmp_path):
    rows = stage.run(_case(tmp_path, "plate"), StageContext(out_dir=tmp_path / "o"))
    assert len(rows) == 1 and rows[0]["model_class"] == "mt" and rows[0]["status"] == "skip"
    assert "no 2-D element" in rows[0]["note"] and "G_norm_final" not in rows[0]


def test_fit_recovers_its_own_constants(tmp_path):
    """A synthetic reference made by the class itself (theta_true): the fit from a start
    off by factors 0.5 to 3 returns theta_true and G ~ 0 (to the finite-difference
    Jacobian's precision: 1e-6 here)."""
    case = _case(tmp_path, "box")
    base = _mt(case)
    true = np.array([800.0, 300.0, 500.0])
    names = tuple(l.name for l in case.loads)
    u_true = statics.solve(base.with_k(np.concatenate([base.k, true])), case).u
    start = base.with_k(np.concatenate([base.k, true * [3.0, 0.5, 2.0]]))
    fit = [names.index(n) for n in case.fit_loads]
    theta, g0, g1 = fit_theta(start, case, u_true, names, fit, (1.0, 1.0, 1.0))
    assert g0 > 1e-4 and g1 < 1e-5 * g0  # (the fit's Jacobian is a finite difference)
    np.testing.assert_allclose(theta, true, rtol=1e-5)


def test_hexahedra_without_rectangular_faces_are_a_one_line_error():
    """The program's hexahedron weights its axis ends exactly on rectangular faces only;
    elsewhere its rest shape carries forces, so the class refuses it (one line, the fix)."""
    from harness.errors import ModelError

    P, cells = _element("hex", 2)
    MTTerm.build(P, cells, 1.0)  # a box: fine
    sheared = P @ np.array([[1.0, 0.3, 0.0], [0.0, 1.0, 0.0], [0.1, 0.0, 1.0]]).T
    with pytest.raises(ModelError) as exc:
        MTTerm.build(sheared, cells, 1.0)
    assert "rectangular" in str(exc.value) and "\n" not in str(exc.value)


def test_statics_of_the_class_never_take_the_cholesky_path(tmp_path, monkeypatch):
    """With every system above the multifrontal threshold, the class's statics still equal
    a dense solve of its (non-symmetric) K: a Cholesky would read one triangle."""
    case = _case(tmp_path, "box")
    net = _mt(case)
    monkeypatch.setattr(statics, "MULTIFRONTAL_MIN", 1)
    res = statics.solve(net, case)
    K = net.stiffness_matrix().toarray()
    for load in case.loads:
        free, f = statics.load_arrays(net, case, load)
        u = np.zeros(f.size)
        u[free] = np.linalg.solve(K[np.ix_(free, free)], f[free])
        assert np.allclose(
            res.displacement(load.name).ravel(), u, rtol=0, atol=1e-9 * np.abs(u).max()
        )
