"""The FEM reference against independent truths: closed forms (patch tests, a rotated
transversely isotropic body, a bar in series, a bar under its own weight),
Euler-Bernoulli frequencies, manufactured solutions (convergence rates), scikit-fem's
own assembly and element finder, and the cache's behaviour."""

from __future__ import annotations

import dataclasses
import textwrap
from pathlib import Path

import numpy as np
import pytest
import skfem

import reference
from harness.case.loadsets import stretch_closed_form
from harness.case.reader import load_case
from harness.errors import ModelError
from reference.fem import Discretisation

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("SPRINGBENCH_CACHE", str(tmp_path / "cache"))


def make_case(tmp_path, text: str, name="c"):
    p = tmp_path / f"{name}.toml"
    p.write_text(textwrap.dedent(text))
    return load_case(p)


def rect_case(tmp_path, cell, element, *, dim=2, E=3.7e3, nu=0.27, extra="", loads='set = "basic2d"\nmagnitude = 2.5',
              divisions=2, max_refine=0):
    if dim == 2:
        body = 'shape = "rectangle"\norigin = [0.3, -1.2]\nsize = [2.5, 0.8]'
    else:
        body = 'shape = "box"\norigin = [0.3, -1.2, 4.0]\nsize = [2.5, 0.8, 1.3]'
    return make_case(tmp_path, f"""
name = "t"
dim = {dim}
[body]
{body}
[material]
E = {E}
nu = {nu}
plane = "stress"
{extra}
[loads]
{loads}
[reference]
cell = "{cell}"
element = "{element}"
divisions = {divisions}
max_refine = {max_refine}
""")


def rel_err(u, exact):
    return np.linalg.norm(u - exact, axis=1).max() / np.linalg.norm(exact, axis=1).max()


# -- assembly ---------------------------------------------------------------------------

@pytest.mark.parametrize("cell", ["tri", "quad", "tet", "hex"])
@pytest.mark.parametrize("order", ["P1", "P2"])
def test_voigt_assembly_equals_scikit_fem_linear_elasticity(cell, order):
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    from harness.case.elasticity import isotropic_compliance
    M = {"tri": skfem.MeshTri, "quad": skfem.MeshQuad, "tet": skfem.MeshTet, "hex": skfem.MeshHex}[cell]
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
    case = rect_case(tmp_path, cell, element, dim=dim, E=3.7e3, nu=0.41 if dim == 3 else -0.2,
                     loads=loads, divisions=1 if dim == 3 else 2)
    sol = reference.solve(case, cache=False)
    lo, hi = case.body.bbox()
    x = np.random.default_rng(1).uniform(lo, hi, (200, dim))
    stretches = [l for l in case.loads if l.name.startswith("stretch-")]
    assert len(stretches) == dim
    for load in stretches:
        exact = stretch_closed_form(load, sol.mesh.p.T, case.material.E, case.material.nu, case.body.origin)
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
    case = rect_case(tmp_path, cell, "P1", dim=dim, extra=extra,
                     loads=f'set = "basic{dim}d"\nmagnitude = {s}', divisions=2)
    sol = reference.solve(case, cache=False)
    # independent compliance in the fibre frame, written out from the definitions
    S = np.zeros((6, 6))
    S[0, 0], S[1, 1], S[2, 2] = 1 / EL, 1 / ET, 1 / ET
    S[0, 1] = S[1, 0] = S[0, 2] = S[2, 0] = -nuLT / EL
    S[1, 2] = S[2, 1] = -nuTT / ET
    S[3, 3], S[4, 4], S[5, 5] = 2 * (1 + nuTT) / ET, 1 / GLT, 1 / GLT
    a, e = (np.deg2rad(30.0), np.deg2rad(25.0)) if dim == 3 else (np.deg2rad(35.0), 0.0)
    f = np.array([np.cos(a) * np.cos(e), np.sin(e), np.sin(a) * np.cos(e)]) if dim == 3 else \
        np.array([np.cos(a), np.sin(a), 0.0])
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
    case = make_case(tmp_path, f"""
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
""")
    sol = reference.solve(case, cache=False)
    x = sol.mesh.p.T
    X = x[:, 0] - 0.3
    a = 2.5 / 3
    ux = np.where(X <= a, 3.0 * X / 200.0, 3.0 * a / 200.0 + 3.0 * (X - a) / 100.0)
    exact = np.column_stack([ux, np.zeros_like(ux)])
    assert rel_err(sol.vertex_displacement("stretch-x"), exact) <= 1e-10


