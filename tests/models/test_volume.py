"""The volume term of springs + volume (harness/models/volume.py): volumes against
determinants and hand cases, forces against finite differences of the energy, zero energy
under rigid motions, the rank-one stiffness against the finite-difference Jacobian of the
force, statics against a dense solve, the adjoint gradient over [k, kv] against finite
differences of G, and recovery of known constants from a synthetic reference."""

import numpy as np
import pytest
from scipy.spatial import Delaunay
from scipy.spatial.transform import Rotation

from harness.linalg.sparse import single_thread_blas
from harness.models.cells import hex_to_tets
from harness.models.volume import VolumeTerm, volume_gradients, volumes
from harness.optimize import FitProblem, optimize
from harness.optimize.evaluation import value_and_grad
from harness.optimize.synthetic import basic_loads, grid_network
from tests.numdiff import energy_forces, force_jacobian


@pytest.fixture(autouse=True)
def _one_blas_thread():
    with single_thread_blas():
        yield


def random_mesh(dim, n=14, seed=0):
    """Random points in the unit square/cube and their Delaunay simplices."""
    rng = np.random.default_rng(seed)
    pts = rng.uniform(0, 1, (n, dim))
    return pts, Delaunay(pts).simplices


def grid_simplices(shape):
    """Simplices of the grid_network nodes (node = i + nx*j (+ nx*ny*l)): quads split in
    two triangles, hexahedra (VTK order) in six tetrahedra."""
    ids = np.arange(int(np.prod(shape))).reshape(shape, order="F")
    if len(shape) == 2:
        a, b, c, d = ids[:-1, :-1], ids[1:, :-1], ids[1:, 1:], ids[:-1, 1:]
        q = np.stack([a.ravel(), b.ravel(), c.ravel(), d.ravel()], 1)
        return np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
    s = (slice(None, -1), slice(1, None))
    h = [
        ids[s[i]][:, s[j]][:, :, s[l]].ravel()
        for (i, j, l) in [
            (0, 0, 0),
            (1, 0, 0),
            (1, 1, 0),
            (0, 1, 0),
            (0, 0, 1),
            (1, 0, 1),
            (1, 1, 1),
            (0, 1, 1),
        ]
    ]
    return hex_to_tets(np.stack(h, 1))


@pytest.mark.parametrize("dim", [2, 3])
def test_volumes_match_determinants_and_hand_cases(dim):
    pts, el = random_mesh(dim)
    a = pts[el[:, 1:]] - pts[el[:, :1]]
    fact = 2.0 if dim == 2 else 6.0
    assert np.allclose(volumes(pts, el), np.linalg.det(a) / fact, rtol=1e-12, atol=1e-15)
    unit = np.vstack([np.zeros(dim), np.eye(dim)])  # the unit right simplex: 1/2, 1/6
    assert volumes(unit, np.arange(dim + 1)[None])[0] == pytest.approx(1 / fact)
    # its gradient by hand: dV/dx_i = unit normal of the opposite face times its size / dim
    g = volume_gradients(unit, np.arange(dim + 1)[None])[0]
    assert np.allclose(g[1:], np.eye(dim) / fact)
    assert np.allclose(g[0], -np.ones(dim) / fact)
    # the Delaunay hull is tiled: the volumes (made positive) sum to the hull's
    from scipy.spatial import ConvexHull

    assert np.abs(volumes(pts, el)).sum() == pytest.approx(ConvexHull(pts).volume, rel=1e-12)


def term(dim, seed=0):
    pts, el = random_mesh(dim, seed=seed)
    rng = np.random.default_rng(seed + 1)
    return pts, VolumeTerm.build(pts, el, rng.uniform(0.5, 2.0, len(el)))


@pytest.mark.parametrize("dim", [2, 3])
def test_force_is_minus_the_energy_gradient(dim):
    pts, vol = term(dim)
    assert np.all(vol.V0 > 0)  # build() orients every element
    x = pts + 0.05 * np.random.default_rng(3).standard_normal(pts.shape)
    f = vol.forces(x)
    fd = energy_forces(vol.energy, x)
    assert np.allclose(f.ravel(), fd, rtol=1e-6, atol=1e-8 * np.abs(fd).max())
    assert np.abs(f).max() > 0


