"""reference/solvers/plan.py: the plans of hand-made systems, derived from the crossovers
by hand, and the sparse solve following the plan it is given."""

import numpy as np
import pytest
import scipy.sparse as sp

from reference.solvers import plan, sparse
from reference.solvers.plan import Plan, System, choose_plan

CHOL = {"gflop": 1.0, "gbytes": 0.1}  # a Cholesky well within the limits
BIG = {"gflop": 10 * plan.CHOLESKY_GFLOP, "gbytes": 0.1}


def test_auto_asks_for_the_estimate_and_then_decides_by_it():
    s = System(5_000, 3, "auto")
    assert choose_plan(s) == Plan(needs_estimate=True)
    assert choose_plan(System(5_000, 3, "auto", estimate=CHOL)).steps == ("cholesky",)
    assert choose_plan(System(5_000, 3, "auto", estimate=BIG)).steps == (
        "amg",
        "amg-strong",
        "cholesky",
    )
    # with the P1/Q1 subspace the two-level replaces AMG, and the Cholesky's limit shrinks with nnz
    s = System(5_000, 3, "auto", coarse=True, nnz=1000, estimate=CHOL)  # 2.8e-5 * 1000 < 1 Gflop
    assert choose_plan(s).steps == ("two-level", "amg-strong", "cholesky")
    s = System(5_000, 3, "auto", coarse=True, nnz=10**6, estimate=CHOL)
    assert choose_plan(s).steps == ("cholesky",)


def test_sizes_that_skip_the_estimate():
    n = plan.SYMBOLIC_MAX[3] + 1
    assert choose_plan(System(n, 3, "auto")).steps == ("amg", "amg-strong", "cholesky")
    n = plan.TWO_LEVEL_FIRST[3]
    assert choose_plan(System(n, 3, "auto", coarse=True)).steps == (
        "two-level",
        "amg-strong",
        "cholesky",
    )
    assert choose_plan(System(plan.TENSOR_MIN[3], 3, "auto", tensor=True)).steps == (
        "tensor",
        "amg",
        "amg-strong",
        "cholesky",
    )
    assert choose_plan(System(plan.TENSOR_MIN[3] - 1, 3, "auto", tensor=True)).needs_estimate


def test_without_coordinates_superlu_is_the_direct_method():
    assert choose_plan(System(plan.SUPERLU_MAX[3], 3, "auto", coords=False)).steps == ("superlu",)
    assert choose_plan(System(plan.SUPERLU_MAX[3] + 1, 3, "auto", coords=False)).steps == (
        "amg",
        "amg-strong",
        "superlu",
    )
    assert choose_plan(System(10, 2, "direct", coords=False)).steps == ("superlu",)
    # the two-level needs the coordinates too
    assert choose_plan(System(10, 2, "two-level", coarse=True, coords=False)).steps == (
        "amg",
        "amg-strong",
        "superlu",
    )


def test_named_methods_and_the_problem_level_choices():
    assert choose_plan(System(10, 2, "cg")).steps == ("cg", "amg", "amg-strong", "cholesky")
    # no preconditioner
    assert choose_plan(System(10, 2, "tensor")).steps == ("amg", "amg-strong", "cholesky")
    assert choose_plan(System(10, 3, "tensor", matrix_free=True)).matrix_free  # asked for by name
    assert not choose_plan(
        System(plan.MATRIX_FREE_MIN[3] - 1, 3, "auto", matrix_free=True)
    ).matrix_free
    assert choose_plan(System(plan.MATRIX_FREE_MIN[3], 3, "auto", matrix_free=True)).matrix_free
    assert not choose_plan(
        System(plan.MATRIX_FREE_MIN[3], 3, "auto")
    ).matrix_free  # one tensor only
    assert choose_plan(System(10, 3, ndof=plan.TWO_LEVEL_MIN)).coarse
    assert not choose_plan(System(10, 3, ndof=plan.TWO_LEVEL_MIN - 1)).coarse
    assert choose_plan(System(10, 3, "two-level")).coarse
    with pytest.raises(ValueError, match="unknown solver 'lu'"):
        choose_plan(System(10, 3, "lu"))


def test_the_sparse_solve_tries_the_planned_methods_in_turn(monkeypatch):
    """A plan handed to the solve: Jacobi CG given two iterations is not accepted, the
    Cholesky solves, and the record lists the failed attempt."""
    n = 60
    A = sp.diags([-np.ones(n - 1), 2.0001 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1], format="csr")
    b = np.sin(np.arange(n))
    X = np.arange(n, dtype=float)[:, None]
    monkeypatch.setattr(sparse, "choose_plan", lambda s: Plan(("cg", "cholesky")))
    monkeypatch.setattr(sparse, "CG_MAXITER", 2)
    records = []
    x = sparse.solve(A, b, "auto", coords=X, records=records)
    np.testing.assert_allclose(x, np.linalg.solve(A.toarray(), b), rtol=1e-9)
    assert records[0].method == "cholesky" and [f.method for f in records[0].fallbacks] == ["cg"]
