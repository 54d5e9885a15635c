"""Richardson extrapolation over mesh levels, and the error estimate it implies.

Level k has mesh parameter h_k = 1 / n_k (n_k cells per graded end zone, see
reference/graded/meshes.py) and point values V_k. If V_k = u + C h_k^p + ..., two levels give
the extrapolant E = V_f + (V_f - V_c) / ((h_c / h_f)^p - 1). The order p is observed:
the median of the orders three consecutive levels show at the probe points with the largest
differences. The
estimate of the extrapolated field's error at a point is the difference of the last two
extrapolants there (E from levels k-1, k against E from k-2, k-1), which over-estimates
the error of the newer one while the levels are in the asymptotic range.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq

ORDER_RANGE = (1.0, 5.0)  # observed orders outside this are clipped (noise, pre-asymptotic)
MAJOR = 0.1  # points whose order is observed: last difference >= MAJOR x the largest
FORMAL_ORDER = 3.0  # of Q2 point values (h^3); an observed order above it is pre-asymptotic
ASYMPTOTIC = 2.0  # a point converges at order p when its difference ratio is within this factor
SAFETY = 3.0  # Roache's factor of safety for an error estimated from two solutions (the
# two extrapolants); the grid convergence index GCI = SAFETY |E_new - E_old| / (r^p - 1)


def richardson(
    coarse: np.ndarray, fine: np.ndarray, h_coarse: float, h_fine: float, p: float
) -> np.ndarray:
    """The extrapolant of two levels' values for order p."""
    return fine + (fine - coarse) / ((h_coarse / h_fine) ** p - 1.0)


def observed_order(values, h) -> float:
    """Order p with (h0^p - h1^p) / (h1^p - h2^p) = |V1 - V0| / |V2 - V1|, solved at
    every point whose last difference is at least MAJOR of the largest (the points that
    decide the estimate), the median taken and clipped to ORDER_RANGE. A median, not the
    largest differences alone: one point in a pre-asymptotic spot (a window across the
    kink where a graded zone meets the middle) swung the order of the Sec. 6 cube between
    2.7 and 4.7 from level to level, while the median stays at 2.9-3.0. NaN when the
    last two levels agree to rounding (nothing left to extrapolate)."""
    v0, v1, v2 = (np.asarray(v, float).reshape(len(np.asarray(v)), -1) for v in values)
    h0, h1, h2 = h
    d1, d2 = np.abs(v1 - v0).max(axis=1), np.abs(v2 - v1).max(axis=1)
    scale = max(np.abs(v2).max(), 1e-300)
    if d2.max() <= 1e-12 * scale or d1.max() <= 1e-12 * scale:
        return float("nan")
    major = d2 >= MAJOR * d2.max()
    return float(np.median([_order(a / b, h0, h1, h2) for a, b in zip(d1[major], d2[major])]))


def _order(target: float, h0: float, h1: float, h2: float) -> float:
    f = lambda p: (h0**p - h1**p) / (h1**p - h2**p) - target  # noqa: E731 - increasing in p
    lo, hi = ORDER_RANGE
    if not np.isfinite(target) or f(lo) >= 0:
        return lo
    if f(hi) <= 0:
        return hi
    return float(brentq(f, lo, hi, xtol=1e-6))


def extrapolate(values, h, p: float):
    """(field, estimate) from the values of the last levels (oldest first) at some points.

    Two or more levels and a finite p: the extrapolant of the last two, and as estimate
    the pointwise norm of its difference from the previous extrapolant times
    SAFETY / ((h_old / h_new)^p - 1) (needs three levels; with two, the plain difference
    of the levels). The levels' values are averaged over a window of cells
    (reference/lattice.py), so the extrapolants converge smoothly and the GCI alone
    bounds the truth where a point's levels converge at order p. A floor at the correction
    made to the finest level (for points where the two extrapolants happen to agree) would
    hold the estimate at the finest level's own error (4.7e-4 where the truth is 7.6e-5,
    Sec. 6 cube, n = 8), so it applies only
    where they do not (its ratio of consecutive differences is off the expected one by
    more than ASYMPTOTIC, or oscillates). Without a usable p (the
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
    # where a point's own levels are not yet converging at order p (the ratio of its last
    # two differences off the expected one by more than ASYMPTOTIC, or of the other sign:
    # oscillatory), the GCI means nothing there: the correction made to the finest level
    # (about that level's own error) stands in
    d1, d2 = values[-2] - values[-3], values[-1] - values[-2]
    expect = (h[-2] ** p - h[-1] ** p) / (h[-3] ** p - h[-2] ** p)
    big = np.abs(d1) > 1e-12 * max(np.abs(fine).max(), 1e-300)
    ratio = np.divide(d2, d1, out=np.full(d1.shape, expect), where=big)
    off = (ratio < expect / ASYMPTOTIC) | (ratio > expect * ASYMPTOTIC)
    off = off.any(axis=-1) if off.ndim > 1 else off
    return e_new, np.where(off, np.maximum(gci, _norm(e_new - fine)), gci)


def _norm(d: np.ndarray) -> np.ndarray:
    return np.linalg.norm(d, axis=-1) if d.ndim > 1 else np.abs(d)
