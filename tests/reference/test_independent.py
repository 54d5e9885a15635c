"""The independent 3-D reference (tests/independent/) against itself and
scikit-fem: exact 1-D element matrices, the Kronecker stiffness against scikit-fem's
assembly of the same discrete problem, the matrix-free operator and its preconditioner
against the assembled matrix, a patch test, a closed-form solve, and the quarter's
symmetry conditions against a solve of the whole box."""

import numpy as np
import pytest
import scipy.sparse.linalg as spla
import skfem
from skfem.models.elasticity import lame_parameters, linear_elasticity

from tests import independent as ie

SIZE = (3.0, 3.0, 3.0)
E, NU, S = 1000.0, 0.3, 1.0


def skfem_quarter_shear(
    size, E: float, nu: float, s: float, n: int, points, beta: float = 2.5
) -> np.ndarray:
    """The same discrete problem as ``quarter_shear`` assembled by scikit-fem's own
    elasticity forms (slow: for small n only), solved directly."""

    class _Mapping(skfem.MappingIsoparametric):
        def invF(self, x, tind=None, newton_max_iters=50, newton_tol=1e-12):
            return super().invF(x, tind=tind, newton_max_iters=newton_max_iters, newton_tol=1e-13)

    a, b, c = size
    mesh = skfem.MeshHex.init_tensor(*ie.quarter_mesh(size, n, beta))
    mapping = _Mapping(mesh, mesh.elem(), mesh.bndelem)
    e = skfem.ElementVector(skfem.ElementHex2())
    basis = skfem.Basis(mesh, e, mapping=mapping, intorder=4)
    K = skfem.asm(linear_elasticity(*lame_parameters(E, nu)), basis)
    top = mesh.facets_satisfying(lambda x: np.isclose(x[2], c), boundaries_only=True)
    fb = skfem.FacetBasis(mesh, e, facets=top, mapping=mapping, intorder=4)
    F = skfem.asm(skfem.LinearForm(lambda v, w: s * np.asarray(v)[0]), fb)  # t . v, t = s e_x
    D = basis.get_dofs(lambda x: np.isclose(x[2], 0.0)).all()
    Dy = basis.get_dofs(lambda x: np.isclose(x[1], b / 2)).all("u^2")
    Dx = basis.get_dofs(lambda x: np.isclose(x[0], a / 2)).all(["u^2", "u^3"])
    fixed = np.unique(np.concatenate([D, Dy, Dx]))
    u = np.zeros(K.shape[0])
    free = np.setdiff1d(np.arange(K.shape[0]), fixed)
    u[free] = spla.spsolve(K[free][:, free].tocsc(), F[free])
    q, flip = ie.mirror_points(np.asarray(points, float), size)
    vals = basis.probes(q.T) @ u  # component-major: all u_x, then u_y, then u_z
    m = len(q)
    return ie.mirror_signs(np.column_stack([vals[:m], vals[m : 2 * m], vals[2 * m :]]), flip)


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
        ref = skfem_quarter_shear(SIZE, E, NU, S, n, pts, beta)
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
        Kaa = K[o[a] : o[a + 1]][:, o[a] : o[a + 1]]
        r = Kaa @ z[o[a] : o[a + 1]] - y[o[a] : o[a + 1]]
        assert np.abs(r).max() <= 1e-10 * np.abs(y[o[a] : o[a + 1]]).max()
    assert np.allclose(K.toarray(), K.toarray().T, rtol=0, atol=1e-12 * abs(K).max())