def test_gravity_bar_quadratic(tmp_path):
    """nu = 0, gravity along -x, rollers at x0: u_x = -(rho g / E)(L x - x^2 / 2), exact for P2."""
    case = make_case(tmp_path, """
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
""")
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
    M = {"tri": skfem.MeshTri, "quad": skfem.MeshQuad, "tet": skfem.MeshTet, "hex": skfem.MeshHex}[cell]
    mesh = M.init_tensor(*[np.linspace(0, 1, n + 1)] * dim)
    d = Discretisation(mesh, cell, order)
    C = lam * np.outer(np.r_[np.ones(dim), np.zeros(3 if dim == 3 else 1)],
                       np.r_[np.ones(dim), np.zeros(3 if dim == 3 else 1)])
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
                    hess_row = hess_row - pi ** 2 * phi(x)
                else:
                    rest = np.prod([np.sin(pi * x[k]) for k in range(dim) if k not in (i, j)], axis=0) if dim == 3 else 1.0
                    hess_row = hess_row + pi ** 2 * np.cos(pi * x[i]) * np.cos(pi * x[j]) * rest
            out.append(-(lam + mu) * hess_row + dim * mu * pi ** 2 * phi(x))
        return np.array(out)

    K = d.stiffness(np.tile(C, (d.nelems, 1, 1)))
    F = d.body_load(force, intorder=d.q_mass + 4)
    fixed = d.part_dofs(lambda x: np.any((x < 1e-12) | (x > 1 - 1e-12), axis=0), range(dim))
    u = solve_system(K, {"m": F}, {"m": fixed}, "direct", d)["m"].reshape(-1, dim)
    b = skfem.CellBasis(mesh, d.elem, intorder=d.q_mass + 4)
    x = np.asarray(b.global_coordinates())
    err = sum(((np.asarray(b.interpolate(u[:, c])) - phi(x)) ** 2 * b.dx).sum() for c in range(dim))
    return np.sqrt(err)


@pytest.mark.parametrize("cell,order,ns,slope", [
    ("tri", "P1", (4, 8, 16), 2), ("tri", "P2", (4, 8, 16), 3), ("quad", "P1", (4, 8, 16), 2),
    ("quad", "P2", (4, 8, 16), 3), ("tet", "P1", (2, 4, 8), 2), ("hex", "P2", (2, 3, 4), 3),
])
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
    fe = cantilever_frequency(2.0e11, 7800.0, L, h ** 3 / 12, h)
    assert abs(f[0] / fe - 1) < 0.02, (f, fe)
    modes = sol.modes(2, load="tip")
    tip = np.argmin(np.linalg.norm(sol.mesh.p.T - [L, h / 2], axis=1))
    assert abs(modes[0][tip, 1]) > 10 * abs(modes[0][tip, 0])  # a bending mode


def test_cantilever_3d_hex(tmp_path):
    from reference.analytic import cantilever_frequency
    case = make_case(tmp_path, """
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
""")
    sol = reference.solve(case, cache=False)
    f = sol.frequencies(3)
    fe = cantilever_frequency(2.0e11, 7800.0, 2.0, 0.1 ** 4 / 12, 0.01)
    assert abs(f[0] / fe - 1) < 0.02 and abs(f[1] / fe - 1) < 0.02, (f, fe)  # two bending planes


# -- point location -------------------------------------------------------------------------

