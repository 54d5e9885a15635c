"""The Kot & Nagahashi term of springs+kn (harness/models/kn.py): forces against finite
differences of the energy, no energy under rigid motions, the rank-one-per-node stiffness
against the force Jacobian and a hand-assembled sum, a square/cubic lattice's elastic
constants (from the model's energy of blocks of growing size) against the hand-derived
lambda = k/h + kn, mu = k/h, and recovery of known [k, kn] from a synthetic reference."""

import numpy as np
import pytest
from scipy.spatial import Delaunay
from scipy.spatial.transform import Rotation

from harness.linalg.sparse import single_thread_blas
from harness.models.kn import KNTerm, node_volumes
from harness.optimize import FitProblem, optimize
from harness.optimize.synthetic import basic_loads, grid_network
from tests.models.test_volume import grid_simplices
from tests.numdiff import energy_forces, force_jacobian


@pytest.fixture(autouse=True)
def _one_blas_thread():
    with single_thread_blas():
        yield


def random_term(dim, n=14, seed=0):
    """Random points, the Delaunay edges as springs, the Delaunay simplices' node volumes
    and random constants (one node kept without cells: it carries no term)."""
    rng = np.random.default_rng(seed)
    pts = rng.uniform(0, 1, (n, dim))
    tri = Delaunay(pts).simplices
    edges = np.unique(
        np.sort(np.concatenate([tri[:, [a, b]] for a in range(dim + 1) for b in range(a)]), axis=1),
        axis=0,
    )
    V = node_volumes(pts, tri)
    V[0] = 0.0
    t = KNTerm.build(pts, edges, V, 1.0)
    return pts, KNTerm.build(pts, edges, V, rng.uniform(0.5, 2.0, t.n_elements))


