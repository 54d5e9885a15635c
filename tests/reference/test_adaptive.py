"""Adaptive refinement of mesh bodies (reference/adaptive/adapt.py, estimator.py, meshparts.py):
the residual indicators against hand-computed fields and an exact solution, adaptive
against uniform refinement and the per-point estimate against independent fine solves
(plain scikit-fem elasticity, not the product's assembly), a 3-D gmsh body."""

import textwrap

import meshio
import numpy as np
import pytest
import skfem
from skfem.models.elasticity import lame_parameters, linear_elasticity

import reference
from harness.case.elasticity import densities, element_stiffness
from harness.case.reader import load_case
from reference.adaptive import estimator
from reference.adaptive.adapt import solve_adaptive
from reference.adaptive.meshparts import UserMeshParts
from reference.fem import Discretisation
from reference.mesh import base_mesh
from reference.problem import body_bbox, fixed_dofs, load_vector, solve_mesh

E, NU = 1000.0, 0.3


def write_mesh(path, mesh):
    """A scikit-fem simplex mesh as VTU with every cell positively oriented."""
    p, t = mesh.p, mesh.t.copy()
    dim = p.shape[0]
    J = np.stack([p[:, t[i]] - p[:, t[0]] for i in range(1, dim + 1)], axis=1).transpose(2, 0, 1)
    flip = np.linalg.det(J) < 0
    t[0, flip], t[1, flip] = mesh.t[1, flip], mesh.t[0, flip]
    pts = p.T if dim == 3 else np.c_[p.T, np.zeros(p.shape[1])]
    meshio.write(path, meshio.Mesh(pts, [("tetra" if dim == 3 else "triangle", t.T)]))
    return path


def mesh_case(tmp_path, mesh_file, dim, loads, reference_keys="", parts=""):
    p = tmp_path / "c.toml"
    p.write_text(
        textwrap.dedent(f"""
        name = "a"
        dim = {dim}
        [body]
        shape = "mesh"
        file = "{mesh_file}"
        {parts}
        [material]
        E = {E}
        nu = {NU}
        density = 1.0
        """)
        + textwrap.dedent(loads)
        + "[reference]\n"
        + textwrap.dedent(reference_keys)
    )
    return load_case(p)


CANTILEVER = """
    [[loads.case]]
    name = "bend"
    gravity = [0.0, -5.0]
    [[loads.case.constraint]]
    part = "x0"
    components = "all"
    [[loads.case.traction]]
    part = "x1"
    vector = [0.0, -1.0]
    """


def independent(mesh, trac=(0.0, -1.0), grav=(0.0, -5.0)):
    """Plane-stress P2 elasticity with scikit-fem's own forms: clamped at x = xmin,
    traction on x = xmax, gravity (density 1). (basis, u, load vector)."""
    b = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementTriP2()), intorder=4)
    lam, mu = lame_parameters(E, NU)
    K = skfem.asm(linear_elasticity(2 * lam * mu / (lam + 2 * mu), mu), b)
    F = load(mesh, trac, grav)
    D = b.get_dofs(lambda x: np.abs(x[0] - mesh.p[0].min()) < 1e-9).all()
    return b, skfem.solve(*skfem.condense(K, F, D=D)), F


def load(mesh, trac=(0.0, -1.0), grav=(0.0, -5.0)):
    """The load vector of :func:`independent` (the same dof order as the product's)."""
    e = skfem.ElementVector(skfem.ElementTriP2())
    F = skfem.asm(
        skfem.LinearForm(lambda v, w: grav[0] * v[0] + grav[1] * v[1]),
        skfem.Basis(mesh, e, intorder=4),
    )
    end = mesh.facets_satisfying(
        lambda x: np.abs(x[0] - mesh.p[0].max()) < 1e-9, boundaries_only=True
    )
    return F + skfem.asm(
        skfem.LinearForm(lambda v, w: trac[0] * v[0] + trac[1] * v[1]),
        skfem.FacetBasis(mesh, e, facets=end, intorder=4),
    )


def at_vertices(b, u, n):
    return u[b.nodal_dofs[:, :n]].T