@pytest.mark.parametrize("cell,dim", [("tri", 2), ("tet", 3), ("quad", 2)])
def test_locator_agrees_with_scikit_fem_probes(tmp_path, cell, dim):
    case = rect_case(tmp_path, cell, "P2", dim=dim, loads=f'set = "basic{dim}d"', divisions=3 if dim == 2 else 2)
    sol = reference.solve(case, cache=False)
    lo, hi = case.body.bbox()
    rng = np.random.default_rng(4)
    x = rng.uniform(lo, hi, (300, dim))
    x[:40, 0] = lo[0]  # on the boundary
    x[40:60, 1] = hi[1]
    load = sol.loads[-1]  # a shear: not a linear field
    U = sol.nodal(load)
    mine = sol.displacement(x, load)
    theirs = np.column_stack([sol.basis.probes(x.T) @ U[:, c] for c in range(dim)])
    assert np.abs(mine - theirs).max() <= 1e-12 * np.abs(theirs).max()
    elem, _ = sol.locator.locate(x[60:])
    finder = sol.mesh.element_finder()(*x[60:].T)
    assert np.mean(elem == finder) > 0.99  # interior points: the same element
    # slightly outside (1e-9 of the size) evaluates like the boundary point
    y = x[:40].copy()
    y[:, 0] -= 1e-9 * np.linalg.norm(hi - lo)
    assert np.abs(sol.displacement(y, load) - mine[:40]).max() <= 1e-6 * np.abs(mine).max()
    with pytest.raises(ModelError, match="outside"):
        sol.displacement(np.array([hi + 0.5 * (hi - lo)]), load)


# -- constraints ------------------------------------------------------------------------------

