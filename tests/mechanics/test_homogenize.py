"""Lattice closed forms (derived by hand in the docstrings) against the homogenisation
module and against the statics of large grids under the standard stretch-x load."""

import numpy as np
import pytest
from scipy.spatial import Delaunay

from harness.case.elasticity import isotropic_compliance, plane
from harness.case.loadsets import basic2d, basic3d
from harness.case.reader import Body, Case, Material
from harness.geometry import grid_points
from harness.mechanics import statics
from harness.mechanics.homogenize import (
    boundary_share,
    case_report,
    cauchy_report,
    engineering_constants,
    group_stiffness,
    lattice_stiffness,
)
from harness.models.sms import make_network
from harness.models.topology import grid_structure

S = 1e-3  # traction


def _case(lo, hi, E=1.0, nu=0.3):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    dim = len(lo)
    return Case(
        path=None,
        name="t",
        dim=dim,
        body=Body("rectangle" if dim == 2 else "box", tuple(lo), tuple(hi - lo)),
        material=Material(E, nu),
        loads=basic2d(S) if dim == 2 else basic3d(S),
        reference=None,
    )


def _measured(net, case):
    """E and nu from the stretch-x statics: end displacements of the x1 and y1 faces."""
    u = statics.solve(net, case, ["stretch-x"]).u[0]
    lo, hi = case.body.bbox()
    p = net.points
    x1 = np.isclose(p[:, 0], hi[0])
    y1 = np.isclose(p[:, 1], hi[1])
    exx = u[x1, 0].mean() / (hi[0] - lo[0])
    eyy = u[y1, 1].mean() / (hi[1] - lo[1])
    return S / exx, -eyy / exx, u


def test_square_lattice_closed_form_isotropic_nu_one_third():
    """Structure 1 with k_edge = 2 k_diag: per cell C11 = k_e + k_d, C12 = C66 = k_d, so
    k_e = 2 k_d is isotropic with nu = C12/C11 = 1/3 and E = (C11^2 - C12^2)/C11 = 8 k_d/3."""
    kd = 0.7
    C = lattice_stiffness(
        np.array([[1, 0], [0, 1], [1, 1], [-1, 1]], float), [2 * kd, 2 * kd, kd, kd], 1.0
    )
    assert np.allclose(C, [[3 * kd, kd, 0], [kd, 3 * kd, 0], [0, 0, kd]])
    n = 21
    p = grid_points([0, 0], [n - 1, n - 1], (n, n))
    top = grid_structure((n, n), "structure1")
    kg = np.array([2 * kd, 2 * kd, kd])[top.groups]
    k = kg * boundary_share(p, top.springs, p.min(0), p.max(0))
    case = _case(p.min(0), p.max(0))
    E, nu, u = _measured(make_network(p, top.springs, k), case)
    assert E == pytest.approx(8 * kd / 3, rel=1e-9)
    assert nu == pytest.approx(1 / 3, rel=1e-9)
    # the whole field is the affine closed form (cell-wise assembly makes it exact)
    assert np.allclose(u[:, 0], S * p[:, 0] / E, atol=1e-12)
    assert np.allclose(u[:, 1], -nu * S * p[:, 1] / E, atol=1e-12)


def _triangle_lattice(nx, ny, h=1.0):
    r = h * np.sqrt(3) / 2
    pts = [
        (x, j * r)
        for j in range(ny)
        for x in (np.arange(nx) * h if j % 2 == 0 else (np.arange(nx - 1) + 0.5) * h)
    ]
    return np.array(pts)


