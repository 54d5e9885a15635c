"""The volume term per node (harness/models/volume.py NodeVolumeTerm): forces against finite
differences of its energy, no energy under rigid motions, the rank-one-per-node stiffness
against the force Jacobian and a hand-assembled sum, the nodal dilatation of a homogeneous
strain (tr eps at every node, boundary ones too: the term adds kv to lambda), no locking
where one term per element locks, the save/load round trip and the exported JSON's
stiffness (written independently in harness/bench/heldout_judge.py) against the model's."""

import json

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.spatial.transform import Rotation

from harness.models.springs import incidence, stiffness_matrix
from harness.models.volume import NodeVolumeTerm, VolumeTerm, volume_gradients, volumes
from tests.models.test_volume import grid_simplices, random_mesh
from tests.numdiff import energy_forces, force_jacobian


def term(dim, seed=0, n=14):
    pts, el = random_mesh(dim, n=n, seed=seed)
    vol = NodeVolumeTerm.build(pts, el, 1.0)
    kv = np.random.default_rng(seed + 1).uniform(0.5, 2.0, vol.n_elements)
    return pts, NodeVolumeTerm.build(pts, el, kv)


@pytest.mark.parametrize("dim", [2, 3])
def test_force_is_minus_the_energy_gradient(dim):
    pts, vol = term(dim)
    x = pts + 0.05 * np.random.default_rng(3).standard_normal(pts.shape)
    f = vol.forces(x)
    fd = energy_forces(vol.energy, x)
    assert np.allclose(f.ravel(), fd, rtol=1e-6, atol=1e-8 * np.abs(fd).max())
    assert np.abs(f).max() > 0


@pytest.mark.parametrize("dim", [2, 3])
def test_rigid_motions_carry_no_energy(dim):
    pts, vol = term(dim, seed=4)
    scale_E = vol.energy(pts * 1.01)
    assert scale_E > 0
    R = Rotation.from_euler(
        "zyx", [70, -40, 25] if dim == 3 else [70, 0, 0], degrees=True
    ).as_matrix()[:dim, :dim]
    x = pts @ R.T + np.random.default_rng(5).standard_normal(dim)
    assert vol.energy(x) <= 1e-20 * scale_E + 1e-28
    assert np.abs(vol.forces(x)).max() <= 1e-10 * np.abs(vol.forces(pts * 1.01)).max()


@pytest.mark.parametrize("dim", [2, 3])
def test_linearised_stiffness_is_the_force_jacobian_and_a_sum_over_nodes(dim):
    pts, vol = term(dim, seed=6)
    K = vol.stiffness_matrix(pts).toarray()
    assert np.allclose(K, K.T)
    assert np.allclose(K, force_jacobian(vol.forces, pts), rtol=1e-6, atol=1e-7 * np.abs(K).max())
    # by hand: node a's column sums grad V_e / (dim + 1) over its elements
    g = volume_gradients(pts, vol.elements)
    dense = np.zeros_like(K)
    for a, node in enumerate(vol.nodes):
        c = np.zeros(pts.size)
        for e, nodes in enumerate(vol.elements):
            if node in nodes:
                for i, j in enumerate(nodes):
                    c[j * dim : (j + 1) * dim] += g[e, i] / (dim + 1)
        dense += vol.kv[a] / vol.Vn[a] * np.outer(c, c)
    assert np.allclose(K, dense, rtol=1e-12, atol=1e-14 * np.abs(K).max())


@pytest.mark.parametrize("dim", [2, 3])
def test_a_homogeneous_strain_gives_its_trace_at_every_node(dim):
    pts, vol = term(dim, seed=8, n=40)
    eps = np.random.default_rng(9).standard_normal((dim, dim)) * 1e-3
    eps = 0.5 * (eps + eps.T)
    u = (pts - pts.mean(0)) @ eps.T
    C = vol.columns(pts)
    dV = np.sqrt(vol.Vn) * (C.T @ u.ravel())  # the linearised dV_a
    assert np.allclose(dV / vol.Vn, np.trace(eps), rtol=1e-10)
    # the energy is then kv/2 tr(eps)^2 times the body's volume: kv joins lambda
    K = NodeVolumeTerm.build(pts, vol.elements, 3.0).stiffness_matrix(pts)
    assert 0.5 * u.ravel() @ (K @ u.ravel()) == pytest.approx(
        0.5 * 3.0 * np.trace(eps) ** 2 * volumes(pts, vol.elements).sum(), rel=1e-10
    )
    assert np.all(vol.Vn > 0) and vol.Vn.sum() == pytest.approx(vol.V0.sum(), rel=1e-12)


