"""Model class "p1" (harness/models/p1.py): linear finite elements on the spring model's
own nodes. Its stiffness against scikit-fem's P1 assembly (tetrahedra, plane-stress and
plane-strain triangles, perturbed meshes); the stage's P1 row against the homogeneous
loads' closed form (P1 meets a linear field exactly) and against an independent P1 solve
of a clamped gravity load written here with scikit-fem (its own load vector)."""

import numpy as np
import pytest
import skfem
from skfem.models.elasticity import lame_parameters, linear_elasticity

from harness.case.elasticity import isotropic_compliance, plane
from harness.case.reader import load_case
from harness.models.p1 import P1Term
from harness.stages import StageContext
from harness.stages import sms as stage

E, NU = 3.0, 0.37


def _perturbed(mesh, amp, seed):
    p = mesh.p + amp * np.random.default_rng(seed).standard_normal(mesh.p.shape)
    return type(mesh)(p, mesh.t)


@pytest.mark.parametrize("kind", ["tet", "tri-stress", "tri-strain"])
def test_p1_stiffness_matches_scikit_fem(kind):
    lam, mu = lame_parameters(E, NU)
    D = np.linalg.inv(isotropic_compliance(E, NU))
    if kind == "tet":
        m, el = _perturbed(skfem.MeshTet().refined(1), 0.03, 1), skfem.ElementTetP1()
    else:
        m, el = _perturbed(skfem.MeshTri().refined(2), 0.02, 2), skfem.ElementTriP1()
        D = plane(D, kind[4:])
        if kind == "tri-stress":
            lam = 2 * lam * mu / (lam + 2 * mu)
    K_ref = skfem.asm(linear_elasticity(lam, mu), skfem.Basis(m, skfem.ElementVector(el))).toarray()
    term = P1Term.build(m.p.T, m.t.T, np.broadcast_to(D, (m.t.shape[1],) + D.shape))
    K = term.stiffness_matrix(m.p.T).toarray()
    assert np.abs(K - K_ref).max() <= 1e-12 * np.abs(K_ref).max()
    # the same element with its nodes listed the other way round (negative volume): same K
    flipped = P1Term.build(
        m.p.T,
        m.t.T[:, [1, 0] + list(range(2, m.t.shape[0]))],
        np.broadcast_to(D, (m.t.shape[1],) + D.shape),
    )
    assert (
        np.abs(flipped.stiffness_matrix(m.p.T).toarray() - K_ref).max()
        <= 1e-12 * np.abs(K_ref).max()
    )


CASE = """name = "p1bar"
dim = 3
[body]
shape = "mesh"
file = "{mesh}"
[material]
E = 1e4
nu = 0.3
density = 2.0
[loads]
set = "homogeneous3d"
magnitude = 10.0
heldout = ["sag"]
[[loads.case]]
name = "sag"
gravity = [0.0, -9.0, 0.0]
[[loads.case.constraint]]
part = "x0"
components = "all"
[reference]
modes = 0
max_refine = 0
[model]
kind = "sms"
placement = "mesh"
masses = "lumped"
stiffness = ["lloyd"]
classes = ["p1"]
[optimizer]
method = "lbfgs"
"""


def test_stage_p1_row_is_exact_on_homogeneous_loads_and_matches_an_independent_p1_solve(tmp_path):
    import meshio

    rng = np.random.default_rng(3)
    m = skfem.MeshTet.init_tensor(np.linspace(0, 2, 5), np.linspace(0, 1, 3), np.linspace(0, 1, 3))
    p = m.p.copy()
    inner = (
        (p[0] > 1e-9)
        & (p[0] < 2 - 1e-9)
        & (p[1] > 1e-9)
        & (p[1] < 1 - 1e-9)
        & (p[2] > 1e-9)
        & (p[2] < 1 - 1e-9)
    )
    # inner nodes only: the faces stay flat
    p[:, inner] += 0.05 * rng.standard_normal((3, inner.sum()))
    t = m.t.T.copy()
    a = p.T[t[:, 1:]] - p.T[t[:, :1]]
    neg = np.einsum("ij,ij->i", a[:, 0], np.cross(a[:, 1], a[:, 2])) < 0
    t[neg, 0], t[neg, 1] = t[neg, 1], t[neg, 0].copy()  # every cell positive, as mesh files must be
    m = skfem.MeshTet(p, t.T)
    meshio.write(tmp_path / "bar.vtu", meshio.Mesh(m.p.T, [("tetra", m.t.T)]))
    f = tmp_path / "p1.toml"
    f.write_text(CASE.format(mesh=tmp_path / "bar.vtu"))
    case = load_case(f)
    out = tmp_path / "out"
    rows = stage.run(case, StageContext(out_dir=out))
    assert {r["model_class"] for r in rows} == {"p1"}
    rows = [r for r in rows if r["optimizer"] == "none"]  # the plain P1 (the fit: its own row)
    assert len(rows) == 1
    # linear exact solution of the homogeneous loads: P1 holds it to rounding
    assert rows[0]["G_norm_final"] < 1e-9
    # an independent P1 solve of the clamped gravity load: scikit-fem's K and load vector
    d = np.load(out / "p1" / "deformed-p1.npz")
    assert np.allclose(d["points"], m.p.T)
    basis = skfem.Basis(m, skfem.ElementVector(skfem.ElementTetP1()))
    K = skfem.asm(linear_elasticity(*lame_parameters(1e4, 0.3)), basis)

    @skfem.LinearForm
    def gravity(v, w):
        return 2.0 * -9.0 * v[1]

    b = skfem.asm(gravity, basis)
    clamped = basis.get_dofs(lambda x: np.isclose(x[0], 0.0)).all()
    u = skfem.solve(*skfem.condense(K, b, D=clamped))
    u_model = d["u_sag"].ravel()  # node-major (x, y, z) like scikit-fem's vector basis
    assert np.abs(u_model - u).max() <= 1e-9 * np.abs(u).max()
    # and the row's G_heldout is that displacement against the reference's (not zero)
    assert rows[0]["G_heldout"] > 1e-3
