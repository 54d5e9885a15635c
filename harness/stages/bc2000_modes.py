"""Held-out natural frequencies of the bc2000 ``fem`` stage: the first modes of each
linearised model (lumped masses rho V) against the FEM reference's ``frequencies()``,
both with the constraints of harness.case.loads.modal_load (the B&C cases: the held-out
``sag``, x0 clamped). No fit uses the modes,
so they show whether constants calibrated on static loads also give the body's dynamics:
``freq_error_heldout`` (fitted constants), ``freq_error_heldout_initial`` (the scaled
ones), RMS relative error as in the sms stage, and ``f1_ratio``."""

from __future__ import annotations

import math

import numpy as np

from harness.case.loads import modal_load
from harness.mechanics.modal import matrix_frequencies


def rms_error(f, f_fem) -> float:
    """RMS relative error of frequencies f against the FEM's (same count)."""
    rel = np.asarray(f, float) / np.asarray(f_fem, float) - 1.0
    return float(np.sqrt(np.mean(rel ** 2))) if len(rel) and np.all(np.isfinite(rel)) else math.nan


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
    f0, f1 = (matrix_frequencies(sum(t * K for t, K in zip(theta, Ks)), masses, free, len(f_fem))
              for theta in (theta_initial, theta_final))
    return {"freq_error_heldout_initial": rms_error(f0, f_fem), "freq_error_heldout": rms_error(f1, f_fem),
            "f1_ratio": float(f1[0] / f_fem[0])}
