"""Core helpers: parts, standard load sets, constitutive matrices (closed forms)."""

import numpy as np
import pytest

from harness.case.elasticity import (
    isotropic_compliance,
    lame,
    plane,
    rotate,
    transversely_isotropic_compliance,
)
from harness.case.loadsets import basic2d, basic3d, stretch_closed_form
from harness.case.parts import classify_nodes, part_predicate


def box_points(lo, hi, n=4):
    axes = [np.linspace(a, b, n) for a, b in zip(lo, hi)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, len(lo))


@pytest.mark.parametrize("dim", [2, 3])
def test_stretch_closed_form_meets_every_constraint(dim):
    lo, hi = np.array([1.0, -2.0, 0.5][:dim]), np.array([3.0, 1.0, 4.0][:dim])
    pts = box_points(lo, hi)
    loads = basic2d(2.5) if dim == 2 else basic3d(2.5)
    stretches = [l for l in loads if l.name.startswith("stretch")]
    assert len(stretches) == dim
    for load in stretches:
        u = stretch_closed_form(load, pts, E=7.0, nu=0.3, origin=lo)
        for c in load.constraints:
            mask = part_predicate(c.part, (lo, hi))(pts.T)
            assert mask.any(), c.part
            assert np.abs(u[mask][:, list(c.components)]).max() < 1e-14


@pytest.mark.parametrize("dim", [2, 3])
def test_stretch_constraints_remove_rigid_motions(dim):
    """The constrained components on a box's nodes leave no rigid motion: the rigid
    modes restricted to the constrained dofs have full column rank."""
    lo, hi = np.zeros(dim), np.array([2.0, 1.0, 3.0][:dim])
    pts = box_points(lo, hi)
    if dim == 2:
        modes = [
            np.tile([1, 0], (len(pts), 1)),
            np.tile([0, 1], (len(pts), 1)),
            np.stack([-pts[:, 1], pts[:, 0]], 1),
        ]
        loads = basic2d(1.0)
    else:
        modes = [np.tile(np.eye(3)[i], (len(pts), 1)) for i in range(3)]
        modes += [np.cross(np.eye(3)[i], pts) for i in range(3)]
        loads = basic3d(1.0)
    for load in loads:
        rows = []
        for c in load.constraints:
            mask = part_predicate(c.part, (lo, hi))(pts.T)
            for comp in c.components:
                rows.append(np.stack([m[mask, comp] for m in modes], 1))
        R = np.vstack(rows)
        assert np.linalg.matrix_rank(R) == len(modes), load.name


def test_basic3d_names_follow_design():
    names = [l.name for l in basic3d(1.0)]
    assert names == (
        ["stretch-x", "stretch-y", "stretch-z", "shear-xy", "shear-yx"]
        + ["shear-xz", "shear-zx", "shear-yz", "shear-zy"]
    )
    shear_xz = basic3d(1.0)[5]
    assert shear_xz.constraints[0].part == "z0" and shear_xz.tractions[0].part == "z1"
    assert shear_xz.tractions[0].vector == (1.0, 0.0, 0.0)


def test_classify_nodes():
    pts = box_points([0, 0], [1, 1], 3)
    cls = classify_nodes(pts, (np.zeros(2), np.ones(2)))
    assert sorted(np.bincount(cls)) == [1, 4, 4]
    assert cls[4] == 0 and cls[0] == 2 and cls[1] == 1


def test_isotropic_matrices():
    E, nu = 3.0, 0.27
    C = np.linalg.inv(isotropic_compliance(E, nu))
    lam, mu = lame(E, nu)
    assert (
        np.isclose(C[0, 0], lam + 2 * mu) and np.isclose(C[0, 1], lam) and np.isclose(C[5, 5], mu)
    )
    Cs = plane(C, "stress")
    assert np.allclose(
        Cs, E / (1 - nu**2) * np.array([[1, nu, 0], [nu, 1, 0], [0, 0, (1 - nu) / 2]])
    )
    assert np.allclose(
        plane(C, "strain"), [[lam + 2 * mu, lam, 0], [lam, lam + 2 * mu, 0], [0, 0, mu]]
    )


def test_transverse_isotropy_rotation():
    S = transversely_isotropic_compliance(10.0, 2.0, 0.3, 0.4, 1.5)
    C = np.linalg.inv(S)
    d = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
    Cg = rotate(C, d[None])[0]
    # uniaxial stress along the fibre: strain along it is sigma/E_L, across -nu_LT sigma/E_L
    sigma = 2.0 * np.outer(d, d)
    voigt = np.array([sigma[0, 0], sigma[1, 1], sigma[2, 2], sigma[1, 2], sigma[0, 2], sigma[0, 1]])
    eps = np.linalg.solve(Cg, voigt)
    E3 = np.array(
        [
            [eps[0], eps[5] / 2, eps[4] / 2],
            [eps[5] / 2, eps[1], eps[3] / 2],
            [eps[4] / 2, eps[3] / 2, eps[2]],
        ]
    )
    assert np.isclose(d @ E3 @ d, 2.0 / 10.0)
    t = np.cross(d, [0, 0, 1.0])
    t /= np.linalg.norm(t)
    assert np.isclose(t @ E3 @ t, -0.3 * 2.0 / 10.0)
    # rotating about the fibre changes nothing: frames differ only by that rotation
    assert np.allclose(rotate(C, np.array([d, d]))[1], Cg)