@pytest.fixture(scope="module")
def lshape(tmp_path_factory):
    """[-1, 1]^2 without its upper right quadrant, 96 triangles: clamped at x = -1 and
    pulled down at x = 1, it bends around the re-entrant corner (a singular stress)."""
    d = tmp_path_factory.mktemp("lshape")
    return write_mesh(d / "l.vtu", skfem.MeshTri.init_lshaped().refined(2))


# -- the indicators --------------------------------------------------------------------


def test_residuals_vanish_where_the_element_is_exact():
    """u = (x^2, xy, yz) with lambda = mu = 1: by hand, div sigma = (3 lambda + 5 mu,
    lambda + mu, 0) = (8, 2, 0); a P2 field represents u, so with f = -div sigma the
    element and jump residuals vanish, and with f = 0 the element residual is
    h^2 |T| |div sigma|^2."""
    m = skfem.MeshTet.init_tensor(*[np.linspace(0, 1, 3)] * 3)
    d = Discretisation(m, "tet", "P2")
    C = np.zeros((6, 6))
    C[:3, :3] = 1.0
    C[np.arange(3), np.arange(3)] += 2.0
    C[3:, 3:] = np.eye(3)
    C = np.broadcast_to(C, (d.nelems, 6, 6)).copy()
    x = d.doflocs
    U = np.stack([x[0] ** 2, x[0] * x[1], x[1] * x[2]], axis=1)
    free = np.zeros((m.p.shape[1], 3), bool)
    div = np.array([8.0, 2.0, 0.0])
    field = estimator.Field(None, U, np.broadcast_to(-div, (d.nelems, 3)).copy(), free)
    assert estimator.element_residual(d, [field], C).max() < 1e-24
    assert estimator.jump_residual(d, [field], C).max() < 1e-24
    bare = estimator.element_residual(
        d, [estimator.Field(None, U, np.zeros((d.nelems, 3)), free)], C
    )[0]
    h = estimator.diameters(m.p, m.t)
    np.testing.assert_allclose(bare, h**2 / d.nelems * (div**2).sum(), rtol=1e-10)


def test_indicators_are_rounding_for_a_closed_form_and_zero_on_a_clamp(tmp_path, lshape):
    """The homogeneous stress states' fields are exact (linear): every indicator is
    rounding; a component fixed at all vertices of an element carries no residual."""
    case = mesh_case(tmp_path, lshape, 2, '[loads]\nset = "homogeneous2d"\nmagnitude = 1.0\n')
    mesh = base_mesh(case)
    d = Discretisation(mesh, "tri", "P2")
    U = solve_mesh(case, mesh)
    C, rho = (
        element_stiffness(case.material, d.centroids()),
        densities(case.material, d.centroids()),
    )
    bbox = body_bbox(case, mesh)
    fixed = {l.name: fixed_dofs(d, case, l, bbox) for l in case.loads}
    eta = estimator.indicators(d, case, case.loads, U, C, rho, bbox, fixed)
    K = d.stiffness(C)
    for l in case.loads:
        assert eta[l.name].sum() < 1e-24 * (U[l.name] @ K @ U[l.name])
    everything = {l.name: np.arange(d.ndof) for l in case.loads}
    noisy = {n: u + 1e-3 * np.sin(np.arange(d.ndof)) for n, u in U.items()}
    eta = estimator.indicators(d, case, case.loads, noisy, C, rho, bbox, everything)
    assert all(v.max() == 0 for v in eta.values())


