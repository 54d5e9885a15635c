"""reference/solvers/linearfield.py (loads whose FE solution is linear, found by a Galerkin solve
over the linear fields and accepted by the solvers' residual test) against the closed
form of a stretch (u_a = s (a - a0) / E, u_b = -nu s (b - b0) / E), on P2 tetrahedra
(assembled K) and on a graded Q2 box (the Kronecker operator); a shear, whose solution
is not linear, is left to the solver (the Cholesky's answer, checked here)."""

from __future__ import annotations

import numpy as np
import pytest
import skfem

from harness.case.elasticity import isotropic_compliance
from reference.fem import Discretisation
from reference.graded.meshes import graded_axes, tensor_mesh
from reference.problem import solve_system
from reference.solvers import linearfield

E, NU, S = 210.0, 0.49, 2.0
SIZE = np.array([4.0, 1.0, 0.7])


def _disc(cell: str) -> Discretisation:
    if cell == "hex":
        return Discretisation(tensor_mesh(graded_axes(np.zeros(3), SIZE, 2)), "hex", "P2")
    mesh = skfem.MeshTet.init_tensor(*[np.linspace(0, s, k) for s, k in zip(SIZE, (9, 3, 3))])
    return Discretisation(mesh, "tet", "P2")


def _stretch(d: Discretisation):
    """stretch-x: roller on x = 0, the corner (0, 0, 0) fixed in y, z, (0, 1, 0) in z."""
    x = d.doflocs
    at = lambda p, q: np.all(np.abs(x - np.array(q)[:, None]) < 1e-9, axis=0)  # noqa: E731, ARG005
    fixed = np.unique(
        np.concatenate(
            [
                d.part_dofs(lambda p: p[0] < 1e-9, [0]),
                d.part_dofs(lambda p: at(p, (0, 0, 0)), [1, 2]),
                d.part_dofs(lambda p: at(p, (0, SIZE[1], 0)), [2]),
            ]
        )
    )
    F = d.traction_load(d.part_facets(lambda p: p[0] > SIZE[0] - 1e-9), (S, 0.0, 0.0))
    return fixed, F


@pytest.mark.parametrize("cell", ["tet", "hex"])
def test_a_stretch_is_its_closed_form_without_a_solve(cell):
    d = _disc(cell)
    C = np.tile(np.linalg.inv(isotropic_compliance(E, NU)), (d.nelems, 1, 1))
    fixed, F = _stretch(d)
    info: list = []
    U = solve_system(
        lambda: d.stiffness(C), {"stretch": F}, {"stretch": fixed}, "auto", d, records=info, C=C
    )
    want = -NU * S / E * d.doflocs.T
    want[:, 0] = S / E * d.doflocs[0]
    assert info[0].method == "linear" and info[0].residual <= 1e-10
    assert np.abs(U["stretch"] - want.ravel()).max() <= 1e-11 * np.abs(want).max()


def test_a_shear_is_not_linear_and_goes_to_the_solver():
    d = _disc("tet")
    C = np.tile(np.linalg.inv(isotropic_compliance(E, NU)), (d.nelems, 1, 1))
    K = d.stiffness(C)
    fixed = d.part_dofs(lambda p: p[2] < 1e-9, range(3))
    F = d.traction_load(d.part_facets(lambda p: p[2] > SIZE[2] - 1e-9), (S, 0.0, 0.0))
    assert (
        linearfield.solve(
            lambda V: K @ V, d.doflocs, F[:, None], fixed, float(abs(K).sum(axis=1).max())
        )
        is None
    )
    info: list = []
    U = solve_system(K, {"shear": F}, {"shear": fixed}, "auto", d, records=info, C=C)
    free = np.setdiff1d(np.arange(d.ndof), fixed)
    want = np.zeros(d.ndof)
    want[free] = np.linalg.solve(K[free][:, free].toarray(), F[free])
    assert info[0].method != "linear"
    assert np.abs(U["shear"] - want).max() <= 1e-8 * np.abs(want).max()
