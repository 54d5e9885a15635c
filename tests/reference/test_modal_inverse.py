"""The reference's natural frequencies through the multifrontal shift-invert operator
(reference.solvers.inverse) equal a dense generalised eigen-solve of the same K and M."""

import textwrap

import numpy as np
import pytest
import scipy.linalg as sl

import reference
from harness.case.reader import load_case
from reference import solvers
from reference.problem import body_bbox, fixed_dofs


@pytest.mark.slow
def test_shift_invert_frequencies_match_a_dense_solve(tmp_path, monkeypatch):
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
    case = load_case(p)
    used = []
    real = solvers.inverse
    monkeypatch.setattr(solvers, "inverse", lambda *a: used.append(1) or real(*a))
    sol = reference.solve(case, cache=False)
    f = sol.frequencies(5)
    assert used and real(*_system(sol, case)[2:]) is not None        # the Cholesky operator was used
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