def test_effectivity_against_an_exact_solution(tmp_path):
    """A free 1 x 0.4 plate pushed along x by gravity G and held by the traction -G L on
    x = 0 (two point supports without reactions). By hand: sigma_xx = G (L - x), the
    rest zero, u = G/E (L x - x^2/2 - nu y^2/2, -nu (L - x) y): quadratic, so P2 is exact
    (eta = 0) and P1 is not; its energy error is exact from the compliance,
    a(e, e) = F(u) - F(u_h), F(u) = G^2 H L^3 / (3 E). The P1 effectivity eta / |e|_a
    stays in a band and constant under refinement (eta converges like the error)."""
    L, H, G = 1.0, 0.4, 10.0
    m0 = skfem.MeshTri.init_tensor(np.linspace(0, L, 6), np.linspace(0, H, 3))
    f = write_mesh(tmp_path / "plate.vtu", m0)
    loads = f"""
        [[loads.case]]
        name = "push"
        gravity = [{G}, 0.0]
        [[loads.case.constraint]]
        part = "a"
        components = "all"
        [[loads.case.constraint]]
        part = "b"
        components = ["y"]
        [[loads.case.traction]]
        part = "x0"
        vector = [{-G * L}, 0.0]
        """
    parts = (
        "[body.parts]\na = { box = [[0.0, 0.0], [0.0, 0.0]] }\n"
        "b = { box = [[1.0, 0.0], [1.0, 0.0]] }\n"
    )
    exact = G**2 * H * L**3 / (3 * E)
    ratios = []
    for order in ("P1", "P2"):
        case = mesh_case(tmp_path, f, 2, loads, f'element = "{order}"\n', parts)
        for k in range(3):
            mesh = base_mesh(case).refined(k) if k else base_mesh(case)
            d = Discretisation(mesh, "tri", order)
            C, rho = (
                element_stiffness(case.material, d.centroids()),
                densities(case.material, d.centroids()),
            )
            bbox = body_bbox(case, mesh)
            load = case.loads[0]
            u = solve_mesh(case, mesh, disc=d)["push"]
            err2 = exact - load_vector(d, case, load, bbox, rho) @ u
            eta2 = estimator.indicators(
                d,
                case,
                [load],
                {"push": u},
                C,
                rho,
                bbox,
                {"push": fixed_dofs(d, case, load, bbox)},
            )["push"].sum()
            if order == "P2":
                assert abs(err2) < 1e-10 * exact and eta2 < 1e-20 * exact
            else:
                ratios.append(np.sqrt(eta2 / err2))
    assert all(1.0 < r < 20.0 for r in ratios), ratios
    assert max(ratios) / min(ratios) < 1.5, ratios


def test_p2_effectivity_and_adaptive_beats_uniform(tmp_path, lshape):
    """The bent L: against an independent solve on the adaptive mesh refined twice more,
    the energy error a(e, e) = F(u) - F(u_h) of uniform levels and of the adaptive
    reference. The P2 effectivity stays in a band on the uniform levels, and the adaptive
    mesh ends with a smaller error than the first uniform level with as many dofs."""
    case = mesh_case(tmp_path, lshape, 2, CANTILEVER, "max_refine = 3\ntol = 1e-8\n")
    mesh, U, est, history, _, _ = solve_adaptive(case)
    b, u, F = independent(mesh.refined(2))
    truth = F @ u

    def energy_error(m, uh):
        return np.sqrt(truth - load(m) @ uh)

    adaptive = energy_error(mesh, U["bend"])
    m = base_mesh(case)
    eff, uniform = [], []
    while not uniform or uniform[-1][0] < history[-1]["n_dofs"]:
        d = Discretisation(m, "tri", "P2")
        C, rho = (
            element_stiffness(case.material, d.centroids()),
            densities(case.material, d.centroids()),
        )
        bbox = body_bbox(case, m)
        uh = solve_mesh(case, m, disc=d)
        np.testing.assert_allclose(
            load_vector(d, case, case.loads[0], bbox, rho), load(m), atol=1e-12
        )
        eta2 = estimator.indicators(
            d,
            case,
            case.loads,
            uh,
            C,
            rho,
            bbox,
            {"bend": fixed_dofs(d, case, case.loads[0], bbox)},
        )["bend"].sum()
        uniform.append((d.ndof, energy_error(m, uh["bend"])))
        eff.append(np.sqrt(eta2) / uniform[-1][1])
        m = m.refined()
    assert all(1.0 < r < 20.0 for r in eff) and max(eff) / min(eff) < 1.5, eff
    assert adaptive < uniform[-1][1], (adaptive, uniform, history[-1]["n_dofs"])


# -- the estimate where the models are scored --------------------------------------------


