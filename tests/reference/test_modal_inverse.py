"""The reference's natural frequencies through the shift-invert operator
(reference.solvers.sparse.inverse: the multifrontal Cholesky, or the two-level CG where the
Cholesky would not fit) equal a dense generalised eigen-solve of the same K and M."""

import textwrap

import numpy as np
import pytest
import scipy.linalg as sl
import scipy.sparse.linalg as spla

import reference
from harness.case.reader import load_case
from reference.problem import body_bbox, fixed_dofs
from reference.solvers import sparse


def _case(tmp_path):
    p = tmp_path / "m.toml"
    p.write_text(
        textwrap.dedent("""
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
        """)
    )
    return load_case(p)


@pytest.mark.slow
@pytest.mark.parametrize("operator", ["cholesky", "two-level"])
def test_shift_invert_frequencies_match_a_dense_solve(tmp_path, monkeypatch, operator):
    """Cholesky: as measured; two-level: the Cholesky's memory bound set to 0, so the
    operator is the CG on the P1 subspace (the large-mesh path), set up once."""
    case = _case(tmp_path)
    if operator == "two-level":
        monkeypatch.setattr(sparse, "INVERSE_GBYTES", 0.0)
    used = []
    real = sparse.inverse
    monkeypatch.setattr(sparse, "inverse", lambda *a: used.append(real(*a)) or used[-1])
    sol = reference.solve(case, cache=False)
    f = sol.frequencies(5)
    assert len(used) == 1 and used[0] is not None  # eigsh never fell back to SuperLU
    # the CG's closure, not the factor's
    assert (operator == "two-level") == (used[0].__name__ == "solve")
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


@pytest.mark.slow
def test_graded_modes_come_from_a_level_within_the_budget(tmp_path, monkeypatch):
    """A graded reference whose finest level is past MODAL_DOFS takes its modes from the
    finest level within it (the Sec. 6 cube at 9 cells per end zone: the finest level's
    shift-invert would not fit). Its frequencies equal scipy's eigen-solve of that level
    assembled here with scikit-fem's own forms, and converge fast over the levels
    (h^(2p): the next level's change is a fraction of this one's)."""
    import dataclasses

    import skfem
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    from reference import methods

    case = _case(tmp_path)
    load = "shear-xy"  # face y0 clamped; the one load solved
    case = dataclasses.replace(
        case,
        reference=dataclasses.replace(case.reference, max_refine=2),
        loads=tuple(l for l in case.loads if l.name == load),
    )
    sol = reference.solve(case, cache=False)
    sizes = [sol.levels.disc(m).ndof for m in sol.levels.meshes]
    assert sizes[0] < sizes[1] < sizes[2] == sol.disc.ndof

    def modal_with(budget):
        monkeypatch.setattr(methods, "MODAL_DOFS", {3: budget})
        sol.method.__dict__.pop("modal_disc", None)
        sol._modal.clear()
        return sol.frequencies(5, load=load)

    f = []
    for k in (0, 1, 2):
        f.append(modal_with(int(sizes[k])))
        assert sol.modal_mesh is (sol.levels.meshes[k] if k < 2 else sol.mesh)
    assert sol.modal_disc is sol.disc  # the finest fits: its own
    assert sol.modes(5, load=load).shape == (5, sol.mesh.p.shape[1], 3)
    change = [np.abs(f[i] / f[2] - 1).max() for i in (0, 1)]
    assert change[1] < change[0] / 2 and change[0] < 0.01, change

    f0 = modal_with(1)  # none fits: the coarsest
    mesh = sol.levels.meshes[0]
    assert sol.modal_mesh is mesh and sol.modes(5, load=load).shape == (5, mesh.p.shape[1], 3)
    np.testing.assert_allclose(f0, f[0], rtol=1e-12)
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementHex2()), intorder=5)
    K = skfem.asm(linear_elasticity(*lame_parameters(1000.0, 0.3)), basis)
    M = skfem.asm(skfem.BilinearForm(lambda u, v, w: 1.5 * skfem.helpers.dot(u, v)), basis)
    clamped = basis.get_dofs(lambda x: np.isclose(x[1], 0.0)).all()
    free = np.setdiff1d(np.arange(basis.N), clamped)
    # scipy's own shift-invert (SuperLU), not the product's operator; a dense solve of these
    # 6k dofs took ~50 s
    lam = np.sort(
        spla.eigsh(
            K[free][:, free].tocsc(),
            k=5,
            M=M[free][:, free].tocsc(),
            sigma=0.0,
            return_eigenvectors=False,
        )
    )
    np.testing.assert_allclose(f0, np.sqrt(lam) / (2 * np.pi), rtol=1e-9)