def test_equilateral_triangle_lattice_closed_form():
    """Three spring directions 60 degrees apart: sum n^4 over them is 3/8 (dd + dd + dd),
    so lambda = mu = sqrt(3) k / 4 (cell area sqrt(3)/2 h^2, unit thickness), plane
    stress E = 8 mu / 3 = 2 k / sqrt(3) and nu = 1/3. Per-triangle assembly: each
    triangle gives k/2 to its edges."""
    k = 1.3
    vec = np.array([[1, 0], [0.5, np.sqrt(3) / 2], [-0.5, np.sqrt(3) / 2]])
    c = engineering_constants(lattice_stiffness(vec, [k] * 3, np.sqrt(3) / 2))
    assert c["E_x"] == pytest.approx(2 * k / np.sqrt(3)) and c["nu_xy"] == pytest.approx(1 / 3)
    p = _triangle_lattice(41, 41)
    tri = Delaunay(p).simplices
    q = p[tri]
    tri = tri[np.all(np.isclose(np.linalg.norm(q - np.roll(q, 1, axis=1), axis=2), 1.0), axis=1)]
    pairs = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [0, 2]]]), axis=1)
    springs, count = np.unique(pairs, axis=0, return_counts=True)
    net = make_network(p, springs, count * k / 2)
    case = _case(p.min(0), p.max(0))
    u = statics.solve(net, case, ["stretch-x"]).u[0]
    # away from the zig-zag sides
    mid = np.all(np.abs(p - p.mean(0)) < 0.25 * np.ptp(p, axis=0), axis=1)
    X = np.hstack([p[mid], np.ones((mid.sum(), 1))])
    grad = np.linalg.lstsq(X, u[mid], rcond=None)[0]
    E, nu = S / grad[0, 0], -grad[1, 1] / grad[0, 0]
    assert E == pytest.approx(2 * k / np.sqrt(3), rel=1e-2)
    assert nu == pytest.approx(1 / 3, rel=1e-2)


def test_cubic_lattice_closed_form():
    """Edges k1 and face diagonals k2 (h = 1): C11 = k1 + 2 k2, C12 = C44 = k2; k1 = k2 = k
    is isotropic with lambda = mu = k: nu = 1/4, E = mu (3 lambda + 2 mu)/(lambda + mu) = 5k/2."""
    k = 0.8
    Cg, names = group_stiffness("edges+face", [1, 1, 1])
    C = np.einsum("g,gij->ij", [k] * 6, Cg)
    assert np.allclose(C[:3, :3], k * (np.ones((3, 3)) + 2 * np.eye(3)))
    assert np.allclose(np.diag(C)[3:], k)
    n = 6
    p = grid_points([0, 0, 0], [n - 1] * 3, (n, n, n))
    top = grid_structure((n, n, n), "edges+face")
    kk = k * boundary_share(p, top.springs, p.min(0), p.max(0))
    case = _case(p.min(0), p.max(0))
    E, nu, u = _measured(make_network(p, top.springs, kk), case)
    assert E == pytest.approx(2.5 * k, rel=1e-9)
    assert nu == pytest.approx(0.25, rel=1e-9)
    assert np.allclose(u[:, 2], -nu * S * p[:, 2] / E, atol=1e-12)


@pytest.mark.parametrize("nu,reachable", [(1 / 3, True), (0.3, False), (0.2, False)])
def test_cauchy_report_flags_unreachable_nu_2d(nu, reachable):
    C_t = plane(np.linalg.inv(isotropic_compliance(1.0, nu)), "stress")
    r = cauchy_report("structure1", [1, 1], C_t)
    assert r["reachable"] is reachable
    assert r["cauchy_nu"] == pytest.approx(1 / 3)
    if reachable:
        # k_e = 3E/4, k_d = 3E/8 (E = 8 k_d / 3)
        assert np.allclose(r["k_groups"], [0.75, 0.75, 0.375])
        assert r["fit"]["nu_xy"] == pytest.approx(1 / 3)
    else:
        assert r["misfit"] > 1e-3


def test_cauchy_report_3d_and_case():
    C3 = np.linalg.inv(isotropic_compliance(1.0, 0.25))
    assert cauchy_report("edges+face", [1, 1, 1], C3)["reachable"]
    assert not cauchy_report(
        "edges+face", [1, 1, 1], np.linalg.inv(isotropic_compliance(1.0, 0.3))
    )["reachable"]
    case = _case([0, 0], [4, 4], nu=0.3)
    rep = case_report(case, {"placement": "grid", "grid": [5, 5], "structure": "structure1"})
    assert not rep["reachable"] and rep["cauchy_nu"] == pytest.approx(1 / 3)
    assert case_report(case, {"placement": "random"}) is None
