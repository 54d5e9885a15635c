"""The reference's natural frequencies through the shift-invert operator
(reference.solvers.inverse: the multifrontal Cholesky, or the two-level CG where the
Cholesky would not fit) equal a dense generalised eigen-solve of the same K and M."""

import textwrap

import numpy as np
import pytest
import scipy.linalg as sl

import reference
from harness.case.reader import load_case
from reference import solvers
from reference.problem import body_bbox, fixed_dofs


def _case(tmp_path):
    p = tmp_path / "m.toml"
    p.write_text(textwrap.dedent("""
        name = "m"
        dim = 3
        [body]
        shape = "box"
        size = [2.0, 1.0, 0.8]
        [material]
        E = 1000.0
        nu = 0.3
        density = 1.5
        [loads]
        set = "basic3d"
        [reference]
        max_refine = 0
        modes = 5
        """))
    return load_case(p)


@pytest.mark.slow
@pytest.mark.parametrize("operator", ["cholesky", "two-level"])
def test_shift_invert_frequencies_match_a_dense_solve(tmp_path, monkeypatch, operator):
    """Cholesky: as measured; two-level: the Cholesky's memory bound set to 0, so the
    operator is the CG on the P1 subspace (the large-mesh path), set up once."""
    case = _case(tmp_path)
    if operator == "two-level":
        monkeypatch.setattr(solvers, "INVERSE_GBYTES", 0.0)
    used = []
    real = solvers.inverse
    monkeypatch.setattr(solvers, "inverse", lambda *a: used.append(real(*a)) or used[-1])
    sol = reference.solve(case, cache=False)
    f = sol.frequencies(5)
    assert len(used) == 1 and used[0] is not None                    # eigsh never fell back to SuperLU
    assert (operator == "two-level") == (used[0].__name__ == "solve")  # the CG's closure, not the factor's
    K, M, _, _ = _system(sol, case)
    lam = sl.eigh(K.toarray(), M.toarray(), eigvals_only=True, subset_by_index=[0, 4])
    np.testing.assert_allclose(f, np.sqrt(lam) / (2 * np.pi), rtol=1e-9)


def _system(sol, case):
    from harness.case.elasticity import densities, element_stiffness
    d = sol.disc
    K = d.stiffness(element_stiffness(case.material, d.centroids()))
    M = d.mass(densities(case.material, d.centroids()))
    fx = fixed_dofs(d, case, case.loads[0], body_bbox(case, sol.mesh))
    free = np.setdiff1d(np.arange(d.ndof), fx)
    Kf = K[free][:, free]
    return Kf, M[free][:, free], Kf, np.repeat(d.doflocs.T, d.dim, axis=0)[free]
