"""The FEM reference against independent truths: closed forms (patch tests, a rotated
transversely isotropic body, a bar in series, a bar under its own weight),
Euler-Bernoulli frequencies, manufactured solutions (convergence rates), scikit-fem's
own assembly and element finder, and the cache's behaviour."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import skfem

import reference
from harness.case.loadsets import stretch_closed_form
from harness.case.reader import load_case
from reference.fem import Discretisation
from tests.reference.refcases import ROOT, make_case, rect_case, rel_err

pytestmark = pytest.mark.usefixtures("own_cache")


# -- assembly ---------------------------------------------------------------------------


@pytest.mark.parametrize("cell", ["tri", "quad", "tet", "hex"])
@pytest.mark.parametrize("order", ["P1", "P2"])
def test_voigt_assembly_equals_scikit_fem_linear_elasticity(cell, order):
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    from harness.case.elasticity import isotropic_compliance

    M = {"tri": skfem.MeshTri, "quad": skfem.MeshQuad, "tet": skfem.MeshTet, "hex": skfem.MeshHex}[
        cell
    ]
    dim = 2 if cell in ("tri", "quad") else 3
    mesh = M.init_tensor(*[np.linspace(0, 1 + 0.5 * i, 3) for i in range(dim)])
    d = Discretisation(mesh, cell, order)
    C = np.linalg.inv(isotropic_compliance(7.0, 0.21))
    if dim == 2:  # plane strain: the in-plane block of the 3-D stiffness
        C = C[np.ix_([0, 1, 5], [0, 1, 5])]
    K = d.stiffness(np.tile(C, (d.nelems, 1, 1)))
    vb = skfem.Basis(mesh, skfem.ElementVector(d.elem), intorder=d.q_mass)
    K2 = skfem.asm(linear_elasticity(*lame_parameters(7.0, 0.21)), vb)
    assert abs(K - K2).max() <= 1e-12 * abs(K2).max()


# -- patch tests ---------------------------------------------------------------------------


@pytest.mark.parametrize("cell,dim", [("tri", 2), ("quad", 2), ("tet", 3), ("hex", 3)])
@pytest.mark.parametrize("element", ["P1", "P2"])
def test_patch_standard_stretches(tmp_path, cell, dim, element):
    loads = f'set = "basic{dim}d"\nmagnitude = 2.5'
    case = rect_case(
        tmp_path,
        cell,
        element,
        dim=dim,
        E=3.7e3,
        nu=0.41 if dim == 3 else -0.2,
        loads=loads,
        divisions=1 if dim == 3 else 2,
    )
    sol = reference.solve(case, cache=False)
    lo, hi = case.body.bbox()
    x = np.random.default_rng(1).uniform(lo, hi, (200, dim))
    stretches = [l for l in case.loads if l.name.startswith("stretch-")]
    assert len(stretches) == dim
    for load in stretches:
        exact = stretch_closed_form(
            load, sol.mesh.p.T, case.material.E, case.material.nu, case.body.origin
        )
        assert rel_err(sol.vertex_displacement(load.name), exact) <= 1e-10, load.name
        exact = stretch_closed_form(load, x, case.material.E, case.material.nu, case.body.origin)
        assert rel_err(sol.displacement(x, load.name), exact) <= 1e-10, load.name


def _rotated_strain(S_local, Q, sigma):
    """Engineering-shear Voigt strain for global stress tensor sigma (3x3) of a material
    with compliance S_local in the frame whose rows are Q: rotate stress in, strain out."""
    pairs = [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)]
    sl = Q @ sigma @ Q.T
    e = S_local @ np.array([sl[i, j] for i, j in pairs])
    eps_l = np.zeros((3, 3))
    for I, (i, j) in enumerate(pairs):
        eps_l[i, j] = eps_l[j, i] = e[I] if i == j else e[I] / 2
    return Q.T @ eps_l @ Q


@pytest.mark.parametrize("dim,cell", [(3, "tet"), (2, "tri")])
def test_transversely_isotropic_rotated_fibre_uniaxial(tmp_path, dim, cell):
    EL, ET, nuLT, nuTT, GLT = 5000.0, 800.0, 0.28, 0.4, 600.0
    direction = "azimuth_deg = 30.0\nelevation_deg = 25.0" if dim == 3 else "azimuth_deg = 35.0"
    extra = f"""
