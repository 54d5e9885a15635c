"""The graded reference of boxes and rectangles (reference/graded/meshes.py, extrapolate.py,
levels.py): meshes, Richardson extrapolation on sequences with a known limit, closed
forms, the case keys, the cache."""

import textwrap

import numpy as np
import pytest

import reference
from harness.case.reader import load_case
from harness.errors import CaseError
from reference.graded.extrapolate import extrapolate, observed_order, richardson
from reference.graded.meshes import (
    AxisMap,
    axis_nodes,
    graded_mesh,
    zone_inverse,
    zone_map,
    zone_slope,
)

pytestmark = pytest.mark.usefixtures("own_cache")


def box_case(
    tmp_path,
    size=(2.5, 0.8, 1.3),
    E=3.7e3,
    nu=0.27,
    loads='set = "basic3d"\nmagnitude = 2.5',
    reference_keys="",
    name="c",
):
    p = tmp_path / f"{name}.toml"
    dim = len(size)
    shape = "box" if dim == 3 else "rectangle"
    origin = [0.3, -1.2, 4.0][:dim]
    p.write_text(
        textwrap.dedent(f"""
        name = "t"
        dim = {dim}
        [body]
        shape = "{shape}"
        origin = {origin}
        size = {list(size)}
        [material]
        E = {E}
        nu = {nu}
        [loads]
        {loads}
        [reference]
        {reference_keys}
        """)
    )
    return load_case(p)


# -- meshes ------------------------------------------------------------------------------


