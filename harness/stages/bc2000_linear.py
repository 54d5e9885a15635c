"""Linear statics of the Bourguignon-Cani models (MS, MT0, MT) under a case's load cases,
their G score against the FEM reference, stiffness calibration against it, and the
undesired-anisotropy measure.

Linearised at the rest shape, every model's stiffness is linear in its constants:
K(theta) = sum_j theta_j K_j with theta = (ks1..ks6, kvs) (MT0 without kvs) or (ks,) (MS),
each K_j the complex-step Jacobian of the model with that one constant set to 1. The fit
minimises G^2 over log theta (scipy.optimize.least_squares).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.optimize import least_squares

from harness.errors import ModelError
from harness.mechanics import statics
from harness.mechanics.dynamics import stiffness
from harness.models.massspring import MassSpring


def parameter_names(model) -> list[str]:
    if isinstance(model, MassSpring):
        return ["ks"]
    return ["ks1", "ks2", "ks3", "ks4", "ks5", "ks6"] + (["kvs"] if model.volume else [])


def unit_stiffnesses(model) -> list[sp.csr_matrix]:
    """K_j of each constant (the linearised stiffness with only that constant = 1)."""
    out = []
    if isinstance(model, MassSpring):
        m = replace(model, ks=np.ones_like(model.ks), kd=np.zeros_like(model.kd))
        return [m.stiffness_matrix()]
    zero = np.zeros_like(model.ks)
    for j in range(6):
        ks = zero.copy()
        ks[:, j] = 1.0
        out.append(stiffness(replace(model, ks=ks, kvs=np.zeros_like(model.kvs), kd=0 * model.kd)))
    if model.volume:
        out.append(stiffness(replace(model, ks=zero, kvs=np.ones_like(model.kvs), kd=0 * model.kd)))
    return out


def current_parameters(model) -> np.ndarray:
    if isinstance(model, MassSpring):
        return np.array([float(np.mean(model.ks))])
    p = list(model.ks.mean(axis=0))
    return np.array(p + ([float(model.kvs.mean())] if model.volume else []))


@dataclass(frozen=True)
class Loads:
    """Per load case: names, free dof masks (L, 3n), forces (L, 3n)."""

    names: list
    free: np.ndarray
    forces: np.ndarray


class _Net:  # what harness.mechanics.statics.load_arrays needs
    def __init__(self, points, masses):
        self.points, self.masses = points, masses


def case_loads(points, case, masses=None) -> Loads:
    net = _Net(points, np.ones(len(points)) if masses is None else masses)
    names, free, forces = statics.all_load_arrays(net, case)
    return Loads(names, free, forces)


def zero_modes(K, loads: Loads, rtol: float = 1e-9, limit: int = 3000) -> int:
    """Largest number of zero-energy modes (singular values below rtol * the largest) of
    the constrained stiffness over the load cases; dense SVD, so only for <= limit dofs
    (-1 if larger)."""
    worst = 0
    for i in range(len(loads.names)):
        fr = loads.free[i]
        if fr.sum() > limit:
            return -1
        sv = np.linalg.svd(K.tocsr()[fr][:, fr].toarray(), compute_uv=False)
        worst = max(worst, int(np.sum(sv < rtol * sv[0])))
    return worst


def solve(K, loads: Loads) -> np.ndarray:
    """Displacements (L, n, 3) of K u = f on the free dofs of each load."""
    out = np.zeros(loads.forces.shape)
    for i in range(len(loads.names)):
        fr = loads.free[i]
        A = K.tocsr()[fr][:, fr].tocsc()
        try:
            lu = spla.splu(A)
            u = lu.solve(loads.forces[i][fr])
        except RuntimeError:
            u = np.full(fr.sum(), np.nan)
        if not np.all(np.isfinite(u)):
            raise ModelError(
                f"load '{loads.names[i]}': the linearised model is singular (a mechanism)",
                fix="hold more nodes, or use nonzero angular/volume stiffness",
            )
        out[i][fr] = u
    return out.reshape(len(loads.names), -1, 3)


def fit(Ks, theta0, u_ref, loads: Loads, weights) -> tuple[np.ndarray, float, float]:
    """Constants minimising G^2 = sum w_p |u_ref - u(theta)|^2 (least squares in log theta).
    Returns (theta, G before, G after)."""
    w = np.sqrt(np.repeat(weights, 3))

    def resid(logt):
        K = sum(t * Kj for t, Kj in zip(np.exp(logt), Ks))
        u = solve(K, loads)
        return ((u_ref - u).reshape(len(u), -1) * w).ravel()

    x0 = np.log(np.maximum(theta0, 1e-12 * max(theta0.max(), 1e-300)))
    r0 = resid(x0)
    res = least_squares(resid, x0, method="trf", x_scale=1.0, max_nfev=200)
    return np.exp(res.x), float(np.linalg.norm(r0)), float(np.linalg.norm(res.fun))


def face_pull(points, K_of_direction, force: float = 1.0):
    """Undesired anisotropy: for each axis a and side, fix the face a = min (or max) and
    pull the opposite face's nodes outward with ``force`` each. The continuum answer is
    the same for the six pulls of a cube; a discrete model's spread is the anisotropy its
    mesh adds. ``K_of_direction(d)`` gives the model's stiffness for a pull along d (the
    element model takes its fibre along d). Rows: direction, stiffness (total force /
    mean pulled-face displacement along d), drift (|mean transverse| / mean along d)."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    tol = 1e-9 * (hi - lo).max()
    rows = []
    n = len(points)
    for a in range(3):
        for sign in (+1, -1):
            d = np.zeros(3)
            d[a] = sign
            held = np.abs(points[:, a] - (lo[a] if sign > 0 else hi[a])) < tol
            pulled = np.abs(points[:, a] - (hi[a] if sign > 0 else lo[a])) < tol
            free = np.repeat(~held, 3)
            f = np.zeros((n, 3))
            f[pulled] = force * d
            K = K_of_direction(d).tocsr()[free][:, free].tocsc()
            u = np.zeros(3 * n)
            u[free] = spla.spsolve(K, f.ravel()[free])
            u = u.reshape(n, 3)[pulled].mean(axis=0)
            along = float(u @ d)
            rows.append(
                {
                    "direction": ("+" if sign > 0 else "-") + "xyz"[a],
                    "stiffness": force * pulled.sum() / along,
                    "drift": float(np.linalg.norm(u - along * d)) / along,
                }
            )
    return rows
