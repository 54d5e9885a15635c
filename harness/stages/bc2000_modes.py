"""Held-out natural frequencies of the bc2000 ``fem`` stage: the first modes of each
linearised model (lumped masses rho V) against the FEM reference's ``frequencies()``,
both with the constraints of harness.case.loads.modal_load (the B&C cases: the held-out
``sag``, x0 clamped). No fit uses the modes,
so they show whether constants calibrated on static loads also give the body's dynamics:
``freq_error_heldout`` (fitted constants), ``freq_error_heldout_initial`` (the scaled
ones), RMS relative error as in the sms stage, ``f1_ratio``, and ``modes_unstable``: how
many of the fitted model's first modes do not oscillate steadily (eigenvalue of M^-1 K
non-real or <= 0; the element model is not conservative, so its K is not symmetric and
that can happen; frequency Re sqrt(lambda) / 2 pi, 0 for lambda <= 0)."""

from __future__ import annotations

import math

import numpy as np

from harness.case.loads import modal_load
from harness.mechanics.modal import matrix_eigenvalues


def rms_error(f, f_fem) -> float:
    """RMS relative error of frequencies f against the FEM's (same count)."""
    rel = np.asarray(f, float) / np.asarray(f_fem, float) - 1.0
    return float(np.sqrt(np.mean(rel**2))) if len(rel) and np.all(np.isfinite(rel)) else math.nan


def heldout_modes(ref, case, masses, loads, Ks, theta_initial, theta_final) -> dict:
    """The columns of one model with stiffness sum_i theta_i Ks[i]: ``loads``
    (harness.stages.bc2000_linear.Loads) gives the free dofs of the modes' load;
    ``masses`` (n,) are the stage's lumped element masses (rho V shared by the vertices)."""
    n = case.reference.modes
    if not n:
        return {}
    first = modal_load(case).name
    f_fem = np.asarray(ref.frequencies(n, load=first), float)
    free = loads.free[loads.names.index(first)]
    lam0, lam1 = (
        matrix_eigenvalues(sum(t * K for t, K in zip(theta, Ks)), masses, free, len(f_fem))
        for theta in (theta_initial, theta_final)
    )
    f0, f1 = (np.sqrt(lam.astype(complex)).real / (2 * np.pi) for lam in (lam0, lam1))
    lam1 = lam1.astype(complex)
    unstable = int(np.sum((lam1.real <= 0) | (np.abs(lam1.imag) > 1e-8 * np.abs(lam1))))
    return {
        "freq_error_heldout_initial": rms_error(f0, f_fem),
        "freq_error_heldout": rms_error(f1, f_fem),
        "f1_ratio": float(f1[0] / f_fem[0]),
        "modes_unstable": unstable,
    }