@pytest.mark.parametrize("dim", [2, 3])
def test_rigid_motions_carry_no_energy(dim):
    pts, vol = term(dim, seed=4)
    stretch = pts * 1.01  # the scale of a real deformation
    scale_E, scale_f = vol.energy(stretch), np.abs(vol.forces(stretch)).max()
    assert scale_E > 0
    rng = np.random.default_rng(5)
    large = [70, -40, 25] if dim == 3 else [0, 0, 70]  # degrees (2-D: about z)
    small = [0, 1e-3, 0] if dim == 3 else [0, 0, 1e-3]
    for angles in (large, small):
        R = Rotation.from_euler(
            "zyx", angles[::-1] if dim == 2 else angles, degrees=True
        ).as_matrix()[:dim, :dim]
        x = pts @ R.T + rng.standard_normal(dim)
        assert vol.energy(x) <= 1e-20 * scale_E + 1e-28
        assert np.abs(vol.forces(x)).max() <= 1e-10 * scale_f
    # linearised: infinitesimal rotations and translations are in the kernel of K_v
    K = vol.stiffness_matrix(pts)
    W = np.zeros((dim, dim))
    W[0, 1], W[1, 0] = 1.0, -1.0
    for u in (pts @ W.T, np.tile(rng.standard_normal(dim), (len(pts), 1))):
        assert np.abs(K @ u.ravel()).max() <= 1e-12 * np.abs(K).max() * np.abs(u).max()
    # a dilation u = x - c is not: each element's dV = dim V0, so u.K.u = dim^2 sum kv V0 (by hand)
    u = (pts - pts.mean(0)).ravel()
    assert u @ (K @ u) == pytest.approx(dim**2 * np.sum(vol.kv * vol.V0), rel=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_linearised_stiffness_is_the_force_jacobian_at_rest(dim):
    pts, vol = term(dim, seed=6)
    K = vol.stiffness_matrix(pts).toarray()
    assert np.allclose(K, K.T)
    J = force_jacobian(vol.forces, pts)
    assert np.allclose(K, J, rtol=1e-6, atol=1e-7 * np.abs(K).max())
    # rank one per element: each element's block is (kv/V0) g g^T (a hand-assembled dense sum)
    g = volume_gradients(pts, vol.elements)
    dense = np.zeros_like(K)
    for e, nodes in enumerate(vol.elements):
        dofs = (nodes[:, None] * dim + np.arange(dim)).ravel()
        ge = g[e].ravel()
        dense[np.ix_(dofs, dofs)] += vol.kv[e] / vol.V0[e] * np.outer(ge, ge)
    assert np.allclose(K, dense, rtol=1e-12, atol=1e-14 * np.abs(K).max())


# -- springs + volume: statics and calibration ---------------------------------------------


def dense_K(pts, spr, el, params):
    """K of springs (outer products of b_e) plus volume blocks, dense, written here."""
    dim = pts.shape[1]
    e = len(spr)
    d = pts[spr[:, 1]] - pts[spr[:, 0]]
    d /= np.linalg.norm(d, axis=1)[:, None]
    K = np.zeros((pts.size, pts.size))
    for s_, (i, j) in enumerate(spr):
        b = np.zeros(pts.size)
        b[i * dim : (i + 1) * dim], b[j * dim : (j + 1) * dim] = -d[s_], d[s_]
        K += params[s_] * np.outer(b, b)
    vol = VolumeTerm.build(pts, el, 1.0)
    g = volume_gradients(pts, vol.elements)
    for m_, nodes in enumerate(vol.elements):
        dofs = (nodes[:, None] * dim + np.arange(dim)).ravel()
        K[np.ix_(dofs, dofs)] += (
            params[e + m_] / vol.V0[m_] * np.outer(g[m_].ravel(), g[m_].ravel())
        )
    return K


def sv_setup(shape, seed=0, shared=False, grouped=False, sigma=0.3):
    """A grid of springs with a volume element per simplex, its basic loads, a reference
    from known perturbed [k, kv] (dense solve) and the FitProblem from k0."""
    pts, spr, groups = grid_network(shape, diagonals="face")
    el = grid_simplices(shape)
    rng = np.random.default_rng(seed)
    L = np.linalg.norm(pts[spr[:, 1]] - pts[spr[:, 0]], axis=1)
    e, m = len(spr), len(el)
    k0 = np.concatenate([1.0 / L, np.full(m, 0.5)])
    if grouped:
        pg = np.concatenate([groups, np.full(m, groups.max() + 1)])
    elif shared:
        pg = np.concatenate([np.arange(e), np.full(m, e)])
    else:
        pg = np.arange(e + m)
    truth = k0 * np.exp(sigma * rng.standard_normal(pg.max() + 1))[pg]
    names, frees, forces = basic_loads(pts, s=float(np.prod(shape)) ** (1 / len(shape)))
    K = dense_K(pts, spr, el, truth)
    U = np.zeros_like(forces)
    for i, (fr, f) in enumerate(zip(frees, forces)):
        U[i, fr] = np.linalg.solve(K[np.ix_(fr, fr)], f[fr])
    cols = VolumeTerm.build(pts, el, 1.0).columns(pts)
    prob = FitProblem.from_network(
        pts,
        spr,
        k0,
        frees,
        forces,
        U,
        np.ones(pts.size),
        names,
        groups=None if pg.max() + 1 == e + m else pg,
        extra_columns=cols,
    )
    return prob, truth, dict(pts=pts, spr=spr, el=el, frees=frees, forces=forces, U=U)


@pytest.mark.parametrize("shape", [(4, 3), (3, 3, 3)])
def test_statics_and_adjoint_gradient_over_springs_and_volumes(shape):
    prob, truth, a = sv_setup(shape, seed=2)
    assert prob.G(truth) <= 1e-10 * prob.G_ref_norm()  # the problem's sparse solve = the dense one
    rng = np.random.default_rng(1)
    k = prob.k0 * np.exp(0.2 * rng.standard_normal(prob.n_springs))
    _, g = value_and_grad(prob, k)
    e = len(a["spr"])
    idx = np.concatenate(
        [rng.choice(e, 4, replace=False), e + rng.choice(prob.n_springs - e, 6, replace=False)]
    )
    h = 1e-4
    for i in idx:
        kp, km = k.copy(), k.copy()
        kp[i] *= 1 + h
        km[i] *= 1 - h
        ref = (
            value_and_grad(prob, kp, grad=False)[0] - value_and_grad(prob, km, grad=False)[0]
        ) / (2 * h * k[i])
        assert g[i] == pytest.approx(ref, rel=1e-5, abs=1e-7 * np.abs(g).max())
    # the per-element formula, dense: dG^2/dkv_e = 2 sum_loads (lambda . gV_e)(u . gV_e) / V0_e
    pts = a["pts"]
    vol = VolumeTerm.build(pts, a["el"], 1.0)
    dim = pts.shape[1]
    gv = volume_gradients(pts, vol.elements).reshape(vol.n_elements, -1)
    dofs = (vol.elements[:, :, None] * dim + np.arange(dim)).reshape(vol.n_elements, -1)
    K = dense_K(pts, a["spr"], a["el"], k)
    mine = np.zeros(vol.n_elements)
    for fr, f, ur in zip(a["frees"], a["forces"], a["U"]):
        u, lam = np.zeros(pts.size), np.zeros(pts.size)
        Kf = K[np.ix_(fr, fr)]
        u[fr] = np.linalg.solve(Kf, f[fr])
        lam[fr] = np.linalg.solve(Kf, ur[fr] - u[fr])
        mine += (
            2 * np.einsum("ed,ed->e", gv, lam[dofs]) * np.einsum("ed,ed->e", gv, u[dofs]) / vol.V0
        )
    assert np.allclose(g[e:], mine, rtol=1e-8, atol=1e-10 * np.abs(mine).max())


@pytest.mark.parametrize(
    "shape, mode, method",
    [
        ((4, 3), "element", "gauss-newton"),
        ((4, 3), "element", "equilibrium-gap"),
        ((3, 3, 3), "shared", "lbfgs"),
        ((3, 3, 3), "grouped", "gauss-newton"),
    ],
)
def test_known_springs_and_volume_constants_are_recovered(shape, mode, method):
    """A reference made by springs + volume with known [k, kv] is fitted back: G -> 0 and
    every constant (per element, one per body, or per spring group) found."""
    prob, truth, a = sv_setup(shape, seed=3, shared=mode == "shared", grouped=mode == "grouped")
    e = len(a["spr"])
    assert np.max(np.abs(prob.k0[e:] / truth[e:] - 1)) > 0.05  # the start is off
    res = optimize(prob, method, {}, seed=0)
    assert res.G_final / res.G_initial <= 1e-8
    assert np.max(np.abs(res.k[e:] / truth[e:] - 1)) < 1e-6
    assert np.max(np.abs(res.k / truth - 1)) < 1e-6
    if mode == "shared":
        assert np.ptp(res.k[e:]) <= 1e-12 * res.k[e]  # one constant for the body