def test_patch_test_linear_field_gives_exactly_its_boundary_tractions():
    """K u = F for an affine u: F the loads of the (constant) tractions sigma n on the six faces."""
    rng = np.random.default_rng(3)
    verts = [
        np.array([0.0, 0.1, 0.5, 2.0]),
        np.array([-1.0, -0.9, 0.3]),
        np.array([2.0, 2.05, 2.3, 3.0, 3.5]),
    ]
    lam, mu = ie.lame(E, NU)
    Gr, c = rng.standard_normal((3, 3)), rng.standard_normal(3)
    X = np.stack(np.meshgrid(*[ie.q2_nodes(v) for v in verts], indexing="ij"), -1).reshape(-1, 3)
    u = (X @ Gr.T + c).T.ravel()  # blocked: all u_x, then u_y, then u_z
    eps = 0.5 * (Gr + Gr.T)
    sig = lam * np.trace(eps) * np.eye(3) + 2 * mu * eps
    F = sum(
        ie.face_load(verts, ax, end, sig @ ((1 if end else -1) * np.eye(3)[ax]))
        for ax in range(3)
        for end in (0, 1)
    )
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
    full = [
        np.concatenate([q[0], size[0] - q[0][::-1][1:]]),
        np.concatenate([q[1], size[1] - q[1][::-1][1:]]),
        q[2],
    ]
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
        assert (
            x[-1] == pytest.approx(1.5)
            and y[-1] == pytest.approx(1.0)
            and z[-1] == pytest.approx(1.5)
        )
        assert np.min(np.abs(x - 1.0)) < 1e-14 and np.min(np.abs(y - 2 / 3)) < 1e-14
        assert np.min(np.abs(z - 0.5)) < 1e-14 and np.min(np.abs(z - 1.0)) < 1e-14
        assert x[1] == pytest.approx(1.0 * (1 / (0.75 * n)) ** 2.5)  # power law at the face
        np.testing.assert_allclose(z, 1.5 - z[::-1], atol=1e-14)
    with pytest.raises(ValueError):
        ie.quarter_mesh(size, 6, 2.5, knot=0.75)


def test_extrapolation_recovers_a_known_expansion():
    rng = np.random.default_rng(7)
    u, C = rng.standard_normal((20, 3)), rng.standard_normal((20, 3))
    ns = (12, 16, 20)
    vals = [u + C / n**2.6 for n in ns]
    ext, change, p = ie.extrapolate_levels(vals, ns)
    assert p == pytest.approx(2.6, abs=1e-6)
    assert np.abs(ext - u).max() < 1e-9


def test_long_axes_grade_the_end_faces_like_the_short_ones():
    """A 10:1 box: with ``long_axes`` the long axis's cells at its end face are those of the
    short axes (same power zone, a third of the shortest side), its third is a node of
    every level, cell sizes stay continuous where the power zone meets the stretch, and
    axes no longer than the shortest side are unchanged (the cubes' truth is the same)."""
    size = (10.0, 1.0, 1.0)
    for n in (4, 8, 12, 16):
        x, y, z = ie.quarter_mesh(size, n, 2.5, knot=0.75, long_axes=True)
        assert len(x) - 1 == n + n // 2 and np.all(np.diff(x) > 0) and x[-1] == pytest.approx(5.0)
        assert np.min(np.abs(x - 10 / 3)) < 1e-13  # the scored third
        k = 3 * n // 4
        # the face zone of the short axis
        np.testing.assert_allclose(x[: k + 1], y[: k + 1], atol=1e-15)
        h = np.diff(x)
        assert h[k] / h[k - 1] < (h[k - 1] / h[k - 2]) * 1.5  # no jump in cell size at the junction
        plain = ie.quarter_mesh(size, n, 2.5, knot=0.75)
        assert all(np.array_equal(a, b) for a, b in zip((y, z), plain[1:]))
        assert x[1] < plain[0][1] / 5  # one power zone: 2.5x+ coarser
    cube = (3.0, 3.0, 3.0)
    assert all(
        np.array_equal(a, b)
        for a, b in zip(
            ie.quarter_mesh(cube, 8, 2.5, 0.75, True), ie.quarter_mesh(cube, 8, 2.5, 0.75)
        )
    )
    with pytest.raises(ValueError):
        # n / 4 not whole: the stretch's end
        ie.quarter_mesh(size, 6, 2.5, knot=0.75, long_axes=True)


@pytest.mark.slow
def test_long_axes_and_plain_truths_converge_to_the_same_field():
    """Two mesh families of the independent solve, extrapolated, agree on a 4:1 box (a
    Richardson extrapolant that depended on the family would not be the truth)."""
    size = (4.0, 1.0, 1.0)
    pts = np.stack(np.meshgrid(*[np.linspace(0, a, 4) for a in size], indexing="ij"), -1).reshape(
        -1, 3
    )
    a, ca, pa = ie.extrapolated_shear(
        size, E, 0.49, S, pts, levels=(8, 12, 16), knot=0.75, long_axes=True
    )
    b, cb, pb = ie.extrapolated_shear(size, E, 0.49, S, pts, levels=(8, 12, 16), knot=0.75)
    scale = np.linalg.norm(a, axis=1).max()
    assert np.linalg.norm(a - b, axis=1).max() < 2e-4 * scale