def beam(shape=(9, 3, 3)):
    """A grid beam of unit cubes split in tetrahedra: points, tets, its edges."""
    ids = np.arange(int(np.prod(shape))).reshape(shape, order="F")
    grid = np.stack(np.meshgrid(*[np.arange(s) for s in shape], indexing="ij"), -1)
    pts = np.zeros((ids.size, 3))
    pts[ids.ravel()] = grid.reshape(-1, 3)
    el = grid_simplices(shape)
    edges = np.unique(
        np.sort(np.concatenate([el[:, [a, b]] for a in range(4) for b in range(a + 1, 4)]), 1),
        axis=0,
    )
    return pts, el, edges


def tip_deflection(pts, K):
    """The mean tip deflection of the beam clamped at x = 0 under a unit tip load along -z."""
    n = len(pts)
    free = np.flatnonzero(np.repeat(pts[:, 0] > 0, 3))
    tip = pts[:, 0] == pts[:, 0].max()
    f = np.zeros((n, 3))
    f[tip, 2] = -1.0 / tip.sum()
    u = np.zeros(3 * n)
    K = sp.csc_matrix(K)
    u[free] = spla.spsolve(K[free][:, free], f.ravel()[free])
    return -u.reshape(n, 3)[tip, 2].mean()


def test_one_term_per_element_locks_one_per_node_does_not():
    """Clamped beam, unit springs on the edges: a stiff volume term per element leaves the
    beam barely able to bend (constraints ~ 0.9 per free dof), one per node (~ 0.4 per
    free dof) keeps most of the springs' bending, as nearly incompressible continua do."""
    pts, el, edges = beam()
    Ks = stiffness_matrix(incidence(pts, edges), np.ones(len(edges)))
    d0 = tip_deflection(pts, Ks)
    kv = 1e3  # the springs' modulus ~ 1 (k / h)
    element = tip_deflection(pts, Ks + VolumeTerm.build(pts, el, kv).stiffness_matrix(pts)) / d0
    node = tip_deflection(pts, Ks + NodeVolumeTerm.build(pts, el, kv).stiffness_matrix(pts)) / d0
    assert element < 0.25
    assert node > 0.5


def test_save_load_and_the_exported_stiffness(tmp_path):
    from harness.bench.heldout_judge import network_stiffness
    from harness.export.model_json import export
    from harness.mechanics.statics import _stiffness
    from harness.models.sms import SpringNetwork
    from harness.models.volume import load, save, with_volume

    pts, el, edges = beam((4, 2, 2))
    pts = pts * 0.1
    rng = np.random.default_rng(2)
    net = SpringNetwork(
        points=pts,
        springs=edges,
        k=rng.uniform(1, 2, len(edges)),
        masses=np.full(len(pts), 0.01),
        classes=np.zeros(len(pts), int),
        groups=np.zeros(len(edges), int),
        cells={"tetra": el},
        info={"stiffness": "test"},
    )
    vnet = with_volume(net, "node", rng.uniform(1e3, 2e3, len(pts)))
    assert isinstance(vnet.volume, NodeVolumeTerm)
    save(tmp_path / "v.npz", vnet)
    back = load(tmp_path / "v.npz", net)
    assert isinstance(back.volume, NodeVolumeTerm) and np.array_equal(
        back.volume.kv, vnet.volume.kv
    )
    K = _stiffness(vnet).toarray()
    assert np.allclose(_stiffness(back).toarray(), K, rtol=1e-14, atol=0)
    data = export(vnet, tmp_path / "m.vtu")
    assert "volume_indices" not in data and len(data["node_volume_nodes"]) == len(pts)
    assert json.loads((tmp_path / "m.json").read_text())["node_volume_shared"] is False
    assert np.allclose(
        network_stiffness(data).toarray(), K, rtol=1e-10, atol=1e-12 * np.abs(K).max()
    )
