"""Richardson extrapolation over mesh levels, and the error estimate it implies.

Level k has mesh parameter h_k = 1 / n_k (n_k cells per graded end zone, see
reference/graded.py) and point values V_k. If V_k = u + C h_k^p + ..., two levels give
the extrapolant E = V_f + (V_f - V_c) / ((h_c / h_f)^p - 1). The order p is observed:
fitted to the largest differences of three consecutive levels over a probe set. The
estimate of the extrapolated field's error at a point is the difference of the last two
extrapolants there (E from levels k-1, k against E from k-2, k-1), which over-estimates
the error of the newer one while the levels are in the asymptotic range.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq

ORDER_RANGE = (1.0, 5.0)   # observed orders outside this are clipped (noise, pre-asymptotic)
SAFETY = 3.0               # Roache's factor of safety for an error estimated from two solutions (the
# two extrapolants); the grid convergence index GCI = SAFETY |E_new - E_old| / (r^p - 1)


def richardson(coarse: np.ndarray, fine: np.ndarray, h_coarse: float, h_fine: float, p: float) -> np.ndarray:
    """The extrapolant of two levels' values for order p."""
    return fine + (fine - coarse) / ((h_coarse / h_fine) ** p - 1.0)


def observed_order(values, h) -> float:
    """Order p with (h0^p - h1^p) / (h1^p - h2^p) = |V1 - V0| / |V2 - V1| (largest
    differences over all points and components), clipped to ORDER_RANGE. NaN when the
    last two levels agree to rounding (nothing left to extrapolate)."""
    v0, v1, v2 = (np.asarray(v, float) for v in values)
    h0, h1, h2 = h
    d1, d2 = np.abs(v1 - v0).max(), np.abs(v2 - v1).max()
    scale = max(np.abs(v2).max(), 1e-300)
    if d2 <= 1e-12 * scale or d1 <= 1e-12 * scale:
        return float("nan")
    target = d1 / d2
    f = lambda p: (h0 ** p - h1 ** p) / (h1 ** p - h2 ** p) - target   # noqa: E731 - increasing in p
    lo, hi = ORDER_RANGE
    if f(lo) >= 0:
        return lo
    if f(hi) <= 0:
        return hi
    return float(brentq(f, lo, hi, xtol=1e-6))


def extrapolate(values, h, p: float):
    """(field, estimate) from the values of the last levels (oldest first) at some points.

    Two or more levels and a finite p: the extrapolant of the last two, and as estimate
    the pointwise norm of its difference from the previous extrapolant times
    SAFETY / ((h_old / h_new)^p - 1), at least the correction to the finest level (needs
    three levels; with two, the plain difference of the levels). Without a usable p (the
    levels agree to rounding: an exactly represented solution) the finest values with
    the plain difference as estimate."""
    values = [np.asarray(v, float) for v in values]
    fine = values[-1]
    if len(values) < 2:
        return fine, np.full(fine.shape[:-1] if fine.ndim > 1 else fine.shape, np.nan)
    plain = _norm(values[-1] - values[-2])
    if not np.isfinite(p):
        return fine, plain
    e_new = richardson(values[-2], values[-1], h[-2], h[-1], p)
    if len(values) < 3:
        return e_new, plain
    e_old = richardson(values[-3], values[-2], h[-3], h[-2], p)
    # E_new - E_old ~ D (h_old^q - h_new^q) for the next order q > p, so the error of E_new,
    # D h_new^q, is about the difference / ((h_old / h_new)^p - 1); SAFETY covers the rest
    # (a misfit p, two terms that cancel in the difference but not in the error)
    gci = SAFETY * _norm(e_new - e_old) / ((h[-2] / h[-1]) ** p - 1.0)
    # where the two extrapolants happen to agree, the correction the extrapolation made to
    # the finest level there (that level's estimated error) stands in
    return e_new, np.maximum(gci, _norm(e_new - fine))


def _norm(d: np.ndarray) -> np.ndarray:
    return np.linalg.norm(d, axis=-1) if d.ndim > 1 else np.abs(d)
