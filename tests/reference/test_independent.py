"""The independent 3-D reference (tests/independent_elasticity.py) against itself and
scikit-fem: exact 1-D element matrices, the Kronecker stiffness against scikit-fem's
assembly of the same discrete problem, the matrix-free operator and its preconditioner
against the assembled matrix, a patch test, a closed-form solve, and the quarter's
symmetry conditions against a solve of the whole box."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

_spec = importlib.util.spec_from_file_location("independent_elasticity",
                                               Path(__file__).resolve().parents[1] / "independent_elasticity.py")
ie = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(ie)

SIZE = (3.0, 3.0, 3.0)
E, NU, S = 1000.0, 0.3, 1.0


def _points(rng, size, m=40):
    g = np.linspace(0, size[0], 4)
    grid = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    return np.vstack([grid, rng.uniform(0, 1, (m, 3)) * np.asarray(size)])


def test_element_matrices_are_the_exact_integrals():
    g, w = np.polynomial.legendre.leggauss(4)
    t, w = 0.5 * (g + 1), 0.5 * w
    N = np.stack([(1 - t) * (1 - 2 * t), 4 * t * (1 - t), t * (2 * t - 1)])
    dN = np.stack([4 * t - 3, 4 - 8 * t, 4 * t - 1])
    np.testing.assert_allclose(ie._M, (N * w) @ N.T, atol=1e-15)
    np.testing.assert_allclose(ie._A, (dN * w) @ dN.T, atol=1e-14)
    np.testing.assert_allclose(ie._B, (dN * w) @ N.T, atol=1e-15)
    np.testing.assert_allclose(ie._m, N @ w, atol=1e-15)


def test_kronecker_assembly_gives_scikit_fems_discrete_solution():
    rng = np.random.default_rng(1)
    pts = _points(rng, SIZE)
    for n, beta in [(2, 2.5), (3, 1.7)]:
        fast = ie.quarter_shear(SIZE, E, NU, S, n, pts, beta, direct=True)
        ref = ie.quarter_shear_skfem(SIZE, E, NU, S, n, pts, beta)
        assert np.abs(fast - ref).max() <= 1e-10 * np.abs(ref).max()


def test_matrix_free_operator_and_preconditioner_match_the_assembled_matrix():
    rng = np.random.default_rng(2)
    verts = ie.quarter_mesh((3.0, 2.0, 1.5), 3, 2.5)
    prob = ie.BoxProblem(verts, 700.0, 0.35, ie.QUARTER_FIXED)
    idx = prob.free_index()
    K = ie.stiffness(verts, 700.0, 0.35)[idx][:, idx]
    x = rng.standard_normal(prob.n_dofs)
    y = K @ x
    assert np.abs(prob.matvec(x) - y).max() <= 1e-13 * np.abs(y).max()
    # the preconditioner is the exact inverse of the diagonal blocks K_aa
    o = prob.offsets
    z = prob.precondition(y)
    for a in range(3):
        Kaa = K[o[a]:o[a + 1]][:, o[a]:o[a + 1]]
        r = Kaa @ z[o[a]:o[a + 1]] - y[o[a]:o[a + 1]]
        assert np.abs(r).max() <= 1e-10 * np.abs(y[o[a]:o[a + 1]]).max()
    assert np.allclose(K.toarray(), K.toarray().T, rtol=0, atol=1e-12 * abs(K).max())


def test_patch_test_linear_field_gives_exactly_its_boundary_tractions():
    """K u = F for an affine u: F the loads of the (constant) tractions sigma n on the six faces."""
    rng = np.random.default_rng(3)
    verts = [np.array([0.0, 0.1, 0.5, 2.0]), np.array([-1.0, -0.9, 0.3]), np.array([2.0, 2.05, 2.3, 3.0, 3.5])]
    lam, mu = ie.lame(E, NU)
    Gr, c = rng.standard_normal((3, 3)), rng.standard_normal(3)
    X = np.stack(np.meshgrid(*[ie.q2_nodes(v) for v in verts], indexing="ij"), -1).reshape(-1, 3)
    u = (X @ Gr.T + c).T.ravel()                 # blocked: all u_x, then u_y, then u_z
    eps = 0.5 * (Gr + Gr.T)
    sig = lam * np.trace(eps) * np.eye(3) + 2 * mu * eps
    F = sum(ie.face_load(verts, ax, end, sig @ ((1 if end else -1) * np.eye(3)[ax]))
            for ax in range(3) for end in (0, 1))
    Ku = ie.stiffness(verts, E, NU) @ u
    assert np.abs(Ku - F).max() <= 1e-12 * np.abs(F).max()


@pytest.mark.parametrize("direct", [True, False])
def test_uniaxial_tension_with_rollers_is_exact(direct):
    """Rollers on x = 0, y = 0, z = 0, traction s e_z on z = c: u = (-nu x, -nu y, z) s / E."""
    rng = np.random.default_rng(4)
    size = (2.0, 1.0, 3.0)
    verts = ie.quarter_mesh(size, 4, 2.5)
    verts = [v * (s / v[-1]) for v, s in zip(verts, size)]
    prob = ie.BoxProblem(verts, E, NU, {0: [(0, 0)], 1: [(1, 0)], 2: [(2, 0)]})
    U = prob.solve(ie.face_load(verts, 2, 1, [0.0, 0.0, S]), direct=direct)
    pts = rng.uniform(0, 1, (50, 3)) * np.asarray(size)
    exact = np.column_stack([-NU * pts[:, 0], -NU * pts[:, 1], pts[:, 2]]) * S / E
    assert np.abs(ie.evaluate_grid(verts, U, pts) - exact).max() <= 1e-10 * np.abs(exact).max()


def test_quarter_with_symmetry_conditions_equals_the_whole_box():
    rng = np.random.default_rng(5)
    size = (3.0, 2.0, 1.5)
    n = 2
    q = ie.quarter_mesh(size, n, 2.5)
    full = [np.concatenate([q[0], size[0] - q[0][::-1][1:]]), np.concatenate([q[1], size[1] - q[1][::-1][1:]]), q[2]]
    prob = ie.BoxProblem(full, E, NU, {a: [(2, 0)] for a in range(3)})
    U = prob.solve(ie.face_load(full, 2, 1, [S, 0.0, 0.0]), direct=True)
    pts = _points(rng, size)
    whole = ie.evaluate_grid(full, U, pts)
    quarter = ie.quarter_shear(size, E, NU, S, n, pts, 2.5, direct=True)
    assert np.abs(whole - quarter).max() <= 1e-10 * np.abs(whole).max()


def test_cg_and_direct_solves_agree():
    rng = np.random.default_rng(6)
    pts = _points(rng, SIZE)
    a = ie.quarter_shear(SIZE, E, NU, S, 4, pts, direct=True)
    b = ie.quarter_shear(SIZE, E, NU, S, 4, pts, direct=False)
    assert np.abs(a - b).max() <= 1e-10 * np.abs(a).max()


def test_knot_grading_puts_the_thirds_on_nodes_of_every_level():
    size = (3.0, 2.0, 1.5)
    for n in (4, 8, 12):
        x, y, z = ie.quarter_mesh(size, n, 2.5, knot=0.75)
        assert np.all(np.diff(x) > 0) and np.all(np.diff(z) > 0)
        assert x[-1] == pytest.approx(1.5) and y[-1] == pytest.approx(1.0) and z[-1] == pytest.approx(1.5)
        assert np.min(np.abs(x - 1.0)) < 1e-14 and np.min(np.abs(y - 2 / 3)) < 1e-14
        assert np.min(np.abs(z - 0.5)) < 1e-14 and np.min(np.abs(z - 1.0)) < 1e-14
        assert x[1] == pytest.approx(1.0 * (1 / (0.75 * n)) ** 2.5)        # power law at the face
        np.testing.assert_allclose(z, 1.5 - z[::-1], atol=1e-14)
    with pytest.raises(ValueError):
        ie.quarter_mesh(size, 6, 2.5, knot=0.75)


def test_extrapolation_recovers_a_known_expansion():
    rng = np.random.default_rng(7)
    u, C = rng.standard_normal((20, 3)), rng.standard_normal((20, 3))
    ns = (12, 16, 20)
    vals = [u + C / n ** 2.6 for n in ns]
    ext, change, p = ie.extrapolate_levels(vals, ns)
    assert p == pytest.approx(2.6, abs=1e-6)
    assert np.abs(ext - u).max() < 1e-9
