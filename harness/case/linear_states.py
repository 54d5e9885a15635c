"""The ``linear2d`` / ``linear3d`` load sets (docs/design.md, "Load sets for any shape"):
equilibrated linear stress fields sigma(x) = sigma0 + sum_k xi_k G[k] on the whole
boundary of any body, xi = (x - c) / L the coordinates of the body's Frame (centroid c,
size L), with minimal constraints at its anchor points. A state of magnitude s has
stresses of about s.

Equilibrium div sigma = 0 leaves 15 of the 18 gradient coefficients in 3-D (4 of 6 in
2-D); the basis, by family (``LoadCase.family``):

- ``constant``: the homogeneous states sxx, syy, [szz, syz, sxz,] sxy (loadsets.homogeneous).
- ``bending``: ``bend-ik``, sigma_ii = s xi_k (k != i): 6 in 3-D, 2 in 2-D.
- ``torsion`` (3-D): ``torsion-x``, ``torsion-y``, torsion about x (sigma_xy = -s xi_z,
  sigma_xz = s xi_y) and about y (sigma_yz = -s xi_x, sigma_xy = s xi_z); the torsion
  about z is minus their sum (the three have rank 2), so the third state is the
  symmetric ``torsion-sym``, sigma_yz = s xi_x, sigma_xz = s xi_y, sigma_xy = s xi_z
  (orthogonal to the three torsions in the coefficients).
- ``shear-gradient``: ``sgrad-ij``, sigma_ii = s xi_i, sigma_ij = -s xi_j (j != i): 6, 2.
- ``gravity``: ``gravity-a``, sigma_aa = s xi_a with the body force b = -(s / L) e_a
  (a force per volume, so it does not depend on the density): div sigma + b = 0.

Linear strain is compatible, so every state's exact displacement is quadratic
(:func:`linear_closed_form`).
"""

from __future__ import annotations

import numpy as np

from harness.case.loadsets import (
    AXES,
    VOIGT,
    Frame,
    LoadCase,
    _box_stress,
    homogeneous,
    minimal_constraints,
    stress_tensor,
)


def _voigt_index(dim: int, i: int, j: int) -> int:
    return VOIGT[dim].index((min(i, j), max(i, j)))


def gradient_states(dim: int) -> list[tuple[str, str, np.ndarray]]:
    """(name, family, G (dim, nv)) of the unit linear states, G[k] = d sigma / d xi_k;
    the gravity states' G is not divergence free (their body force balances it)."""
    nv = len(VOIGT[dim])
    out = []

    def state(name, fam, *terms):  # terms: (i, j, k, coefficient): sigma_ij += c xi_k
        G = np.zeros((dim, nv))
        for i, j, k, c in terms:
            G[k, _voigt_index(dim, i, j)] += c
        out.append((name, fam, G))

    for i in range(dim):
        for k in range(dim):
            if k != i:
                state(f"bend-{AXES[i]}{AXES[k]}", "bending", (i, i, k, 1.0))
    if dim == 3:
        for a in (0, 1):
            b, c = (a + 1) % 3, (a + 2) % 3
            state(f"torsion-{AXES[a]}", "torsion", (a, b, c, -1.0), (a, c, b, 1.0))
        state("torsion-sym", "torsion", (1, 2, 0, 1.0), (0, 2, 1, 1.0), (0, 1, 2, 1.0))
    for i in range(dim):
        for j in range(dim):
            if j != i:
                state(
                    f"sgrad-{AXES[i]}{AXES[j]}", "shear-gradient", (i, i, i, 1.0), (i, j, j, -1.0)
                )
    for a in range(dim):
        state(f"gravity-{AXES[a]}", "gravity", (a, a, a, 1.0))
    return out


def divergence(G, size: float) -> np.ndarray:
    """div sigma (dim,) of the linear field with gradient G (dim, nv) in xi = x / size."""
    G = np.asarray(G, float)
    dim = G.shape[0]
    return (
        np.array([sum(G[j, _voigt_index(dim, i, j)] for j in range(dim)) for i in range(dim)])
        / size
    )