[material.fibre]
E_fibre = {EL}
E_cross = {ET}
nu_fibre = {nuLT}
nu_cross = {nuTT}
G_fibre = {GLT}
{direction}
"""
    s = 2.5
    case = rect_case(
        tmp_path,
        cell,
        "P1",
        dim=dim,
        extra=extra,
        loads=f'set = "basic{dim}d"\nmagnitude = {s}',
        divisions=2,
    )
    sol = reference.solve(case, cache=False)
    # independent compliance in the fibre frame, written out from the definitions
    S = np.zeros((6, 6))
    S[0, 0], S[1, 1], S[2, 2] = 1 / EL, 1 / ET, 1 / ET
    S[0, 1] = S[1, 0] = S[0, 2] = S[2, 0] = -nuLT / EL
    S[1, 2] = S[2, 1] = -nuTT / ET
    S[3, 3], S[4, 4], S[5, 5] = 2 * (1 + nuTT) / ET, 1 / GLT, 1 / GLT
    a, e = (np.deg2rad(30.0), np.deg2rad(25.0)) if dim == 3 else (np.deg2rad(35.0), 0.0)
    f = (
        np.array([np.cos(a) * np.cos(e), np.sin(e), np.sin(a) * np.cos(e)])
        if dim == 3
        else np.array([np.cos(a), np.sin(a), 0.0])
    )
    t2 = np.cross(f, [0.3, 0.2, 1.0])
    t2 /= np.linalg.norm(t2)
    Q = np.array([f, t2, np.cross(f, t2)])  # any frame with the fibre first (transverse isotropy)
    sigma = np.zeros((3, 3))
    sigma[0, 0] = s
    eps = _rotated_strain(S, Q, sigma)
    # u = L (x - x0): u_x = eps_xx x (rollers at x0); the pinned corners fix the rotation
    L = np.zeros((3, 3))
    L[0, 0], L[1, 1], L[2, 2] = eps[0, 0], eps[1, 1], eps[2, 2]
    L[1, 0], L[2, 0], L[1, 2] = 2 * eps[0, 1], 2 * eps[0, 2], 2 * eps[1, 2]
    L = L[:dim, :dim]
    lo, hi = case.body.bbox()
    x = np.vstack([sol.mesh.p.T, np.random.default_rng(2).uniform(lo, hi, (100, dim))])
    exact = (x - lo) @ L.T
    assert np.abs(L[1, 0]) > 0.1 * np.abs(L[0, 0])  # the fibre really couples stretch and shear
    assert rel_err(sol.displacement(x, "stretch-x"), exact) <= 1e-10


def test_bar_in_series_regions(tmp_path):
    """nu = 0, left third twice as stiff: u_x is piecewise linear (1-D bar in series)."""
    extra = "[[material.regions]]\nbox = [[0.3, -1.2], [1.1333333333333333, -0.4]]\nE = 200.0"
    case = make_case(
        tmp_path,
        f"""
name = "t"
dim = 2
[body]
shape = "rectangle"
origin = [0.3, -1.2]
size = [2.5, 0.8]
[material]
E = 100.0
nu = 0.0
{extra}
[loads]
set = "basic2d"
magnitude = 3.0
[reference]
element = "P1"
divisions = 3
max_refine = 0
""",
    )
    sol = reference.solve(case, cache=False)
    x = sol.mesh.p.T
    X = x[:, 0] - 0.3
    a = 2.5 / 3
    ux = np.where(X <= a, 3.0 * X / 200.0, 3.0 * a / 200.0 + 3.0 * (X - a) / 100.0)
    exact = np.column_stack([ux, np.zeros_like(ux)])
    assert rel_err(sol.vertex_displacement("stretch-x"), exact) <= 1e-10


def test_gravity_bar_quadratic(tmp_path):
    """nu = 0, gravity along -x, rollers at x0: u_x = -(rho g / E)(L x - x^2 / 2), exact for P2."""
    case = make_case(
        tmp_path,
        """
