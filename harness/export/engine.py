"""What an explicit engine needs besides the spring constants: per-spring damping and the
stable time step, from plain arrays (points, springs, k, masses; SI units).

- ``spring_damping``: kd_e = 2 zeta sqrt(k_e mu_e), mu_e = m_i m_j / (m_i + m_j) the
  reduced mass of the spring's two particles: each spring, alone between its two masses,
  is damped at the ratio zeta of its critical value (f_d = kd (v_j - v_i) . d along the
  spring, NVIDIA Newton's ``add_spring(i, j, ke, kd, control)`` ``kd``).
- ``stable_step``: the largest step of symplectic (semi-implicit) Euler / Verlet for the
  free, linearised network: with omega_max^2 the largest eigenvalue of M^-1 K and zeta_top
  the damping ratio of that mode (Rayleigh quotient of the damping matrix
  C = B diag(kd) B^T), a damped oscillator is stable for
  dt < 2 / omega_max (sqrt(1 + zeta_top^2) - zeta_top). ``FLOAT32_MARGIN`` keeps a float32
  engine (rounded forces, and stiffening of the loaded geometry) clear of the limit.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from harness.errors import ModelError
from harness.models.springs import incidence, stiffness_matrix

FLOAT32_MARGIN = 0.9


def spring_damping(
    springs: np.ndarray, k: np.ndarray, masses: np.ndarray, zeta: float
) -> np.ndarray:
    """Per-spring damping coefficients kd (N s/m) at damping ratio zeta."""
    springs = np.asarray(springs, int)
    m = np.asarray(masses, float)
    mi, mj = m[springs[:, 0]], m[springs[:, 1]]
    if np.any(mi <= 0) or np.any(mj <= 0):
        raise ModelError(
            "spring damping needs positive masses", field="masses", fix="use --masses lumped"
        )
    mu = mi * mj / (mi + mj)
    return 2.0 * zeta * np.sqrt(np.asarray(k, float) * mu)


def stable_step(points, springs, k, masses, kd=None, volume=None) -> dict:
    """{"omega_max" (rad/s), "zeta_top", "dt_stable" (s), "dt_stable_float32" (s)} of the
    free network (no constraints: the largest eigenvalue is a local, high mode); ``volume``:
    a springs + volume model's VolumeTerm (harness/models/volume.py) or a springs+kn model's
    KNTerm (harness/models/kn.py), undamped, adds to K (a non-symmetric term by its symmetric
    part)."""
    points = np.asarray(points, float)
    m = np.repeat(np.asarray(masses, float), points.shape[1])
    if np.any(m <= 0):
        raise ModelError(
            "the stable step needs positive masses", field="masses", fix="use --masses lumped"
        )
    B = incidence(points, springs)
    s = sp.diags(1.0 / np.sqrt(m))
    K = stiffness_matrix(B, k)
    if volume is not None:
        K = K + volume.stiffness_matrix(points)
        if not getattr(volume, "symmetric", True):  # B&C's elements (harness/models/mt.py): the
            K = 0.5 * (K + K.T)  # symmetric part, as mechanics.dynamics.stable_step
    A = (s @ K @ s).tocsr()
    if A.shape[0] <= 300:
        lam, vec = np.linalg.eigh(A.toarray())
        lam, v = lam[-1], vec[:, -1]
    else:
        # seeded start
        lam, vec = spla.eigsh(
            A, k=1, which="LA", tol=1e-8, v0=np.random.default_rng(0).standard_normal(A.shape[0])
        )
        lam, v = lam[0], vec[:, 0]
    omega = float(np.sqrt(max(lam, 0.0)))
    zeta = 0.0
    if kd is not None and omega > 0:
        C = s @ stiffness_matrix(B, kd) @ s
        zeta = float(v @ (C @ v)) / (2.0 * omega * float(v @ v))
    dt = 2.0 / omega * (np.sqrt(1.0 + zeta**2) - zeta) if omega > 0 else float("inf")
    return {
        "omega_max": omega,
        "zeta_top": zeta,
        "dt_stable": float(dt),
        "dt_stable_float32": FLOAT32_MARGIN * float(dt),
    }
