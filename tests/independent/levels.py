"""Levels and Richardson extrapolation of the quarter shear: the observed order and the
extrapolant of the last three levels."""

from __future__ import annotations

import numpy as np

from .box import evaluate_grid
from .quarter import mirror_points, mirror_signs, quarter_shear_field


def shear_levels(
    size,
    E,
    nu,
    s,
    points,
    levels,
    beta: float = 2.5,
    knot: float | None = None,
    status=None,
    long_axes: bool = False,
):
    """[(n, u (m, 3), n_dofs, seconds, CG iterations)] of the quarter shear at each level."""
    import time

    out = []
    for n in levels:
        t0 = time.perf_counter()
        verts, U, prob = quarter_shear_field(size, E, nu, s, n, beta, knot, long_axes)
        q, flip = mirror_points(np.asarray(points, float), size)
        u = mirror_signs(evaluate_grid(verts, U, q), flip)
        out.append((n, u, prob.n_dofs, time.perf_counter() - t0, prob.iterations))
        if status:
            status(out[-1])
    return out


def extrapolated_shear(
    size,
    E,
    nu,
    s,
    points,
    levels=(6, 8, 10),
    beta: float = 2.5,
    knot: float | None = None,
    long_axes: bool = False,
):
    """(extrapolated u (m, 3), its estimate (largest change of the extrapolant between the
    last two pairs of levels, relative to max |u|), the observed order). ``knot`` (e.g.
    0.75, every n a multiple of 4): the thirds of the sides are nodes of every level, so
    the convergence is regular (without it the points move within their cells and the
    order on the sec6 cube's 4 x 4 x 4 grid wanders between 1 and 4; with it, 2.56)."""
    vals = [
        u
        for _, u, *_ in shear_levels(
            size, E, nu, s, points, levels, beta, knot, long_axes=long_axes
        )
    ]
    return extrapolate_levels(vals, levels)


def extrapolate_levels(vals, levels):
    """(extrapolant of the last two levels, relative change from the previous pair's
    extrapolant (NaN with two levels), the order observed on the last three levels)."""
    h = [1.0 / n for n in levels]
    p = observed_order(vals[-3:], h[-3:]) if len(vals) >= 3 else 2.0
    ests = [_richardson(vals[i], vals[i + 1], h[i], h[i + 1], p) for i in range(len(vals) - 1)]
    scale = np.linalg.norm(ests[-1], axis=1).max()
    change = np.linalg.norm(ests[-1] - ests[-2], axis=1).max() / scale if len(ests) > 1 else np.nan
    return ests[-1], change, p


def observed_order(vals, h) -> float:
    """p with (h0^p - h1^p) / (h1^p - h2^p) = d1 / d2, d the largest pointwise differences
    of three levels (exact for u + C h^p with any level ratios)."""
    from scipy.optimize import brentq

    v0, v1, v2 = vals
    h0, h1, h2 = h
    target = np.abs(v1 - v0).max() / np.abs(v2 - v1).max()
    f = lambda p: (h0**p - h1**p) / (h1**p - h2**p) - target  # noqa: E731 - increasing in p
    return float(brentq(f, 0.1, 10.0))


def _richardson(coarse, fine, hc, hf, p):
    return fine + (fine - coarse) / ((hc / hf) ** p - 1.0)