name = "t"
dim = 2
[body]
shape = "rectangle"
size = [2.0, 0.5]
[material]
E = 50.0
nu = 0.0
density = 3.0
[[loads.case]]
name = "weight"
constraint = [{ part = "x0", components = ["x"] }, { part = "x0y0", components = ["y"] }]
gravity = [-9.81, 0.0]
[reference]
element = "P2"
divisions = 2
max_refine = 0
""",
    )
    sol = reference.solve(case, cache=False)
    x = np.random.default_rng(3).uniform([0, 0], [2.0, 0.5], (50, 2))
    ux = -(3.0 * 9.81 / 50.0) * (2.0 * x[:, 0] - x[:, 0] ** 2 / 2)
    assert rel_err(sol.displacement(x, "weight"), np.column_stack([ux, 0 * ux])) <= 1e-10


# -- convergence on a manufactured solution -------------------------------------------------


def _manufactured(cell, order, n):
    """Unit square/cube, u_i = prod sin(pi x_k) (zero on the boundary), plane strain /
    3-D isotropic with Lame lam, mu; f = -(lam + mu) grad div u - mu lap u by hand."""
    from reference.problem import solve_system

    lam, mu = 1.2, 0.8
    dim = 2 if cell in ("tri", "quad") else 3
    M = {"tri": skfem.MeshTri, "quad": skfem.MeshQuad, "tet": skfem.MeshTet, "hex": skfem.MeshHex}[
        cell
    ]
    mesh = M.init_tensor(*[np.linspace(0, 1, n + 1)] * dim)
    d = Discretisation(mesh, cell, order)
    C = lam * np.outer(
        np.r_[np.ones(dim), np.zeros(3 if dim == 3 else 1)],
        np.r_[np.ones(dim), np.zeros(3 if dim == 3 else 1)],
    )
    C += mu * np.diag(np.r_[2 * np.ones(dim), np.ones(3 if dim == 3 else 1)])
    pi = np.pi

    def phi(x):
        return np.prod(np.sin(pi * x), axis=0)

    def force(x):
        out = []
        for i in range(dim):
            hess_row = 0.0
            for j in range(dim):
                if i == j:
                    hess_row = hess_row - pi**2 * phi(x)
                else:
                    rest = (
                        np.prod([np.sin(pi * x[k]) for k in range(dim) if k not in (i, j)], axis=0)
                        if dim == 3
                        else 1.0
                    )
                    hess_row = hess_row + pi**2 * np.cos(pi * x[i]) * np.cos(pi * x[j]) * rest
            out.append(-(lam + mu) * hess_row + dim * mu * pi**2 * phi(x))
        return np.array(out)

    K = d.stiffness(np.tile(C, (d.nelems, 1, 1)))
    F = d.body_load(force, intorder=d.q_mass + 4)
    fixed = d.part_dofs(lambda x: np.any((x < 1e-12) | (x > 1 - 1e-12), axis=0), range(dim))
    u = solve_system(K, {"m": F}, {"m": fixed}, "direct", d)["m"].reshape(-1, dim)
    b = skfem.CellBasis(mesh, d.elem, intorder=d.q_mass + 4)
    x = np.asarray(b.global_coordinates())
    err = sum(((np.asarray(b.interpolate(u[:, c])) - phi(x)) ** 2 * b.dx).sum() for c in range(dim))
    return np.sqrt(err)


@pytest.mark.parametrize(
    "cell,order,ns,slope",
    [
        ("tri", "P1", (4, 8, 16), 2),
        ("tri", "P2", (4, 8, 16), 3),
        ("quad", "P1", (4, 8, 16), 2),
        ("quad", "P2", (4, 8, 16), 3),
        ("tet", "P1", (2, 4, 8), 2),
        ("hex", "P2", (2, 3, 4), 3),
    ],
)
def test_manufactured_l2_rates(cell, order, ns, slope):
    errs = [_manufactured(cell, order, n) for n in ns]
    fit = np.polyfit(np.log(1.0 / np.array(ns)), np.log(errs), 1)[0]
    assert abs(fit - slope) < 0.3, (errs, fit)


def test_manufactured_l2_rate_tet_p2():
    errs = [_manufactured("tet", "P2", n) for n in (2, 3, 4, 6)]
    fit = np.polyfit(np.log(1.0 / np.array([2, 3, 4, 6])), np.log(errs), 1)[0]
    assert abs(fit - 3) < 0.35, (errs, fit)


# -- modal analysis ----------------------------------------------------------------------


def test_cantilever_first_frequency_euler_bernoulli():
    from reference.analytic import cantilever_frequency

    case = load_case(ROOT / "cases/verification/cantilever_2d.toml")
    case = dataclasses.replace(case, reference=dataclasses.replace(case.reference, max_refine=0))
    sol = reference.solve(case, cache=False)
    f = sol.frequencies(2, load="tip")
    L, h = 2.0, 0.1
    fe = cantilever_frequency(2.0e11, 7800.0, L, h**3 / 12, h)
    assert abs(f[0] / fe - 1) < 0.02, (f, fe)
    modes = sol.modes(2, load="tip")
    tip = np.argmin(np.linalg.norm(sol.mesh.p.T - [L, h / 2], axis=1))
    assert abs(modes[0][tip, 1]) > 10 * abs(modes[0][tip, 0])  # a bending mode


def test_cantilever_3d_hex(tmp_path):
    from reference.analytic import cantilever_frequency

    case = make_case(
        tmp_path,
        """
name = "t"
dim = 3
[body]
shape = "box"
size = [2.0, 0.1, 0.1]
[material]
E = 2.0e11
nu = 0.3
density = 7800.0
[[loads.case]]
name = "clamp"
constraint = [{ part = "x0", components = ["all"] }]
[reference]
cell = "hex"
element = "P2"
divisions = 1
max_refine = 0
""",
    )
    sol = reference.solve(case, cache=False)
    f = sol.frequencies(3)
    fe = cantilever_frequency(2.0e11, 7800.0, 2.0, 0.1**4 / 12, 0.01)
    assert abs(f[0] / fe - 1) < 0.02 and abs(f[1] / fe - 1) < 0.02, (f, fe)  # two bending planes
