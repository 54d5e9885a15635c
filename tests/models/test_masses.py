"""Masses (Deussen Section 4): moments of bodies and the min-norm / non-negative /
Voronoi rules, against independent formulas and numpy's lstsq."""

import numpy as np
import pytest

from harness.case.reader import Material, Region
from harness.geometry import box, grid_points, polygon, random_points, rectangle
from harness.models.masses import (
    body_moments,
    box_moments,
    compute_masses,
    mesh_moments,
    monomials,
    polygon_moments,
)

L_SHAPE = np.array([[1, 2], [3, 2], [3, 3], [2, 3], [2, 4], [1, 4]], float)  # away from the origin


def test_polygon_moments_equal_box_formula_and_additivity():
    rect = np.array([[1, 2], [4, 2], [4, 3.5], [1, 3.5]])
    assert np.allclose(polygon_moments(rect), box_moments([1, 2], [4, 3.5]), rtol=1e-14)
    m = polygon_moments(L_SHAPE)
    parts = box_moments([1, 2], [3, 3]) + box_moments([1, 3], [2, 4])
    assert np.allclose(m, parts, rtol=1e-14)


def test_mesh_moments_triangles_and_hexahedra():
    tri = np.array([[0, 1, 2], [0, 2, 3]])
    pts = np.array([[1, 2], [4, 2], [4, 3.5], [1, 3.5]], float)
    assert np.allclose(
        mesh_moments(pts, {"triangle": tri}), box_moments([1, 2], [4, 3.5]), rtol=1e-13
    )
    lo, hi = np.array([1.0, 2, 3]), np.array([2.0, 4, 3.5])
    corners = np.array(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
    )
    hp = lo + corners * (hi - lo)
    assert np.allclose(
        mesh_moments(hp, {"hexahedron": np.arange(8)[None]}), box_moments(lo, hi), rtol=1e-13
    )


@pytest.mark.parametrize("body,n", [(polygon(L_SHAPE), 40), (box([1, 2, 3], [2, 4, 3.5]), 70)])
def test_min_norm_masses_reproduce_moments_and_equal_lstsq(body, n):
    p = random_points(body, n, seed=7)
    res = compute_masses("moments", p, body)
    A = monomials(p)
    exact = body_moments(body)
    rel = np.abs(A @ res.masses - exact) / np.abs(exact)
    assert rel.max() < 1e-12
    ls = np.linalg.lstsq(A, exact, rcond=None)[0]  # numpy's min-norm solution
    assert np.allclose(res.masses, ls, rtol=1e-9, atol=1e-12 * np.abs(ls).max())
    assert res.residual < 1e-12


def test_nonneg_masses_have_no_negatives_and_match_moments():
    body = polygon(L_SHAPE)
    p = random_points(body, 40, seed=1)
    plain = compute_masses("moments", p, body)
    nn = compute_masses("moments-nonneg", p, body)
    assert plain.n_negative > 0  # this point set needs the variant
    assert nn.n_negative == 0 and nn.masses.min() >= 0
    assert nn.residual < 1e-6


def test_voronoi_masses_on_a_grid_are_cell_areas():
    body = rectangle([0, 0], [4, 2])
    p = grid_points(body.lo, body.hi, (5, 3))
    m = compute_masses("voronoi", p, body, Material(E=1, nu=0.3, density=2.0)).masses.reshape(3, 5)
    assert np.isclose(m[1, 1], 2.0 * 1.0 * 1.0)  # interior: h^2 rho
    assert np.isclose(m[0, 1], 2.0 * 0.5)  # edge: half
    assert np.isclose(m[0, 0], 2.0 * 0.25)  # corner: quarter
    u = compute_masses("uniform", p, body, Material(E=1, nu=0.3, density=2.0))
    assert np.allclose(u.masses, 16.0 / 15)


def test_density_regions_enter_the_moments():
    body = rectangle([0, 0], [3, 1])
    mat = Material(E=1, nu=0.3, density=1.0, regions=(Region((0, 0), (1, 1), 2.0, None, 5.0),))
    p = body_moments(body, mat)
    assert np.isclose(p[0], 5 * 1 + 1 * 2)
    assert np.isclose(p[1], 5 * 0.5 + 1 * (9 - 1) / 2)  # int x over [0,1]: 1/2; over [1,3]: 4
    m = compute_masses("moments", grid_points(body.lo, body.hi, (7, 3)), body, mat)
    assert np.isclose(m.masses.sum(), 7.0) and m.residual < 1e-12
