"""reference/solvers/twolevel.py (the two-level method of reference/solvers/sparse.py) against
independent truths: the P1/Q1 prolongation reproduces the lower-order fields it claims
to (evaluated from their formula at the P2/Q2 dof locations), and the two-level solves
match dense numpy solves of small systems (several right-hand sides, a zero one, the
coarse solve by Cholesky or by AMG), with the residual checked from A, b and x here."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import skfem

from reference.fem import Discretisation
from reference.solvers import plan, sparse, twolevel
from tests.reference.test_solvers import elasticity

CELLS = {"tet": skfem.MeshTet, "hex": skfem.MeshHex, "tri": skfem.MeshTri, "quad": skfem.MeshQuad}


def _low_order_field(cell, x):
    """A field of the P1 (simplices) or Q1 (tensor cells on axis-aligned boxes) space."""
    if cell in ("tet", "tri"):
        return 1.0 + 2.0 * x[0] - 3.0 * x[1] + (0.5 * x[2] if len(x) == 3 else 0.0)
    if cell == "quad":
        return 1.0 + x[0] - 2.0 * x[1] + 3.0 * x[0] * x[1]
    return (
        1.0 + x[0] - 2.0 * x[1] + 0.5 * x[2] + x[0] * x[1] - x[1] * x[2] + 3.0 * x[0] * x[1] * x[2]
    )


@pytest.mark.parametrize("cell", ["tet", "hex", "tri", "quad"])
def test_prolongation_reproduces_the_lower_order_fields(cell):
    dim = 3 if cell in ("tet", "hex") else 2
    rng = np.random.default_rng(0)
    # uneven cells
    axes = [np.sort(np.r_[0.0, rng.uniform(0.1, 0.9, 2), 1.0]) * (1.0 + i) for i in range(dim)]
    mesh = CELLS[cell].init_tensor(*axes)
    d = Discretisation(mesh, cell, "P2")
    P = twolevel.prolongation(d)
    nv = mesh.p.shape[1]
    assert P.shape == (d.ndof, dim * nv)
    for c in range(dim):  # component c of the vector field, the others zero
        coarse = np.zeros((nv, dim))
        coarse[:, c] = _low_order_field(cell, mesh.p)
        fine = (P @ coarse.ravel()).reshape(-1, dim)
        np.testing.assert_allclose(
            fine[:, c], _low_order_field(cell, d.doflocs), rtol=0, atol=1e-12
        )
        assert not np.any(np.delete(fine, c, axis=1))
    assert twolevel.prolongation(Discretisation(mesh, cell, "P1")) is None


def _system(**kw):
    A, b, R, X, d, free = elasticity(**kw)
    return A, b, R, X, twolevel.prolongation(d)[free]


@pytest.mark.parametrize("coarse_solver", ["cholesky", "amg"])
def test_two_level_matches_dense_solve(monkeypatch, coarse_solver):
    """A clamped 2 x 1 x 1 box, nu = 0.45, P2: three right-hand sides (one zero) against
    numpy's dense solve; the coarse system factorised or, forced, by AMG."""
    if coarse_solver == "amg":
        monkeypatch.setattr(twolevel, "COARSE_GBYTES", 0.0)
    A, b, R, X, P = _system(size=(2.0, 1.0, 1.0), divs=(4, 2, 2), E=1e5, nu=0.45)
    B = np.column_stack([b, np.zeros_like(b), np.random.default_rng(1).standard_normal(len(b))])
    truth = np.linalg.solve(A.toarray(), B)
    info = []
    x = sparse.solve(A, B, "two-level", R, coords=X, records=info, coarse=P)
    assert info[-1].method == "two-level" and info[-1].fallbacks == () and info[-1].iterations > 0
    assert not np.any(x[:, 1])
    res = np.linalg.norm(B[:, [0, 2]] - A @ x[:, [0, 2]], axis=0) / np.linalg.norm(
        B[:, [0, 2]], axis=0
    )
    assert res.max() <= info[-1].rtol and info[-1].residual == pytest.approx(res.max(), rel=1e-6)
    assert np.abs(x - truth).max() <= 1e-8 * np.abs(truth).max()


def test_preconditioner_is_symmetric_positive_definite():
    """CG needs M symmetric positive definite: checked on the dense matrix of M."""
    A, b, R, X, P = _system(size=(1.0, 1.0, 1.0), divs=(2, 2, 2), nu=0.3)
    s = 1.0 / np.sqrt(A.diagonal())
    As = sp.csr_matrix(A.multiply(s[:, None]).multiply(s[None, :]))
    M = twolevel.TwoLevel(As, s, P, X, R)(np.eye(A.shape[0]))
    assert np.abs(M - M.T).max() <= 1e-10 * np.abs(M).max()
    assert np.linalg.eigvalsh(0.5 * (M + M.T)).min() > 0


def test_auto_takes_two_level_where_it_took_amg(small_estimate_limit):
    A, b, R, X, P = _system(size=(2.0, 1.0, 1.0), divs=(4, 2, 2), nu=0.3)
    truth = np.linalg.solve(A.toarray(), b)
    info = []
    x = sparse.solve(A, b, "auto", R, coords=X, records=info, coarse=P)
    assert info[-1].method == "two-level"
    assert np.abs(x - truth).max() <= 1e-8 * np.abs(truth).max()
    sparse.solve(A, b, "auto", R, coords=X, records=info)  # no coarse space: AMG as before
    assert info[-1].method == "amg"