def test_point_estimate_bounds_the_true_error_at_every_vertex(tmp_path):
    """A holed plate (gmsh) clamped at x = 0 and bent: the reference's per-point
    estimate at the user's vertices against the error of its displacement there, from
    an independent solve on its final mesh refined twice (whose own error is far
    smaller: checked against a third refinement). It bounds the error at every vertex
    and is not a wild over-estimate."""
    pytest.importorskip("gmsh")
    from tests import meshes

    case = mesh_case(
        tmp_path,
        meshes.holed_plate(tmp_path, size=0.08),
        2,
        CANTILEVER,
        "max_refine = 3\ntol = 1e-8\n",
    )
    ref = reference.solve(case, cache=False)
    nv = base_mesh(case).p.shape[1]
    pts = base_mesh(case).p.T
    truth = [at_vertices(*independent(ref.mesh.refined(r))[:2], nv) for r in (2, 3)]
    u = ref.displacement(pts, "bend")
    err = np.linalg.norm(u - truth[0], axis=1)
    assert np.linalg.norm(truth[1] - truth[0], axis=1).max() < 0.2 * err.max()
    e = ref.error_estimate(pts, "bend")
    assert np.all(e >= err), np.max(err / np.maximum(e, 1e-300))
    assert e.max() < 30 * err.max()
    assert ref.error_estimate["bend"] == pytest.approx(
        e.max() / np.linalg.norm(u, axis=1).max(), rel=1e-9
    )
    assert ref.level >= 2 and np.isfinite(ref.error_estimate["bend"])


def test_no_refinement_no_estimate_and_closed_forms_are_exact(tmp_path, lshape):
    one = reference.solve(
        mesh_case(tmp_path, lshape, 2, CANTILEVER, "max_refine = 0\n"), cache=False
    )
    assert np.isnan(one.error_estimate["bend"]) and not one.met_tol
    assert np.isnan(one.error_estimate(one.mesh.p.T[:3], "bend")).all()
    exact = reference.solve(
        mesh_case(tmp_path, lshape, 2, '[loads]\nset = "homogeneous2d"\n'), cache=False
    )
    assert exact.level == 0 and exact.met_tol and max(exact.error_estimate.values()) == 0.0


def test_doerfler_marks_the_fewest_elements_for_the_share():
    eta2 = np.array([1.0, 4.0, 2.0, 3.0])
    assert set(estimator.doerfler(eta2, 0.5)) == {1, 3}  # 4 + 3 >= 5
    assert set(estimator.doerfler(eta2, 0.1)) == {1}
    assert set(estimator.doerfler(eta2, 0.1, least=0.5)) == {1, 3}


# -- a 3-D gmsh body -------------------------------------------------------------------------


