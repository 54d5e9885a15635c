"""The nested dissection's separators: valid (they separate) and small (a minimum vertex
cover of the cut's edges), checked against a separator written here, the layer of left
vertices that touch the right side."""

from pathlib import Path

import meshio
import numpy as np
import scipy.sparse as sp
import skfem
from skfem.models.elasticity import lame_parameters, linear_elasticity

import harness.linalg.multifrontal as mf
from harness.linalg.sparse import dissection_tree


def p2_block():
    """The P2 elasticity matrix of the README's lug (gmsh's tetrahedra), its dofs' places."""
    lug = meshio.read(Path(__file__).parents[2] / "examples" / "lug.msh")
    m = skfem.MeshTet(lug.points.T, lug.cells_dict["tetra"].T)
    basis = skfem.Basis(m, skfem.ElementVector(skfem.ElementTetP2()))
    K = skfem.asm(linear_elasticity(*lame_parameters(1.0, 0.3)), basis)
    return sp.csr_matrix(K), basis.doflocs.T


def layer_tree(A, coords, leaf):
    """The same median bisection, the separator the left vertices that touch the right."""
    A = sp.csr_matrix((np.ones(A.nnz), A.indices, A.indptr), shape=A.shape)
    nodes = []

    def rec(idx):
        c = coords[idx][:, int(np.argmax(np.ptp(coords[idx], axis=0)))]
        left = c < np.median(c)
        if len(idx) <= leaf or left.all() or not left.any():
            nodes.append((idx, []))
            return len(nodes) - 1
        touch = np.asarray(A[idx[left]][:, idx[~left]].sum(axis=1)).ravel() > 0
        sep = np.zeros(len(idx), bool)
        sep[np.flatnonzero(left)[touch]] = True
        kids = [rec(part) for part in (idx[left & ~sep], idx[~left]) if len(part)]
        nodes.append((idx[sep], kids))
        return len(nodes) - 1

    rec(np.arange(A.shape[0]))
    return nodes


def separated(A, nodes) -> bool:
    """No edge joins the vertices under one child of a node to those under the other."""
    under = []
    for V, kids in nodes:
        under.append(np.concatenate([V] + [under[c] for c in kids]))
        if len(kids) == 2 and A[under[kids[0]]][:, under[kids[1]]].nnz:
            return False
    return True


def test_the_separators_separate_and_are_smaller_than_the_touching_layer(monkeypatch):
    A, coords = p2_block()
    ours, layer = dissection_tree(A, coords, leaf=64), layer_tree(A, coords, 64)
    assert separated(A, ours) and separated(A, layer)
    order = np.concatenate([V for V, _ in ours])
    assert np.array_equal(np.sort(order), np.arange(A.shape[0]))
    top = len(ours[-1][0]), len(layer[-1][0])  # the first cut, across the lug
    assert top[0] <= 0.85 * top[1], top
    work = mf.Symbolic(A, coords, leaf=64).estimate()["gflop"]
    monkeypatch.setattr(mf, "dissection_tree", layer_tree)
    assert work <= 0.6 * mf.Symbolic(A, coords, leaf=64).estimate()["gflop"]


def test_a_factorisation_on_the_tree_solves():
    A, coords = p2_block()
    fixed = coords[:, 0] <= coords[:, 0].min() + 1e-3
    A = A[~fixed][:, ~fixed]
    b = np.random.default_rng(0).normal(size=(A.shape[0], 2))
    x = mf.MultifrontalCholesky(A, mf.Symbolic(A, coords[~fixed], leaf=64)).solve(b)
    assert np.linalg.norm(A @ x - b) <= 1e-7 * np.linalg.norm(b)


def test_a_dense_cut_takes_the_smaller_touching_layer():
    """A matrix coupling dofs as widely as a coarse level's Galerkin matrix (A^2 of the lug's:
    ~500 nonzeros a row): its cuts are too dense for the matching, and the separator is the
    smaller of the two layers that touch the other side; it still separates."""
    from harness.linalg.sparse import DENSE_CUT

    A, coords = p2_block()
    A2 = sp.csr_matrix(abs(A) @ abs(A))
    tree = dissection_tree(A2, coords, leaf=64)
    assert separated(A2, tree)
    c = coords[:, 0]
    left = c < np.median(c)
    cut = A2[np.flatnonzero(left)][:, np.flatnonzero(~left)]
    touch_l = int((np.diff(cut.indptr) > 0).sum())
    touch_r = len(np.unique(cut.indices))
    assert cut.nnz > DENSE_CUT * (touch_l + touch_r)
    assert len(tree[-1][0]) == min(touch_l, touch_r)