@pytest.fixture
def small_estimate_limit(monkeypatch):
    monkeypatch.setattr(plan, "CHOLESKY_GFLOP", 0.0)


def test_two_level_that_fails_falls_back(monkeypatch):
    """Too few iterations allowed: recorded as a fallback, the answer from the Cholesky."""
    A, b, R, X, P = _system(size=(2.0, 1.0, 0.5), divs=(4, 2, 2), nu=0.49)
    truth = np.linalg.solve(A.toarray(), b)
    monkeypatch.setattr(sparse, "TWO_LEVEL_MAXITER", 2)
    monkeypatch.setitem(sparse.GFLOP_PER_NONZERO, "two-level", 1e3)  # skip the strong AMG
    info = []
    x = sparse.solve(A, b, "two-level", R, coords=X, records=info, coarse=P)
    assert info[-1].method == "cholesky" and [f.method for f in info[-1].fallbacks] == ["two-level"]
    assert info[-1].fallbacks[0].residual > sparse.RTOL
    assert np.abs(x - truth).max() <= 1e-9 * np.abs(truth).max()


def test_thin_nearly_incompressible_bar_closed_form():
    """The 10:1 bar of test_solvers (nu = 0.49, symmetry planes, stretched): the linear
    closed form, whichever method ends up solving it."""
    E, nu, sig = 2.0e3, 0.49, 3.0
    A, b, R, X, d, free = elasticity(
        size=(10.0, 1.0, 1.0),
        divs=(20, 2, 2),
        E=E,
        nu=nu,
        clamp="symmetry",
        traction=(sig, 0.0, 0.0),
    )
    info = []
    x = sparse.solve(
        A, b, "two-level", R, coords=X, records=info, coarse=twolevel.prolongation(d)[free]
    )
    p = d.doflocs
    exact = (np.stack([sig * p[0], -nu * sig * p[1], -nu * sig * p[2]]) / E).T.ravel()[free]
    assert np.abs(x - exact).max() <= 1e-8 * np.abs(exact).max()
    assert info[-1].method == "two-level"


def test_solve_system_hands_the_coarse_space_over():
    """reference.problem.solve_system with 'two-level' on a Discretisation: the same
    displacements as with the Cholesky."""
    from harness.case.elasticity import isotropic_compliance
    from reference.problem import solve_system

    mesh = skfem.MeshTet.init_tensor(
        *[np.linspace(0, L, k + 1) for L, k in zip((2.0, 1.0, 1.0), (4, 2, 2))]
    )
    d = Discretisation(mesh, "tet", "P2")
    K = d.stiffness(np.tile(np.linalg.inv(isotropic_compliance(1e5, 0.45)), (d.nelems, 1, 1)))
    fixed = d.part_dofs(lambda x: x[0] < 1e-9, range(3))
    F = {
        "tip": d.traction_load(d.part_facets(lambda x: x[0] > 2 - 1e-9), (0.0, -1.0, 0.0)),
        "sag": d.body_load(np.tile([0.0, 0.0, -9.81], (d.nelems, 1))),
    }
    fx = {n: fixed for n in F}
    info: list = []
    U = solve_system(K, F, fx, "two-level", d, records=info)
    V = solve_system(K, F, fx, "cholesky", d)
    assert info[0].method == "two-level" and info[0].loads == ("tip", "sag")
    for n in F:
        assert np.abs(U[n] - V[n]).max() <= 1e-8 * np.abs(V[n]).max()


def test_auto_weighs_the_cholesky_against_the_two_level(monkeypatch):
    """'auto' with a coarse space: the Cholesky while its estimate is at most
    TWO_LEVEL_GFLOP_PER_NONZERO * nnz, else the two-level; from TWO_LEVEL_FIRST dofs the
    two-level without an estimate. Every answer matches the dense solve."""
    A, b, R, X, P = _system(size=(2.0, 1.0, 1.0), divs=(4, 2, 2), nu=0.45)
    truth = np.linalg.solve(A.toarray(), b)
    for per_nonzero, first, expected in (
        (1.0, 10**9, "cholesky"),
        (0.0, 10**9, "two-level"),
        (1.0, 1, "two-level"),
    ):
        monkeypatch.setattr(plan, "TWO_LEVEL_GFLOP_PER_NONZERO", per_nonzero)
        monkeypatch.setattr(plan, "TWO_LEVEL_FIRST", {2: first, 3: first})
        info = []
        x = sparse.solve(A, b, "auto", R, coords=X, records=info, coarse=P)
        assert info[-1].method == expected and (info[-1].estimate is not None) == (first > 1)
        assert np.abs(x - truth).max() <= 1e-8 * np.abs(truth).max()


@pytest.mark.parametrize(
    "cell,size,divs",
    [
        ("hex", (2.0, 1.0, 1.0), (4, 2, 2)),
        ("quad", (4.0, 1.0), (8, 2)),
        ("tri", (4.0, 1.0), (8, 2)),
    ],
)
def test_two_level_on_q2_and_2d_matches_dense_solve(cell, size, divs):
    A, b, R, X, P = _system(cell=cell, size=size, divs=divs, nu=0.45)
    truth = np.linalg.solve(A.toarray(), b)
    info = []
    x = sparse.solve(A, b, "two-level", R, coords=X, records=info, coarse=P)
    assert info[-1].method == "two-level" and info[-1].residual <= info[-1].rtol
    assert np.abs(x - truth).max() <= 1e-8 * np.abs(truth).max()
