"""Closed-form solutions the reference is checked against.

- ``stretch_closed_form``: the standard stretches of a homogeneous isotropic box (plane
  stress in 2-D), from harness.case.loadsets.
- ``uniform_stress_displacement``: any homogeneous anisotropic body under a uniform
  uniaxial stress s along axis a, with the standard stretch constraints: strain
  e = S sigma (engineering shears) and the rigid rotation that the rollers and the
  pinned corners select, u = L (x - x0) with L lower triangular.
- ``cantilever_frequency``: Euler-Bernoulli clamped-free bending frequencies.
"""

from __future__ import annotations

import numpy as np

from harness.case.loadsets import stretch_closed_form  # noqa: F401  (re-exported)

VOIGT_2D = [(0, 0), (1, 1), (0, 1)]
VOIGT_3D = [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)]
EB_ROOTS = np.array([1.8751040687, 4.6940911330, 7.8547574382, 10.9955407349])


def uniform_stress_displacement(S: np.ndarray, s: float, axis: int, points, origin) -> np.ndarray:
    """u (n, dim) of a uniform stress s along ``axis`` for the Voigt compliance S
    (3x3 in 2-D, 6x6 in 3-D), with u_axis = 0 on the min face and rotations fixed as in
    the standard stretches (the basic2d/basic3d stretch-x)."""
    points = np.asarray(points, float)
    dim = points.shape[1]
    pairs = VOIGT_2D if dim == 2 else VOIGT_3D
    sigma = np.zeros(len(pairs))
    sigma[pairs.index((axis, axis))] = s
    e = S @ sigma
    L = np.zeros((dim, dim))
    for I, (i, j) in enumerate(pairs):
        if i == j:
            L[i, i] = e[I]
        elif i == 0:  # u_x = e_xx x exactly (rollers), so shears with x go to the other component
            L[j, 0] = e[I]
        else:  # the corner (x0, y1, z0) fixed in z: gamma_yz goes to u_y
            L[i, j] = e[I]
    if axis != 0:  # the standard stretch along another axis pins the rotations differently
        raise NotImplementedError("only the x stretch is tabulated")
    return (points - np.asarray(origin, float)) @ L.T


def cantilever_frequency(
    E: float, rho: float, length: float, I: float, A: float, mode: int = 0
) -> float:
    """Euler-Bernoulli natural frequency (Hz) of a clamped-free beam."""
    return EB_ROOTS[mode] ** 2 / (2 * np.pi * length**2) * np.sqrt(E * I / (rho * A))