def test_node_volumes_tile_the_body_and_a_grid_node_owns_its_cell():
    for shape in ((5, 4), (4, 3, 3)):
        pts, _, _ = grid_network(shape)
        V = node_volumes(pts, grid_simplices(shape))
        assert V.sum() == pytest.approx(np.prod(np.array(shape) - 1.0), rel=1e-12)
        inner = np.all((pts > 0) & (pts < np.array(shape) - 1), axis=1)
        # h = 1: an interior node owns h^d
        assert inner.any() and np.allclose(V[inner], 1.0, rtol=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_force_is_minus_the_energy_gradient(dim):
    pts, t = random_term(dim)
    assert t.n_elements == len(pts) - 1  # the node without volume carries nothing
    x = pts + 0.05 * np.random.default_rng(3).standard_normal(pts.shape)
    f = t.forces(x)
    fd = energy_forces(t.energy, x)
    assert np.abs(f).max() > 0
    assert np.allclose(f.ravel(), fd, rtol=1e-6, atol=1e-7 * np.abs(fd).max())


@pytest.mark.parametrize("dim", [2, 3])
def test_rigid_motions_carry_no_energy(dim):
    pts, t = random_term(dim, seed=4)
    stretch = pts * 1.01
    scale_E, scale_f = t.energy(stretch), np.abs(t.forces(stretch)).max()
    assert scale_E > 0
    rng = np.random.default_rng(5)
    for angles in ([70, -40, 25], [1e-3, 0, 0]):  # degrees; 2-D: the first about z
        R = Rotation.from_euler(
            "zyx" if dim == 3 else "z", angles if dim == 3 else angles[0], degrees=True
        ).as_matrix()[:dim, :dim]
        x = pts @ R.T + rng.standard_normal(dim)
        assert t.energy(x) <= 1e-20 * scale_E + 1e-28
        assert np.abs(t.forces(x)).max() <= 1e-9 * scale_f
    # linearised: infinitesimal rotations and translations are in the kernel of K
    K = t.stiffness_matrix(pts)
    for a, b in ((0, 1), (1, 2))[: dim - 1]:
        W = np.zeros((dim, dim))
        W[a, b], W[b, a] = 1.0, -1.0
        u = pts @ W.T
        assert np.abs(K @ u.ravel()).max() <= 1e-12 * np.abs(K).max() * np.abs(u).max()
    u = np.tile(rng.standard_normal(dim), (len(pts), 1))
    assert np.abs(K @ u.ravel()).max() <= 1e-12 * np.abs(K).max() * np.abs(u).max()
    # a dilation u = x - c stretches every spring by 1 (strain), so s_a = 1 and u.K.u =
    # d^2 sum_a kn_a V_a (by hand)
    u = (pts - pts.mean(0)).ravel()
    assert u @ (K @ u) == pytest.approx(dim**2 * np.sum(t.kv * t.V), rel=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_linearised_stiffness_is_the_force_jacobian_and_rank_one_per_node(dim):
    pts, t = random_term(dim, seed=6)
    K = t.stiffness_matrix(pts).toarray()
    assert np.allclose(K, K.T)
    J = force_jacobian(t.forces, pts)
    assert np.allclose(K, J, rtol=1e-6, atol=1e-7 * np.abs(K).max())
    # by hand, node by node: c_a = d sqrt(V_a) / N_a sum over a's springs (i, j) of
    # (u_j - u_i) . n / L, n = (x_j - x_i) / L
    dense = np.zeros_like(K)
    for a, N, V, kn in zip(t.nodes, t.N, t.V, t.kv):
        c = np.zeros(pts.size)
        for i, j in t.springs:
            if a in (i, j):
                d = pts[j] - pts[i]
                L = np.linalg.norm(d)
                c[j * dim : (j + 1) * dim] += d / L / L
                c[i * dim : (i + 1) * dim] -= d / L / L
        c *= dim * np.sqrt(V) / N
        dense += kn * np.outer(c, c)
    assert np.allclose(K, dense, rtol=1e-12, atol=1e-13 * np.abs(K).max())


# -- the regular lattice: effective constants against the hand-derived formula ----------------


def lattice_energy(n, dim, h, k, kn, eps):
    """(1/2) u.K.u of springs (edges + face diagonals: the 2-D square lattice with both
    diagonals, edge constant 2k, diagonal k; 3-D every spring k) plus the term, on a block
    of n nodes per axis under u = eps x."""
    shape = (n,) * dim
    pts, spr, groups = grid_network(shape, spacing=h, diagonals="face")
    kk = np.full(len(spr), k)
    if dim == 2:
        kk[groups < 2] = 2 * k  # edges (groups 0, 1 = along x, y)
    t = KNTerm.build(pts, spr, node_volumes(pts, grid_simplices(shape)), kn)
    d = pts[spr[:, 1]] - pts[spr[:, 0]]
    L = np.linalg.norm(d, axis=1)
    u = pts @ eps.T
    # springs' linear stretch
    dl = np.einsum("ed,ed->e", d / L[:, None], u[spr[:, 1]] - u[spr[:, 0]])
    Ku = t.stiffness_matrix(pts) @ u.ravel()
    return 0.5 * np.sum(kk * dl**2) + 0.5 * u.ravel() @ Ku


def energy_per_cell(dim, h, k, kn, eps):
    """The leading coefficient of E(n), a polynomial of degree dim in n (counts of springs
    and of interior, face, edge and corner nodes are): the energy of one cell of the
    infinite lattice, exactly, from blocks of n = 2 .. dim + 2 nodes per axis."""
    ns = np.arange(2, dim + 3)
    E = [lattice_energy(n, dim, h, k, kn, eps) for n in ns]
    coef = np.polyfit(ns - 1.0, E, dim)
    check = np.polyval(coef, dim + 2.0)  # and n = dim + 3 lies on it
    assert lattice_energy(dim + 3, dim, h, k, kn, eps) == pytest.approx(check, rel=1e-9)
    return coef[0]


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("kn_over", [0.0, 3.0, -1.0, -5.0 / 3.0 + 1e-3])
def test_lattice_elastic_constants_and_nu_match_the_hand_formula(dim, kn_over):
    """Hand derivation (docstring of harness/models/kn.py): mu = k/h (3-D; 2-D: k, per unit
    thickness), lambda = mu + kn, so 3-D nu = (mu + kn) / (4 mu + 2 kn) (1/4 at kn = 0, -1 as
    the bulk modulus 5 mu / 3 + kn -> 0), 2-D plane stress nu = (mu + kn) / (3 mu + kn)."""
    h, k = 0.5, 2.0
    mu = k / h if dim == 3 else k
    kn = kn_over * mu
    cell = h**dim

    def C(eps):
        return 2 * energy_per_cell(dim, h, k, kn, eps) / cell  # eps : C : eps

    e = np.eye(dim)
    C11 = C(np.outer(e[0], e[0]))
    C12 = (C(np.outer(e[0], e[0]) + np.outer(e[1], e[1])) - 2 * C11) / 2
    C44 = C(np.outer(e[0], e[1]) + np.outer(e[1], e[0])) / 4  # eps_xy = eps_yx = 1: 4 C44
    lam = mu + kn
    assert C11 == pytest.approx(lam + 2 * mu, rel=1e-9)
    assert C12 == pytest.approx(lam, rel=1e-9, abs=1e-9 * mu)
    assert C44 == pytest.approx(mu, rel=1e-9)
    assert C11 - C12 == pytest.approx(2 * C44, rel=1e-9)  # isotropic
    nu = C12 / (C11 + C12) if dim == 3 else C12 / C11  # uniaxial stress (2-D: plane stress)
    hand = (1 + kn_over) / (4 + 2 * kn_over) if dim == 3 else (1 + kn_over) / (3 + kn_over)
    assert nu == pytest.approx(hand, rel=1e-9, abs=1e-12)
    if kn_over == 0.0:
        assert nu == pytest.approx(0.25 if dim == 3 else 1 / 3)  # the Cauchy value
    # a rotated shear (a pure deviatoric strain in other axes) sees the same mu: isotropy
    R = Rotation.from_euler("z", 27, degrees=True).as_matrix()[:dim, :dim]
    dev = R @ np.diag([1.0, -1.0] + [0.0] * (dim - 2)) @ R.T
    assert C(dev) == pytest.approx(2 * mu * np.sum(dev * dev), rel=1e-9)


# -- recoverability: a reference made by the model is fitted back ---------------------------


def dense_K(pts, spr, t, k, kn):
    """Springs k_e b_e b_e^T plus kn_a c_a c_a^T with c_a = t.columns (checked above)."""
    dim = pts.shape[1]
    d = pts[spr[:, 1]] - pts[spr[:, 0]]
    d /= np.linalg.norm(d, axis=1)[:, None]
    K = np.zeros((pts.size, pts.size))
    for s_, (i, j) in enumerate(spr):
        b = np.zeros(pts.size)
        b[i * dim : (i + 1) * dim], b[j * dim : (j + 1) * dim] = -d[s_], d[s_]
        K += k[s_] * np.outer(b, b)
    C = t.columns(pts).toarray()
    return K + (C * kn) @ C.T


@pytest.mark.parametrize(
    "shape, shared, method",
    [
        ((4, 3), False, "gauss-newton"),
        ((3, 3, 3), True, "lbfgs"),
        ((4, 3), True, "gauss-newton"),
        ((4, 3), False, "equilibrium-gap"),
    ],
)
def test_known_springs_and_kn_constants_are_recovered(shape, shared, method):
    pts, spr, _ = grid_network(shape, diagonals="face")
    t = KNTerm.build(pts, spr, node_volumes(pts, grid_simplices(shape)), 1.0, shared=shared)
    e, m = len(spr), t.n_elements
    L = np.linalg.norm(pts[spr[:, 1]] - pts[spr[:, 0]], axis=1)
    k0 = np.concatenate([1.0 / L, np.full(m, 0.5)])
    pg = np.concatenate([np.arange(e), np.full(m, e) if shared else e + np.arange(m)])
    rng = np.random.default_rng(3)
    truth = k0 * np.exp(0.3 * rng.standard_normal(pg.max() + 1))[pg]
    names, frees, forces = basic_loads(pts, s=float(np.prod(shape)) ** (1 / len(shape)))
    K = dense_K(pts, spr, t, truth[:e], truth[e:])
    U = np.zeros_like(forces)
    for i, (fr, f) in enumerate(zip(frees, forces)):
        U[i, fr] = np.linalg.solve(K[np.ix_(fr, fr)], f[fr])
    prob = FitProblem.from_network(
        pts,
        spr,
        k0,
        frees,
        forces,
        U,
        np.ones(pts.size),
        names,
        groups=pg if shared else None,
        extra_columns=t.columns(pts),
    )
    assert prob.G(truth) <= 1e-10 * prob.G_ref_norm()  # the sparse solve = the dense one
    assert np.max(np.abs(k0[e:] / truth[e:] - 1)) > 0.05  # the start is off
    res = optimize(prob, method, {}, seed=0)
    assert res.G_final / res.G_initial <= 1e-8
    assert np.max(np.abs(res.k / truth - 1)) < 1e-6
    if shared:
        assert np.ptp(res.k[e:]) <= 1e-12 * res.k[e]