def test_p2_edge_and_corner_constraints(tmp_path):
    case = rect_case(tmp_path, "tet", "P2", dim=3, loads='set = "basic3d"', divisions=2)
    from harness.case.parts import part_predicate
    from reference.mesh import base_mesh
    d = Discretisation(base_mesh(case), "tet", "P2")
    bbox = case.body.bbox()
    n_edge = 2  # cells along y (the shortest side, 2 divisions) on the x0z0 edge
    edge = d.part_dofs(part_predicate("x0z0", bbox), (0, 1, 2))
    assert len(edge) == 3 * (2 * n_edge + 1)  # vertices and mid-edge nodes
    corner = d.part_dofs(part_predicate("x0y0z0", bbox), (1,))
    assert len(corner) == 1 and d.doflocs[:, corner[0] // 3] == pytest.approx(bbox[0])


def test_free_rigid_motion_is_an_error_naming_the_load(tmp_path):
    case = make_case(tmp_path, """
name = "t"
dim = 2
[body]
shape = "rectangle"
size = [1.0, 1.0]
[material]
E = 1.0
nu = 0.3
[[loads.case]]
name = "wobbly"
constraint = [{ part = "x0y0", components = ["all"] }]
traction = [{ part = "x1", vector = [1.0, 0.0] }]
[reference]
max_refine = 0
""")
    with pytest.raises(ModelError, match="wobbly.*1 rigid"):
        reference.solve(case, cache=False)


# -- convergence of the shear references, cache ------------------------------------------------

@pytest.mark.slow
def test_basic2d_shears_mesh_converged():
    case = load_case(ROOT / "cases/verification/plate_stress_tri.toml", "full")
    sol = reference.solve(case, cache=False)
    for name in ("shear-x", "shear-y"):
        assert sol.error_estimate[name] < case.reference.tol, sol.history
    # the estimate shrinks level by level (the refinement converges, not stalls)
    est = [h["shear-x"] for h in sol.history[1:]]
    assert all(b < 0.5 * a for a, b in zip(est, est[1:])), sol.history


def test_cache_roundtrip_and_key(tmp_path):
    from reference.cache import case_key
    case = rect_case(tmp_path, "tri", "P2", divisions=2, max_refine=1)
    a = reference.solve(case)
    b = reference.solve(case)
    assert not a.from_cache and b.from_cache
    for load in a.loads:
        np.testing.assert_array_equal(a.nodal(load), b.nodal(load))
    assert a.error_estimate == b.error_estimate and a.n_dofs == b.n_dofs
    assert list((tmp_path / "cache" / "reference").glob("*.npz"))
    other = dataclasses.replace(case, material=dataclasses.replace(case.material, E=case.material.E * 1.01))
    renamed = dataclasses.replace(case, name="renamed", description="x")
    assert case_key(other) != case_key(case)
    assert case_key(renamed) == case_key(case)
    c = reference.solve(other)
    assert not c.from_cache
    np.testing.assert_allclose(c.nodal("stretch-x") * 1.01, a.nodal("stretch-x"), rtol=1e-9, atol=1e-15)


# -- command and stage ---------------------------------------------------------------------

def test_reference_command_writes_points(tmp_path):
    from harness.cli import main
    case_path = tmp_path / "c.toml"
    rect_case(tmp_path, "tri", "P2", divisions=2, max_refine=0)
    lo = np.array([0.3, -1.2])
    pts = np.array([[0.3, -1.2], [1.0, -1.0], [2.8, -0.4]])
    (tmp_path / "p.csv").write_text("x,y\n" + "\n".join(f"{a},{b}" for a, b in pts))
    out = tmp_path / "u.csv"
    assert main(["reference", str(case_path), "--points", str(tmp_path / "p.csv"), "--out", str(out)]) == 0
    import pandas as pd
    df = pd.read_csv(out)
    assert list(df.columns) == ["load", "x", "y", "ux", "uy"] and len(df) == 3 * 4
    case = load_case(case_path)
    sx = df[df.load == "stretch-x"]
    exact = stretch_closed_form(case.loads[0], pts, case.material.E, case.material.nu, lo)
    np.testing.assert_allclose(sx[["ux", "uy"]].to_numpy(), exact, rtol=1e-9, atol=1e-12)
    (tmp_path / "bad.csv").write_text("a,b\n1,2\n")
    assert main(["reference", str(case_path), "--points", str(tmp_path / "bad.csv"), "--out", str(out)]) == 2


def test_stage_rows(tmp_path):
    from harness.stages import StageContext
    from harness.stages import reference_check as stage
    case = rect_case(tmp_path, "tri", "P2", divisions=2, max_refine=1)
    assert stage.applies(case)
    rows = stage.run(case, StageContext(out_dir=tmp_path))
    assert [r["load"] for r in rows] == ["stretch-x", "stretch-y", "shear-x", "shear-y"]
    assert all(r["model"] == "FEM" and r["n_dofs"] > 0 for r in rows)
    assert rows[0]["closed_form_error"] < 1e-10 and np.isnan(rows[2]["closed_form_error"])
    assert rows[0]["u_max"] == pytest.approx(np.hypot(2.5 * 2.5 / 3.7e3, 0.27 * 2.5 * 0.8 / 3.7e3), rel=1e-9)
    # a row whose estimate misses the case's tol (or has none) says so
    for r in rows:
        assert r["status"] == ("ok" if r["error_estimate"] < r["ref_tol"] else "ref-coarse")
    assert rows[0]["status"] == "ok" and rows[2]["status"] == "ref-coarse"    # one refinement: shear 1e-2
    coarse = stage.run(rect_case(tmp_path, "tri", "P2", divisions=2, max_refine=0), StageContext(out_dir=tmp_path))
    assert all(r["status"] == "ref-coarse" for r in coarse)                # one level: no estimate


# -- polygons ------------------------------------------------------------------------------

def test_polygon_rectangle_patch_and_l_shape_area(tmp_path):
    case = make_case(tmp_path, """
name = "t"
dim = 2
[body]
shape = "polygon"
vertices = [[0.3, -1.2], [2.8, -1.2], [2.8, -0.4], [0.3, -0.4]]
[material]
E = 3.7e3
nu = 0.27
[loads]
set = "basic2d"
[reference]
element = "P2"
divisions = 3
max_refine = 0
""")
    sol = reference.solve(case, cache=False)
    for load in case.loads[:2]:
        exact = stretch_closed_form(load, sol.mesh.p.T, 3.7e3, 0.27, [0.3, -1.2])
        assert rel_err(sol.vertex_displacement(load.name), exact) <= 1e-10
    from reference.mesh import polygon_mesh
    L = [[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]]
    m = polygon_mesh(L, 6)
    x = m.p[:, m.t]
    e1, e2 = x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]
    area = 0.5 * np.abs(e1[0] * e2[1] - e1[1] * e2[0]).sum()
    assert area == pytest.approx(3.0, rel=1e-12)
    assert len(m.boundary_facets()) == len(np.unique(m.facets[:, m.boundary_facets()])) # one closed loop