def test_gmsh_body_gets_a_finite_cached_estimate_and_keeps_the_users_parts(tmp_path, monkeypatch):
    """A gmsh cylinder clamped and loaded on slabs that cut its tetrahedra (calibrate's
    held-out loads): a finite estimate after adaptive refinement, the same per-point
    estimate from the cache, and on every level the tip traction's resultant is the
    traction times the area of the user's boundary facets in the slab (an independent
    sum of triangle areas), and the clamp holds exactly the points of the user's
    clamped entities."""
    pytest.importorskip("gmsh")
    from tests import meshes

    f = meshes.cylinder(tmp_path, size=0.08)
    loads = """
        [[loads.case]]
        name = "tip"
        [[loads.case.constraint]]
        part = "clamp"
        components = "all"
        [[loads.case.traction]]
        part = "tip"
        vector = [0.0, -100.0, 0.0]
        """
    parts = (
        "[body.parts]\nclamp = { box = [[-1.0, -1.0, -1.0], [0.03, 1.0, 1.0]] }\n"
        "tip = { box = [[0.47, -1.0, -1.0], [1.0, 1.0, 1.0]] }\n"
    )
    case = mesh_case(tmp_path, f, 3, loads, "max_refine = 1\ntol = 1e-6\n", parts)
    monkeypatch.setenv("SPRINGBENCH_CACHE", str(tmp_path / "cache"))
    ref = reference.solve(case)
    m0 = base_mesh(case)
    assert ref.level >= 2 and 0 < ref.error_estimate["tip"] < 1 and not ref.met_tol
    pts = m0.p.T
    e = ref.error_estimate(pts, "tip")
    assert np.all(np.isfinite(e)) and e.max() > 0
    again = reference.solve(case)
    assert again.from_cache
    np.testing.assert_array_equal(again.error_estimate(pts, "tip"), e)
    np.testing.assert_array_equal(again.displacement(pts, "tip"), ref.displacement(pts, "tip"))
    # the user's loaded facets: boundary triangles with all vertices (and centroid) in the slab
    faces = np.sort(
        np.vstack([m0.t[[a, b, c]].T for a, b, c in ((0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3))]),
        axis=1,
    )
    uniq, count = np.unique(faces, axis=0, return_counts=True)
    bnd = uniq[count == 1]
    loaded = bnd[(m0.p[0, bnd] >= 0.47 - 1e-9).all(axis=1)]
    x = m0.p[:, loaded]  # (3, facets, 3 vertices)
    area = (
        0.5
        * np.linalg.norm(
            np.cross((x[:, :, 1] - x[:, :, 0]).T, (x[:, :, 2] - x[:, :, 0]).T), axis=1
        ).sum()
    )
    parts_ = UserMeshParts(case, m0)
    for mesh in (m0, m0.refined(), ref.mesh):
        d = Discretisation(mesh, "tet", "P2")
        bbox = body_bbox(case, mesh)
        F = load_vector(d, case, case.loads[0], bbox, np.ones(d.nelems), parts=parts_).reshape(
            -1, 3
        )
        assert F.sum(axis=0) == pytest.approx([0.0, -100.0 * area, 0.0], abs=1e-9 * 100 * area)
        fixed = np.unique(fixed_dofs(d, case, case.loads[0], bbox, parts=parts_) // 3)
        on_clamp = d.doflocs[0] <= 0.03 + 1e-9
        user_clamped = m0.p[0] <= 0.03 + 1e-9
        assert set(fixed) <= set(np.flatnonzero(on_clamp))
        assert set(np.flatnonzero(user_clamped)) <= set(fixed)
        assert len(fixed) < on_clamp.sum()  # the slab's own points would be more


# -- the estimate against an independent 3-D solve -------------------------------------------

SHEAR = """
    [[loads.case]]
    name = "shear"
    [[loads.case.constraint]]
    part = "z0"
    components = "all"
    [[loads.case.traction]]
    part = "z1"
    vector = [1.0, 0.0, 0.0]
    """


def test_cube_estimate_bounds_the_independent_error_without_a_wild_factor(tmp_path):
    """A 3 x 3 x 3 cube of tetrahedra (vertices at thirds, as the B&C cube_333) sheared:
    face z = 0 clamped, traction along x on z = 3. The truth at the user's vertices is the
    independent graded Q2 solve of tests/independent/ (its own assembly,
    mesh and solver, extrapolated; its own error checked far below the reference's).
    The reference's per-point estimate bounds the true error at every vertex and its
    largest value is within a small factor of the largest true error (the estimate over
    consecutive adaptive levels was ~10x)."""
    from tests import independent as ie

    m = skfem.MeshTet.init_tensor(*[np.linspace(0.0, 3.0, 4)] * 3)
    case = mesh_case(
        tmp_path, write_mesh(tmp_path / "cube.vtu", m), 3, SHEAR, "max_refine = 3\ntol = 1e-8\n"
    )
    ref = reference.solve(case, cache=False)
    pts = base_mesh(case).p.T
    truth, change, _ = ie.extrapolated_shear(
        (3.0, 3.0, 3.0), E, NU, 1.0, pts, levels=(4, 8, 12), knot=0.75
    )
    umax = np.linalg.norm(truth, axis=1).max()
    err = np.linalg.norm(ref.displacement(pts, "shear") - truth, axis=1)
    assert change < 0.05 * err.max() / umax  # the truth's own error: far smaller
    e = ref.error_estimate(pts, "shear")
    moving = err > 1e-9 * umax  # not the clamped vertices
    assert np.all(e[moving] >= err[moving]), np.min(e[moving] / err[moving])
    assert e.max() < 4.0 * err.max(), (e.max(), err.max())
    # i, j, k
    assert len(ref.history) >= 3 and ref.history[-1]["n_dofs"] >= 8 * ref.history[0]["n_dofs"]
