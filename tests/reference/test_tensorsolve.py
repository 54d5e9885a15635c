"""reference/solvers/tensorsolve.py (the graded boxes' CG without an assembled matrix) against a
dense solve of the stiffness scikit-fem assembles from a form written in
tests/reference/test_kronecker.py: whole faces clamped and a mirror plane fixing one
component, two loads at once; an exact initial guess needs no iteration; and the graded
levels give the same fields whether a cut's load groups run in one thread or two."""

from __future__ import annotations

import numpy as np
import pytest

from harness.case.elasticity import isotropic_compliance
from reference.graded import levels
from reference.graded.meshes import graded_axes, q2_doflocs, tensor_mesh
from reference.lattice import Lattice
from reference.solvers import plan, tensorsolve
from tests.reference.test_graded import box_case
from tests.reference.test_kronecker import _skfem_stiffness


def _problem():
    mesh = tensor_mesh(graded_axes(np.zeros(3), np.array([3.0, 1.0, 1.0]), 2))
    C = np.linalg.inv(isotropic_compliance(1e3, 0.49))
    basis, K = _skfem_stiffness(mesh, C)
    x = basis.doflocs[:, ::3]
    nodes = lambda f: np.flatnonzero(f(x))  # noqa: E731
    fixed = np.unique(
        np.concatenate(
            [
                (3 * nodes(lambda p: p[2] < 1e-9)[:, None] + np.arange(3)).ravel(),  # clamped z0
                3 * nodes(lambda p: p[1] < 1e-9) + 1,
            ]
        )
    )  # u_y = 0 on y0
    b = np.zeros((K.shape[0], 2))
    top = nodes(lambda p: p[2] > 1 - 1e-9)
    b[3 * top, 0] = 1.0  # x-forces on the top face's nodes
    b[3 * nodes(lambda p: p[0] > 3 - 1e-9) + 2, 1] = -1.0  # z-forces on the end x1
    return x, C, K, fixed, b


def test_the_matrix_free_solve_is_the_dense_solve():
    x, C, K, fixed, b = _problem()
    free = np.setdiff1d(np.arange(K.shape[0]), fixed)
    want = np.zeros_like(b)
    want[free] = np.linalg.solve(K[free][:, free].toarray(), b[free])
    A = tensorsolve.operator(Lattice.q2(x), C)
    got, rec = tensorsolve.solve(A, b, fixed)
    assert rec.matrix_free and rec.residual <= rec.rtol and rec.iterations > 10
    assert np.abs(got - want).max() <= 1e-8 * np.abs(want).max()
    assert np.all(got[fixed] == 0)
    exact, again = tensorsolve.solve(A, b, fixed, x0=want)  # from the solution: nothing to do
    assert again.iterations == 0 and np.abs(exact - want).max() <= 1e-12 * np.abs(want).max()


def test_lattice_fields_round_trip():
    x = q2_doflocs(tensor_mesh(graded_axes(np.zeros(3), np.array([3.0, 1.0, 1.0]), 2)))
    lat = Lattice.q2(x)
    v = np.random.default_rng(0).standard_normal((3 * x.shape[1], 2))
    assert lat.to_lattice(v).shape == (2, 3) + lat.shape and lat.field_shape == (3,) + lat.shape
    np.testing.assert_array_equal(lat.from_lattice(lat.to_lattice(v)), v)
    np.testing.assert_array_equal(lat.from_lattice(lat.to_lattice(v[:, 0])), v[:, 0])
    grid = Lattice.of(x)  # any tensor grid; q2 checks the midpoints besides
    assert all(np.array_equal(a, b) for a, b in zip(grid.axes, lat.axes))
    np.testing.assert_array_equal(lat.to_lattice(v[:, 0])[1].ravel()[grid.index], v[1::3, 0])
    np.testing.assert_array_equal(grid.grid(v[1::3, :1])[..., 0], lat.to_lattice(v[:, 0])[1])


@pytest.mark.slow
def test_levels_in_one_thread_or_two_agree(tmp_path, monkeypatch):
    monkeypatch.setattr(plan, "MATRIX_FREE_MIN", {3: 0})  # the coarse levels through the CG too
    case = box_case(tmp_path, size=(2.0, 1.0, 1.0), nu=0.45, reference_keys="max_refine = 0")
    runs = []
    for workers in (1, 2):
        monkeypatch.setattr(levels, "WORKERS", workers)
        info: list = []
        lev, est, _ = levels.solve_graded(case, records=info)
        runs.append((lev, est, [(r.method, r.loads) for r in info]))
    (a, ea, ra), (b, eb, rb) = runs
    assert ra == rb and ea.keys() == eb.keys()
    assert any(m == "tensor" for m, _ in ra)
    for name in a.fields:
        for (k, u), (k2, v) in zip(a.fields[name], b.fields[name]):
            assert k == k2 and np.abs(u - v).max() <= 1e-12 * max(np.abs(u).max(), 1e-300)