@pytest.mark.parametrize("length", [1.0, 3.0, 10.0])
def test_axis_nodes_are_graded_towards_both_ends(length):
    x = axis_nodes(length, 1.0, 4, beta=3.0)
    assert x[0] == 0.0 and x[-1] == pytest.approx(length, abs=1e-15)
    assert np.all(np.diff(x) > 0)
    np.testing.assert_allclose(x, length - x[::-1], atol=1e-12)  # symmetric
    # a vertex on the mid-plane
    assert len(x) % 2 == 1 and x[len(x) // 2] == pytest.approx(length / 2)
    w = 0.5 * min(length, 1.0)
    assert x[1] == pytest.approx(w * zone_map(0.25))  # the zone's map at the end
    h = np.diff(x)
    assert h.max() <= zone_slope() * w / 4 * 1.0001  # middle cells no larger than the graded limit
    # the middle scales with n: twice the end-zone cells, about twice the middle cells
    mid = lambda n: int(np.sum(axis_nodes(length, 1.0, n) > w + 1e-12)) - 1 - n  # noqa: E731
    if length > 1.0:
        assert mid(8) == pytest.approx(2 * mid(4), abs=2)  # both even


def test_zone_map_is_a_power_law_at_the_face_and_flat_where_the_zone_ends():
    """s^3 near the face (the grading the singular edges need), value 1 and no curvature
    at s = 1 (so a cube's two zones meet without a kink in the cell sizes), increasing;
    the inverse and AxisMap's t(x) undo it."""
    s = np.linspace(0.0, 1.0, 2001)
    f = zone_map(s)
    assert np.all(np.diff(f) > 0) and f[-1] == pytest.approx(1.0, abs=1e-15)
    assert zone_map(1e-4) / 1e-12 == pytest.approx(1.0, rel=1e-3)
    e = 1e-4
    assert (zone_map(1 + e) - 2 * zone_map(1.0) + zone_map(1 - e)) / e**2 == pytest.approx(
        0.0, abs=1e-5
    )
    assert (zone_map(1 + e) - zone_map(1 - e)) / (2 * e) == pytest.approx(zone_slope(), rel=1e-7)
    np.testing.assert_allclose(zone_inverse(f), s, atol=1e-12)
    for length, n in ((3.0, 4), (10.0, 3), (1.05, 5)):
        a = AxisMap.of(length, 1.0, n)
        t = np.linspace(0.0, a.cells, 301)
        np.testing.assert_allclose(a.t(a.x(t)), t, atol=1e-9)
        np.testing.assert_allclose(
            a.x(np.arange(a.cells + 1)), axis_nodes(length, 1.0, n), atol=1e-12 * length
        )


def test_graded_mesh_is_a_tensor_mesh_of_the_box():
    m = graded_mesh([0.3, -1.2, 4.0], [2.5, 0.8, 1.3], 2)
    assert m.t.shape[0] == 8
    np.testing.assert_allclose(m.p.min(axis=1), [0.3, -1.2, 4.0])
    np.testing.assert_allclose(m.p.max(axis=1), [2.8, -0.4, 5.3])
    vol = sum(np.prod(np.ptp(m.p[:, m.t[:, e]], axis=1)) for e in range(m.t.shape[1]))
    assert vol == pytest.approx(2.5 * 0.8 * 1.3, rel=1e-12)


# -- extrapolation ----------------------------------------------------------------------


def test_observed_order_and_richardson_on_a_known_expansion():
    rng = np.random.default_rng(3)
    u = rng.standard_normal((50, 3))
    C, D = rng.standard_normal((50, 3)), rng.standard_normal((50, 3))
    ns = [4, 5, 6, 7]
    h = [1 / n for n in ns]
    V = [u + C * hk**2.7 + 0.3 * D * hk**3.7 for hk in h]
    p = observed_order(V[-3:], h[-3:])
    assert 2.4 < p < 3.2
    E, est = extrapolate(V, h, p)
    err = np.linalg.norm(E - u, axis=1)
    plain = np.linalg.norm(V[-1] - u, axis=1)
    assert err.max() < 0.25 * plain.max()  # extrapolation gains
    assert np.all(est >= err)  # and its estimate bounds it here
    # a pure power: exact for the right order
    W = [u + C * hk**2.0 for hk in h]
    np.testing.assert_allclose(richardson(W[0], W[1], h[0], h[1], 2.0), u, atol=1e-12)
    assert observed_order(W[:3], h[:3]) == pytest.approx(2.0, abs=1e-5)


def test_exact_levels_give_no_order_and_a_rounding_estimate():
    u = np.ones((5, 2))
    assert np.isnan(observed_order([u, u, u], [0.5, 0.25, 0.125]))
    E, est = extrapolate([u, u], [0.5, 0.25], float("nan"))
    assert np.array_equal(E, u) and np.all(est == 0)


# -- the graded reference -----------------------------------------------------------------


def test_box_defaults_to_graded_and_keys_are_checked(tmp_path):
    assert box_case(tmp_path).reference.method == "graded"
    assert box_case(tmp_path).reference.cell == "hex"
    assert box_case(tmp_path, reference_keys='cell = "tet"').reference.method == "refine"
    assert box_case(tmp_path, size=(2.0, 1.0), loads='set = "basic2d"').reference.method == "refine"
    assert (
        box_case(
            tmp_path, size=(2.0, 1.0), loads='set = "basic2d"', reference_keys='method = "graded"'
        ).reference.cell
        == "quad"
    )
    with pytest.raises(CaseError, match="reference.method"):
        box_case(tmp_path, reference_keys='method = "graded"\ncell = "tet"')
    with pytest.raises(CaseError, match="reference.method"):
        box_case(tmp_path, reference_keys='method = "graded"\nelement = "P1"')


@pytest.fixture(scope="module")
def graded_box(tmp_path_factory):
    """One graded solve shared by the tests below: three levels (n = 2, 3, 4)."""
    case = box_case(
        tmp_path_factory.mktemp("box"), size=(1.25, 0.8, 1.0), reference_keys="max_refine = 2"
    )
    return case, reference.solve(case, cache=False)


def test_stretches_meet_their_closed_form_and_stop_refining(graded_box):
    case, sol = graded_box
    lo, hi = case.body.bbox()
    x = np.random.default_rng(1).uniform(lo, hi, (200, 3))
    E, nu, s = 3.7e3, 0.27, 2.5
    for a, name in enumerate(("stretch-x", "stretch-y", "stretch-z")):
        want = -nu * s / E * (x - lo)
        want[:, a] = s / E * (x[:, a] - lo[a])
        got = sol.displacement(x, name)
        assert np.abs(got - want).max() <= 1e-10 * np.abs(want).max()
        assert len(sol.levels.fields[name]) == 2  # exact after two levels
        assert sol.error_estimate[name] < 1e-9
        np.testing.assert_allclose(
            sol.vertex_displacement(name), sol.displacement(sol.mesh.p.T, name), atol=1e-12 * s / E
        )


def test_shears_are_extrapolated_with_a_per_point_estimate(graded_box):
    case, sol = graded_box
    lo, hi = case.body.bbox()
    x = np.random.default_rng(1).uniform(lo, hi, (200, 3))
    assert len(sol.levels.fields["shear-xz"]) == 3 and 1.0 <= sol.levels.orders["shear-xz"] <= 5.0
    est = sol.error_estimate(x, "shear-xz")
    assert est.shape == (200,) and np.all(est >= 0) and np.isfinite(est).all()
    # the extrapolant is Richardson's of the last two (window-averaged) levels at the order used
    vals, h = sol.levels.values(x, "shear-xz")
    p = sol.levels.orders["shear-xz"]
    want = vals[-1] + (vals[-1] - vals[-2]) / ((h[-2] / h[-1]) ** p - 1)
    np.testing.assert_allclose(
        sol.displacement(x, "shear-xz"), want, rtol=0, atol=1e-12 * np.abs(want).max()
    )
    assert np.abs(want - vals[-1]).max() > 0
    # three coarse levels cannot meet 1e-4
    assert sol.error_estimate["shear-xz"] > 1e-4 and not sol.met_tol
    assert [h["n_dofs"] for h in sol.history] == sorted(h["n_dofs"] for h in sol.history)


def test_graded_solution_round_trips_through_the_cache(tmp_path):
    case = box_case(tmp_path, size=(1.0, 1.0, 1.0), reference_keys="max_refine = 2")
    a = reference.solve(case)
    b = reference.solve(case)
    assert b.from_cache and not a.from_cache
    assert a.error_estimate == b.error_estimate and a.n_dofs == b.n_dofs
    x = np.random.default_rng(2).uniform(*case.body.bbox(), (40, 3))
    for name in ("shear-xy", "stretch-z"):
        np.testing.assert_array_equal(a.displacement(x, name), b.displacement(x, name))
        np.testing.assert_array_equal(a.error_estimate(x, name), b.error_estimate(x, name))
    assert a.levels.orders == b.levels.orders
    assert [r.method for r in a.solver] == [r.method for r in b.solver]


@pytest.mark.parametrize(
    "size,nu", [((10.0, 1.0, 1.0), 0.49), ((2.0, 1.0, 0.5), 0.28), ((1000.0, 200.0, 200.0), 0.45)]
)
def test_thin_soft_and_millimetre_boxes_solve_at_default_settings(tmp_path, size, nu):
    """The inputs that made 'auto' give up: a 10:1 bar at nu = 0.49, a
    2 x 1 x 0.5 box, a bar in millimetres with E in Pa. Every load solves to a small
    residual; the stretch meets its closed form, the shears are finite."""
    E = 1e5 if size[0] > 100 else 210.0
    case = box_case(
        tmp_path,
        size=size,
        E=E,
        nu=nu,
        reference_keys="max_refine = 0",
        loads='set = "basic3d"\nmagnitude = 1.0',
    )
    sol = reference.solve(case, cache=False)
    # 3 stretches + 6 shears on their quarters (one mirror each); all to the solver's acceptance
    assert len(sol.solver) == 9 and all(r.residual < 1e-6 for r in sol.solver)
    lo, hi = case.body.bbox()
    x = np.random.default_rng(5).uniform(lo, hi, (50, 3))
    want = -nu / E * (x - lo)
    want[:, 0] = (x[:, 0] - lo[0]) / E
    assert np.abs(sol.displacement(x, "stretch-x") - want).max() <= 1e-9 * np.abs(want).max()
    assert all(np.all(np.isfinite(sol.displacement(x, n))) for n in sol.loads)


def test_box_cell_stiffness_is_the_general_quadrature(monkeypatch):
    """The stiffness of box cells (scaled gradient products of cell 0) equals the general
    per-quadrature-point loop to rounding, for a per-element anisotropic C, in 2-D and
    3-D; a mesh whose cells are not boxes takes the general loop."""
    from reference.fem import Discretisation

    rng = np.random.default_rng(7)
    for dim, cell in ((2, "quad"), (3, "hex")):
        mesh = graded_mesh(np.full(dim, 0.3), np.array([2.5, 0.8, 1.3][:dim]), 2)
        d = Discretisation(mesh, cell, "P2")
        nv = 3 * (dim - 1)
        A = rng.standard_normal((d.nelems, nv, nv))
        C = A @ A.transpose(0, 2, 1) + nv * np.eye(nv)
        assert d._box_cells() is not None
        fast = d.stiffness(C)
        monkeypatch.setattr(d, "_box_cells", lambda: None)
        slow = d.stiffness(C)
        assert abs(fast - slow).max() <= 1e-13 * abs(slow).max()
    skew = graded_mesh(np.zeros(3), np.ones(3), 1)
    skew = type(skew)(skew.p + 0.1 * skew.p[[1]] * np.array([[1.0], [0.0], [0.0]]), skew.t)
    assert Discretisation(skew, "hex", "P2")._box_cells() is None


@pytest.mark.parametrize(
    "first,last,want",
    [
        (2, 10, [2, 3, 4, 6, 8, 9, 10]),
        (2, 9, [2, 3, 4, 6, 7, 8, 9]),
        (2, 8, [2, 3, 4, 6, 7, 8]),
        (2, 6, [2, 3, 4, 5, 6]),
        (3, 4, [3, 4]),
        (1, 12, [1, 2, 3, 5, 7, 9, 10, 11, 12]),
    ],
)
def test_levels_skip_every_second_n_between_the_first_and_last_three(first, last, want):
    from reference.graded.levels import next_divisions

    ns = [first]
    while ns[-1] < last:
        ns.append(next_divisions(ns[-1], first, last))
    assert ns == want