def linear_states(dim: int, s: float, anchors, frame: Frame) -> tuple[LoadCase, ...]:
    """The set: the constant states, then the bending, torsion, shear-gradient and
    gravity states of magnitude s, each on the whole boundary with minimal constraints
    at ``anchors`` (module docstring)."""
    if anchors is None or frame is None:
        raise ValueError("the linear states need the body's anchor points and frame")
    cons = minimal_constraints(anchors)
    out = list(homogeneous(dim, s, anchors))
    zero = (0.0,) * len(VOIGT[dim])
    for name, fam, G in gradient_states(dim):
        b = -divergence(s * G, frame.size)
        out.append(
            LoadCase(
                name,
                cons,
                stress=zero,
                stress_gradient=tuple(map(tuple, (s * G).tolist())),
                frame=frame,
                family=fam,
                body_force=tuple((b + 0.0).tolist()) if np.any(b) else None,
            )
        )
    return tuple(out)


def _tensor_strain(voigt_strain: np.ndarray) -> np.ndarray:
    """Engineering-shear Voigt strain (..., nv) -> tensor strain (..., dim, dim)."""
    dim = 2 if voigt_strain.shape[-1] == 3 else 3
    half = np.array([1.0 if i == j else 0.5 for i, j in VOIGT[dim]])
    return stress_tensor(voigt_strain * half)


def linear_closed_form(load: LoadCase, points, compliance, anchors) -> np.ndarray:
    """u (n, dim) of a homogeneous or linear stress load on a homogeneous body with
    Voigt compliance S. With r = x - c (c the frame's centroid; 0 for a constant
    stress), eps(x) = eps0 + e_ijk r_k, e_ijk = d eps_ij / d x_k (tensor strain):
    u_i = eps0_ij r_j + 1/2 D_ijk r_j r_k, D_ijk = e_ijk + e_ikj - e_jki (its symmetric
    gradient is eps), plus the rigid motion the load's constraints at ``anchors`` (one
    point per constraint) select."""
    points = np.asarray(points, float)
    dim = points.shape[1]
    S = np.asarray(compliance, float)
    voigt = load.stress if load.stress is not None else _box_stress(load, dim)
    eps0 = _tensor_strain(S @ np.asarray(voigt, float))
    if load.stress_gradient is not None:
        c, L = np.asarray(load.frame.centroid, float), load.frame.size
        # e[i, j, k]
        e = _tensor_strain(np.asarray(load.stress_gradient, float) @ S.T / L).transpose(1, 2, 0)
        D = e + e.transpose(0, 2, 1) - e.transpose(2, 0, 1)
    else:
        c, D = np.zeros(dim), np.zeros((dim, dim, dim))

    def field(x):
        r = np.atleast_2d(x) - c
        return r @ eps0.T + 0.5 * np.einsum("ijk,nj,nk->ni", D, r, r)

    # rigid motion a + w x x (2-D: a + w (-y, x)): one equation per constrained component
    def rigid(x):
        if dim == 2:
            return np.hstack([np.eye(2), [[-x[1]], [x[0]]]])
        return np.hstack([np.eye(3), [[0, x[2], -x[1]], [-x[2], 0, x[0]], [x[1], -x[0], 0]]])

    rows, rhs = [], []
    for con, x in zip(load.constraints, np.asarray(anchors, float)):
        R, u = rigid(x), field(x)[0]
        for comp in con.components:
            rows.append(R[comp])
            rhs.append(-u[comp])
    coef = np.linalg.solve(np.array(rows), np.array(rhs))
    a, w = coef[:dim], coef[dim:]
    spin = (
        np.cross(w, points) if dim == 3 else w[0] * np.stack([-points[:, 1], points[:, 0]], axis=1)
    )
    return field(points) + a + spin


def linear2d(s: float, anchors, frame: Frame) -> tuple[LoadCase, ...]:
    """The load set "linear2d": the 2-D homogeneous and equilibrated linear stress states."""
    return linear_states(2, s, anchors, frame)


def linear3d(s: float, anchors, frame: Frame) -> tuple[LoadCase, ...]:
    """The load set "linear3d": the 3-D homogeneous and equilibrated linear stress states."""
    return linear_states(3, s, anchors, frame)
