"""reference/solvers/kronecker.py (the graded boxes' Q2 stiffness as Kronecker products, applied
without assembly) against independent truths: the 1-D matrices against the Q2 element
matrices written out by hand; K u against the stiffness scikit-fem assembles from a
bilinear form written here (isotropic and orthotropic, 3-D hexahedra and 2-D
quadrilaterals on graded tensor meshes); its diagonal and norm bound against that
matrix's."""

from __future__ import annotations

import numpy as np
import pytest
import skfem
from skfem.helpers import sym_grad

from harness.case.elasticity import isotropic_compliance
from reference.graded.meshes import graded_axes, tensor_mesh
from reference.lattice import Lattice
from reference.solvers.kronecker import KroneckerStiffness, axis_matrices
from tests.reference.test_tensorpre import _orthotropic


def test_axis_matrices_are_the_q2_element_matrices():
    nodes = np.array([0.0, 0.15, 0.3, 0.8, 1.3])  # two cells, 0.3 and 1.0 long
    m = axis_matrices(nodes)
    Me = np.array([[4, 2, -1], [2, 16, 2], [-1, 2, 4]]) / 30.0
    Ae = np.array([[7, -8, 1], [-8, 16, -8], [1, -8, 7]]) / 3.0
    De = np.array([[-3, -4, 1], [4, 0, -4], [-1, 4, 3]]) / 6.0  # int N_i' N_j on [0, 1]
    M0, A0, D0 = np.zeros((5, 5)), np.zeros((5, 5)), np.zeros((5, 5))
    for s, h in ((slice(0, 3), 0.3), (slice(2, 5), 1.0)):
        M0[s, s] += h * Me
        A0[s, s] += Ae / h
        D0[s, s] += De
    np.testing.assert_allclose(m["M"], M0, atol=1e-14)
    np.testing.assert_allclose(m["A"], A0, atol=1e-13)
    np.testing.assert_allclose(m["D"], D0, atol=1e-14)
    np.testing.assert_allclose(m["Dt"], D0.T, atol=1e-14)


def _skfem_stiffness(mesh, C: np.ndarray):
    """K of sigma = C eps (Voigt, engineering shears) with scikit-fem's own vector basis."""
    dim = mesh.p.shape[0]
    elem = skfem.ElementVector(skfem.ElementHex2() if dim == 3 else skfem.ElementQuad2())
    basis = skfem.Basis(mesh, elem, intorder=4)
    pairs = (
        [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)] if dim == 3 else [(0, 0), (1, 1), (0, 1)]
    )

    def voigt(e):
        return [e[i, j] if i == j else 2 * e[i, j] for i, j in pairs]

    @skfem.BilinearForm
    def form(u, v, _):
        eu, ev = voigt(sym_grad(u)), voigt(sym_grad(v))
        return sum(C[a, b] * eu[b] * ev[a] for a in range(len(pairs)) for b in range(len(pairs)))

    return basis, form.assemble(basis)


@pytest.mark.parametrize("dim,material", [(3, "iso"), (3, "ortho"), (2, "iso"), (2, "ortho")])
def test_apply_equals_the_assembled_stiffness(dim, material):
    size = np.array([3.0, 1.0, 1.5][:dim])
    mesh = tensor_mesh(graded_axes(np.zeros(dim), size, 2))
    C = _orthotropic(dim) if material == "ortho" else np.linalg.inv(isotropic_compliance(1e3, 0.45))
    if dim == 2 and material == "iso":
        C = C[np.ix_([0, 1, 5], [0, 1, 5])]  # plane strain
    basis, K = _skfem_stiffness(mesh, C)
    # scikit-fem's vector dofs: component c of scalar node i at basis.nodal_dofs / ... (interleaved)
    locs = basis.doflocs[:, ::dim]
    grid = Lattice.of(locs)
    op = KroneckerStiffness.of(grid.axes, C)
    u = np.random.default_rng(3).standard_normal(K.shape[0])
    U = np.zeros((dim, int(np.prod(grid.shape))))
    U[:, grid.index] = u.reshape(-1, dim).T
    KU = op.apply(U.reshape(op.shape)).reshape(dim, -1)[:, grid.index].T.ravel()
    Ku = K @ u
    assert np.abs(KU - Ku).max() <= 1e-12 * np.abs(Ku).max()
    diag = op.diagonal().reshape(dim, -1)[:, grid.index].T.ravel()
    np.testing.assert_allclose(diag, K.diagonal(), rtol=1e-12)
    true = float(abs(K).sum(axis=1).max())
    assert true <= op.norm_bound() <= 1.5 * true
