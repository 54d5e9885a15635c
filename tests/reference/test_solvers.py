"""reference.solvers.sparse against independent truths: dense numpy solves of small systems,
a closed-form stretch of a thin nearly incompressible bar (a linear field, which P1/P2
reproduce exactly), the same body in millimetres with E in Pa (the solution scales
exactly), residuals ||b - A x|| / ||b||, forced AMG failures that must end in the
direct method, and singular systems that must give one ModelError line."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import skfem

from harness.case.elasticity import isotropic_compliance
from harness.errors import ModelError
from reference.fem import Discretisation
from reference.solvers import dofcoords, plan, sparse
from reference.solvers.record import SolveRecord

METHODS = ["auto", "direct", "cholesky", "superlu", "amg", "cg"]


def elasticity(
    cell="tet",
    order="P2",
    size=(1.0, 1.0, 1.0),
    divs=(2, 2, 2),
    E=1e3,
    nu=0.3,
    scale=1.0,
    clamp="face",
    traction=(0.0, 0.3, -1.0),
):
    """Free-dof system of a box [0, size] * scale: (A, b, near_null, coords, d, free).
    clamp='face': x = 0 clamped; 'symmetry': the normal component fixed on the three
    planes x = 0, y = 0, z = 0 (no rigid motion left, stretches stay homogeneous);
    'none': nothing fixed (singular)."""
    dim = len(size)
    M = {
        ("tet", 3): skfem.MeshTet,
        ("hex", 3): skfem.MeshHex,
        ("tri", 2): skfem.MeshTri,
        ("quad", 2): skfem.MeshQuad,
    }[cell, dim]
    mesh = M.init_tensor(*[np.linspace(0, L * scale, k + 1) for L, k in zip(size, divs)])
    d = Discretisation(mesh, cell, order)
    C = np.linalg.inv(isotropic_compliance(E, nu))
    if dim == 2:
        from harness.case.elasticity import plane

        C = plane(C, "strain")
    K = d.stiffness(np.tile(C, (d.nelems, 1, 1)))
    tol = 1e-9 * scale
    if clamp == "face":
        fixed = d.part_dofs(lambda x: x[0] < tol, range(dim))
    elif clamp == "symmetry":
        fixed = np.concatenate([d.part_dofs(lambda x, c=c: x[c] < tol, [c]) for c in range(dim)])
    else:
        fixed = np.zeros(0, int)
    end = d.part_facets(lambda x: x[0] > size[0] * scale - tol)
    F = d.traction_load(end, traction[-dim:])
    free = np.setdiff1d(np.arange(d.ndof), fixed)
    A = sp.csr_matrix(K[free][:, free])
    coords = np.repeat(d.doflocs.T, dim, axis=0)[free]
    return A, F[free], d.rigid_modes()[free], coords, d, free


@pytest.fixture(scope="module")
def small():
    return elasticity(divs=(2, 2, 2))


@pytest.mark.parametrize("method", METHODS)
def test_matches_dense_solve_and_records_it(small, method):
    A, b, R, X, _, _ = small
    truth = np.linalg.solve(A.toarray(), b)
    info = []
    x = sparse.solve(A, b, method, R, coords=X, records=info)
    assert x.shape == b.shape
    assert np.abs(x - truth).max() <= 1e-9 * np.abs(truth).max()
    assert len(info) == 1 and isinstance(info[0], SolveRecord)  # one record a solve
    assert info[-1].method in ("amg", "amg-strong", "cholesky", "superlu", "cg")
    assert info[-1].residual == pytest.approx(
        np.linalg.norm(b - A @ x) / np.linalg.norm(b), rel=1e-6, abs=1e-16
    )
    assert info[-1].residual <= info[-1].rtol
    assert info[-1].seconds > 0
    expected = {
        "direct": "cholesky",
        "cholesky": "cholesky",
        "superlu": "superlu",
        "amg": "amg",
        "auto": "cholesky",
    }
    if method in expected:
        assert info[-1].method == expected[method] and info[-1].fallbacks == ()


def test_positional_call_without_info_or_coords(small):
    """The historic call solve(A, b, method, near_null) still returns x; without coords the
    Cholesky reads the locations off the rigid-body modes, without both it is SuperLU."""
    A, b, R, _, _, _ = small
    truth = np.linalg.solve(A.toarray(), b)
    for method, near_null, used in [
        ("direct", R, "cholesky"),
        ("direct", None, "superlu"),
        ("amg", R, "amg"),
    ]:
        info = []
        x = sparse.solve(A, b, method, near_null, records=info)
        assert info[-1].method == used
        np.testing.assert_allclose(x, truth, rtol=0, atol=1e-9 * np.abs(truth).max())
    assert np.allclose(
        sparse.solve(A, b, "direct", R), truth, rtol=0, atol=1e-9 * np.abs(truth).max()
    )


def test_coordinates_from_rigid_modes(small):
    A, _, R, X, d, _ = small
    Y = dofcoords.coords_from_modes(A, R)
    # rigid_modes uses centred coordinates divided by their largest magnitude
    c = d.doflocs.mean(axis=1)
    s = np.abs(d.doflocs - c[:, None]).max()
    # filled ones: neighbour means (within an element)
    np.testing.assert_allclose(Y, (X - c) / s, atol=1.0)
    exact = np.abs(Y - (X - c) / s) < 1e-12
    assert exact.sum(axis=1).min() >= 2  # each dof carries 2 of its 3
    assert dofcoords.coords_from_modes(A, np.ones((A.shape[0], 6))) is None


def test_many_right_hand_sides_share_one_setup(small, monkeypatch):
    A, b, R, X, _, _ = small
    B = np.column_stack([b, np.zeros_like(b), -2 * b, np.arange(len(b), dtype=float)])
    truth = np.linalg.solve(A.toarray(), B)
    calls = {"sym": 0, "amg": 0}
    from harness.linalg import multifrontal

    sym = multifrontal.Symbolic
    hier = sparse._hierarchy

    def counting_sym(*a, **k):
        calls["sym"] += 1
        return sym(*a, **k)

    def counting_hier(*a, **k):
        calls["amg"] += 1
        return hier(*a, **k)

    monkeypatch.setattr(sparse, "Symbolic", counting_sym)  # where the solve looks it up
    monkeypatch.setattr(sparse, "_hierarchy", counting_hier)
    for method in ("cholesky", "amg"):
        info = []
        x = sparse.solve(A, B, method, R, coords=X, records=info)
        assert x.shape == B.shape and not np.any(x[:, 1])
        assert np.abs(x - truth).max() <= 1e-9 * np.abs(truth).max()
        assert info[-1].residual <= info[-1].rtol
    assert calls == {"sym": 1, "amg": 1}


@pytest.mark.parametrize("method", ["auto", "amg", "direct"])
def test_thin_nearly_incompressible_bar_closed_form(method):
    """10:1 bar, nu = 0.49, stretched by sigma on x = L with symmetry planes: u = (sigma x,
    -nu sigma y, -nu sigma z) / E exactly (a linear field is in the P2 space)."""
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
    x = sparse.solve(A, b, method, R, coords=X, records=info)
    p = d.doflocs
    exact = (np.stack([sig * p[0], -nu * sig * p[1], -nu * sig * p[2]]) / E).T.ravel()[free]
    assert np.abs(x - exact).max() <= 1e-8 * np.abs(exact).max()
    assert info[-1].residual <= info[-1].rtol


def test_thin_bar_bending_matches_dense():
    """The same bar clamped and bent (nu = 0.49): a system plain AMG gives up on."""
    A, b, R, X, _, _ = elasticity(size=(10.0, 1.0, 1.0), divs=(20, 2, 2), nu=0.49)
    truth = np.linalg.solve(A.toarray(), b)
    for method in ("amg", "auto"):
        info = []
        x = sparse.solve(A, b, method, R, coords=X, records=info)
        assert np.abs(x - truth).max() <= 1e-8 * np.abs(truth).max(), info
        assert info[-1].residual <= info[-1].rtol


@pytest.mark.parametrize("method", ["auto", "amg", "direct", "cg", "superlu"])
def test_millimetres_and_pascal_give_the_metre_solution(method):
    """2 x 1 x 0.5 box: in metres with E = 1e5 Pa and in millimetres (coordinates ~1e3)
    with the same E in Pa and the same traction: K scales by 1e3, b by 1e6, u by 1e3."""
    kw = dict(size=(2.0, 1.0, 0.5), divs=(6, 3, 2), E=1e5, nu=0.45)
    A, b, R, X, _, _ = elasticity(**kw)
    Amm, bmm, Rmm, Xmm, _, _ = elasticity(**kw, scale=1e3)
    np.testing.assert_allclose(Xmm, 1e3 * X)
    x = sparse.solve(A, b, method, R, coords=X)
    info = []
    xmm = sparse.solve(Amm, bmm, method, Rmm, coords=Xmm, records=info)
    assert np.abs(xmm / 1e3 - x).max() <= 1e-8 * np.abs(x).max()
    truth = np.linalg.solve(A.toarray(), b)
    assert np.abs(x - truth).max() <= 1e-8 * np.abs(truth).max()
    assert info[-1].residual <= info[-1].rtol


def test_amg_that_fails_falls_back_to_cholesky(monkeypatch):
    A, b, R, X, _, _ = elasticity(size=(2.0, 1.0, 0.5), divs=(4, 2, 2), nu=0.49)
    truth = np.linalg.solve(A.toarray(), b)
    monkeypatch.setattr(sparse, "AMG_MAXITER", 2)
    monkeypatch.setattr(sparse, "STRONG_MAXITER", 3)
    monkeypatch.setattr(sparse, "CHOLESKY_OVERHEAD_GFLOP", 1e9)  # never skip the strong AMG
    for method in ("auto", "amg", "cg"):
        if method == "auto":
            monkeypatch.setattr(plan, "CHOLESKY_GFLOP", 0.0)
        info = []
        x = sparse.solve(A, np.column_stack([b, 3 * b]), method, R, coords=X, records=info)
        assert info[-1].method == "cholesky"
        tried = [f.method for f in info[-1].fallbacks]
        assert tried == (["cg"] if method == "cg" else []) + ["amg", "amg-strong"]
        assert all(f.residual > sparse.RTOL and f.reason for f in info[-1].fallbacks)
        assert info[-1].residual <= info[-1].rtol
        np.testing.assert_allclose(x[:, 1], 3 * truth, rtol=0, atol=1e-9 * np.abs(3 * truth).max())


def test_broken_hierarchy_falls_back(monkeypatch, small):
    """An AMG setup that raises, and one whose V-cycle is not positive definite (CG breaks
    down): both are recorded and the answer comes from the Cholesky (or SuperLU when
    there are no locations)."""
    A, b, R, X, _, _ = small
    truth = np.linalg.solve(A.toarray(), b)

    def raising(*a, **k):
        raise np.linalg.LinAlgError("broken")

    monkeypatch.setattr(sparse, "_hierarchy", raising)
    info = []
    x = sparse.solve(A, b, "amg", R, coords=X, records=info)
    assert info[-1].method == "cholesky" and [f.method for f in info[-1].fallbacks] == [
        "amg",
        "amg-strong",
    ]
    assert "setup failed" in info[-1].fallbacks[0].reason
    assert np.abs(x - truth).max() <= 1e-9 * np.abs(truth).max()

    class Negative:
        def aspreconditioner(self, cycle="V"):
            return sp.linalg.aslinearoperator(-sp.identity(A.shape[0]))

    monkeypatch.setattr(sparse, "_hierarchy", lambda *a, **k: Negative())
    info = []
    x = sparse.solve(A, b, "amg", None, records=info)  # no modes, no coords: SuperLU
    assert info[-1].method == "superlu" and "breakdown" in info[-1].fallbacks[0].reason
    assert np.abs(x - truth).max() <= 1e-9 * np.abs(truth).max()


@pytest.mark.parametrize("method", METHODS)
def test_singular_system_is_one_model_error(method):
    A, b, R, X, _, _ = elasticity(divs=(2, 1, 1), clamp="none")
    rng = np.random.default_rng(1)
    with pytest.raises(ModelError, match="the stiffness matrix is singular") as err:
        sparse.solve(A, rng.standard_normal(len(b)), method, R, coords=X)
    assert "check the constraints" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("bad", ["nan-matrix", "inf-rhs", "zero-row"])
def test_non_finite_or_empty_row_is_singular(small, bad):
    A, b, R, X, _, _ = small
    A = A.tolil(copy=True)
    b = b.copy()
    if bad == "nan-matrix":
        A[3, 3] = np.nan
    elif bad == "inf-rhs":
        b[5] = np.inf
    else:
        A[4, :] = 0
        A[:, 4] = 0
    with pytest.raises(ModelError, match="singular"):
        sparse.solve(A.tocsr(), b, "auto", R, coords=X)


def test_zero_and_empty_right_hand_sides(small):
    A, b, R, X, _, _ = small
    info = []
    assert not np.any(sparse.solve(A, np.zeros_like(b), "auto", R, coords=X, records=info))
    assert info[-1].residual == 0
    x = sparse.solve(A, np.zeros((len(b), 0)), "amg", R)
    assert x.shape == (len(b), 0)


def test_two_dimensional_quad_p2():
    A, b, R, X, _, _ = elasticity(cell="quad", size=(4.0, 1.0), divs=(8, 2), nu=0.49)
    truth = np.linalg.solve(A.toarray(), b)
    assert R.shape[1] == 3
    for method, coords in [("auto", X), ("direct", None), ("amg", None)]:
        info = []
        x = sparse.solve(A, b, method, R, coords=coords, records=info)
        assert info[-1].method in ("cholesky", "amg", "amg-strong")
        assert np.abs(x - truth).max() <= 1e-8 * np.abs(truth).max()


def test_unknown_method_is_a_value_error(small):
    A, b, R, _, _, _ = small
    with pytest.raises(ValueError, match="unknown solver"):
        sparse.solve(A, b, "lu", R)


@pytest.mark.slow
def test_medium_3d_q2_hex_all_paths_agree():
    """~7k dofs of Q2 hex, nu = 0.45: Cholesky, SuperLU, AMG agree to 1e-8."""
    A, b, R, X, _, _ = elasticity(cell="hex", size=(2.0, 1.0, 0.5), divs=(8, 4, 3), nu=0.45)
    ref = sparse.solve(A, b, "superlu")
    for method in ("auto", "cholesky", "amg"):
        info = []
        x = sparse.solve(A, b, method, R, coords=X, records=info)
        assert info[-1].residual <= info[-1].rtol
        assert np.abs(x - ref).max() <= 1e-8 * np.abs(ref).max(), (method, info)


def test_auto_chooses_by_the_cholesky_estimate(small, monkeypatch):
    A, b, R, X, _, _ = small
    info = []
    sparse.solve(A, b, "auto", R, coords=X, records=info)
    assert info[-1].method == "cholesky" and 0 < info[-1].estimate["gflop"] < plan.CHOLESKY_GFLOP
    monkeypatch.setattr(plan, "CHOLESKY_GFLOP", info[-1].estimate["gflop"] / 2)
    sparse.solve(A, b, "auto", R, coords=X, records=info)
    assert info[-1].method == "amg" and info[-1].fallbacks == ()
    assert info[-1].residual <= info[-1].rtol
    assert plan.choose("auto", 1000, 3) == "direct" and plan.choose("auto", 10**6, 3) == "amg"
    assert plan.choose("cg", 10, 2) == "cg"


def test_strong_amg_is_skipped_when_the_cholesky_is_cheaper(monkeypatch):
    A, b, R, X, _, _ = elasticity(size=(2.0, 1.0, 0.5), divs=(4, 2, 2), nu=0.49)
    truth = np.linalg.solve(A.toarray(), b)
    monkeypatch.setattr(sparse, "AMG_MAXITER", 2)
    monkeypatch.setitem(sparse.GFLOP_PER_NONZERO, "amg", 1e3)  # its work passed the Cholesky's
    info = []
    x = sparse.solve(A, b, "amg", R, coords=X, records=info)
    assert info[-1].method == "cholesky" and [f.method for f in info[-1].fallbacks] == ["amg"]
    assert info[-1].estimate["gflop"] > 0
    assert np.abs(x - truth).max() <= 1e-9 * np.abs(truth).max()


def test_the_fallback_chain_is_chosen_by_work_not_by_the_clock(monkeypatch):
    """A failed AMG's work is counted (iterations x nonzeros), not timed: with a clock that
    jumps 1000 s at every reading (a busy machine) the same steps run, the strong AMG gets
    the same iterations and the answer is the same bit for bit."""
    A, b, R, X, _, _ = elasticity(size=(2.0, 1.0, 0.5), divs=(4, 2, 2), nu=0.49)
    monkeypatch.setattr(sparse, "AMG_MAXITER", 2)
    monkeypatch.setattr(sparse, "STRONG_MAXITER", 3)
    runs = []
    for jumping in (False, True):
        if jumping:
            now = [0.0]

            def clock():
                now[0] += 1000.0
                return now[0]

            monkeypatch.setattr(sparse.time, "process_time", clock)
            monkeypatch.setattr(sparse.time, "perf_counter", clock)
        info = []
        x = sparse.solve(A, np.column_stack([b, 3 * b]), "amg", R, coords=X, records=info)
        runs.append((x, [(f.method, f.residual) for f in info[-1].fallbacks], info[-1].method))
    (x0, steps0, m0), (x1, steps1, m1) = runs
    assert [s for s, _ in steps0] == ["amg", "amg-strong"] and m0 == m1 == "cholesky"
    assert steps0 == steps1 and np.array_equal(x0, x1)
