"""Central-difference checks shared by the model tests (an independent route to a
stiffness: only the force rule is evaluated)."""

from __future__ import annotations

import numpy as np


def force_jacobian(forces, pts: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """-d forces / d x (n*dim, n*dim) at pts (n, dim) by central differences: the linear
    stiffness a force rule implies."""
    J = np.zeros((pts.size, pts.size))
    for j in range(pts.size):
        xp, xm = pts.copy().ravel(), pts.copy().ravel()
        xp[j] += h
        xm[j] -= h
        J[:, j] = -(forces(xp.reshape(pts.shape)) - forces(xm.reshape(pts.shape))).ravel() / (2 * h)
    return J


def energy_forces(energy, x: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """-d energy / d x (n*dim,) at x (n, dim) by central differences: the forces an energy
    implies."""
    fd = np.zeros(x.size)
    for j in range(x.size):
        xp, xm = x.copy().ravel(), x.copy().ravel()
        xp[j] += h
        xm[j] -= h
        fd[j] = -(energy(xp.reshape(x.shape)) - energy(xm.reshape(x.shape))) / (2 * h)
    return fd