def test_stage_fibre_closed_form_and_cantilever_columns(tmp_path):
    from harness.stages import StageContext
    from harness.stages import reference_check as stage
    extra = """
[material.fibre]
E_fibre = 4000.0
E_cross = 900.0
azimuth_deg = 20.0
elevation_deg = 30.0
"""
    case = rect_case(tmp_path, "hex", "P1", dim=3, loads='set = "basic3d"', extra=extra, divisions=1)
    rows = stage.run(case, StageContext(out_dir=tmp_path))
    assert rows[0]["closed_form_error"] < 1e-10 and np.isnan(rows[1]["closed_form_error"])
    case = load_case(ROOT / "cases/verification/cantilever_2d.toml")
    case = dataclasses.replace(case, reference=dataclasses.replace(case.reference, max_refine=0))
    rows = stage.run(case, StageContext(out_dir=tmp_path))
    assert all(abs(r["f1_eb_ratio"] - 1) < 0.02 for r in rows)


@pytest.mark.parametrize("method", ["amg", "cg"])
def test_iterative_solvers_match_direct(tmp_path, method):
    case = rect_case(tmp_path, "tet", "P2", dim=3, loads='set = "basic3d"', divisions=2)
    direct = reference.solve(case, cache=False)
    other = dataclasses.replace(case, reference=dataclasses.replace(case.reference, solver=method))
    it = reference.solve(other, cache=False)
    for load in ("shear-xy", "shear-zy"):
        a, b = direct.nodal(load), it.nodal(load)
        assert np.abs(a - b).max() <= 1e-8 * np.abs(a).max()


def test_mass_matrix_total_mass_with_region_density(tmp_path):
    from harness.case.elasticity import densities
    from reference.mesh import base_mesh
    extra = "[[material.regions]]\nbox = [[0.3, -1.2], [1.55, -0.4]]\nE = 200.0\ndensity = 5.0"
    case = rect_case(tmp_path, "quad", "P2", extra=extra + "\n", divisions=2)
    d = Discretisation(base_mesh(case), "quad", "P2")
    rho = densities(case.material, d.centroids())
    M = d.mass(rho)
    ones_x = np.zeros(d.ndof)
    ones_x[0::2] = 1  # a unit translation along x
    total = ones_x @ M @ ones_x
    assert total == pytest.approx(5.0 * 1.25 * 0.8 + 1.0 * 1.25 * 0.8, rel=1e-12)


@pytest.mark.parametrize("cell", ["tet", "hex"])
def test_mesh_file_body_patch(tmp_path, cell):
    """A body read from a mesh file (meshio VTU written here) reproduces the stretches."""
    import meshio
    M = skfem.MeshTet if cell == "tet" else skfem.MeshHex
    m = M.init_tensor(np.linspace(1, 2, 3), np.linspace(0, 0.5, 2), np.linspace(-1, 0, 3))
    from skfem.io.meshio import to_meshio
    out = to_meshio(m)
    if cell == "tet":  # scikit-fem's tensor tets mix orientations; files must not
        c = out.cells[0].data
        x = out.points[c]
        neg = np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0]) < 0
        c[neg] = c[neg][:, [1, 0, 2, 3]]
    meshio.write(tmp_path / "body.vtu", out)
    case = make_case(tmp_path, f"""
name = "t"
dim = 3
[body]
shape = "mesh"
file = "body.vtu"
[material]
E = 10.0
nu = 0.2
[loads]
set = "basic3d"
[reference]
cell = "{cell}"
element = "P1"
max_refine = 0
""")
    sol = reference.solve(case, cache=False)
    for load in case.loads[:3]:
        exact = stretch_closed_form(load, sol.mesh.p.T, 10.0, 0.2, [1, 0, -1])
        assert rel_err(sol.vertex_displacement(load.name), exact) <= 1e-10


def test_plane_strain_stretch_matches_effective_moduli(tmp_path):
    """Plane strain: the stretch is the plane-stress closed form with E/(1-nu^2), nu/(1-nu)."""
    from harness.stages import StageContext
    from harness.stages import reference_check as stage
    case = rect_case(tmp_path, "quad", "P2", E=70.0, nu=0.33)
    case = dataclasses.replace(case, material=dataclasses.replace(case.material, plane="strain"))
    sol = reference.solve(case, cache=False)
    E, nu = 70.0 / (1 - 0.33 ** 2), 0.33 / (1 - 0.33)
    exact = stretch_closed_form(case.loads[1], sol.mesh.p.T, E, nu, case.body.origin)
    assert rel_err(sol.vertex_displacement("stretch-y"), exact) <= 1e-10
    rows = stage.run(case, StageContext(out_dir=tmp_path))
    assert rows[0]["closed_form_error"] < 1e-10
