"""The sec6 shear on a quarter of the box: its graded mesh, its symmetry conditions and the
mirror back to the whole box."""

from __future__ import annotations

import numpy as np

from .box import BoxProblem, evaluate_grid
from .q2 import face_load


def _half_axis(
    length: float, mirrored: bool, n: int, beta: float, knot=None, reach=None
) -> np.ndarray:
    """Nodes on [0, length]: n cells graded (power beta) towards 0 over the end zone
    (all of it, or with ``mirrored`` its first half, mirrored onto the second). ``knot`` =
    (s_k, x_k): the end zone's parameter s in [0, s_k] maps to [0, x_k] (x = x_k
    (s / s_k)^beta), [s_k, 1] uniformly to the rest, so x_k is a node of every level with
    n s_k an integer (a scored point there keeps its place in the mesh: a smooth error
    expansion in 1/n, which Richardson extrapolation needs). ``reach`` < x_k: ``_long_axis``."""
    w = length / 2 if mirrored else length
    if knot is not None and reach is not None and knot[1] > reach * (1 + 1e-9):
        return _long_axis(length, mirrored, n, beta, knot, reach)
    s = np.linspace(0.0, 1.0, n + 1)
    if knot is None:
        x = w * s**beta
    else:
        sk, xk = knot
        if abs(n * sk - round(n * sk)) > 1e-9:
            raise ValueError(f"n = {n}: n * {sk} must be an integer to put the knot on a node")
        x = np.where(
            s <= sk, xk * (np.minimum(s, sk) / sk) ** beta, xk + (w - xk) * (s - sk) / (1 - sk)
        )
    return np.concatenate([x, length - x[::-1][1:]]) if mirrored else x


def _long_axis(length, mirrored, n, beta, knot, reach):
    """s in [0, s_k] -> [0, reach] by the power law, [s_k, s_k + 1/2] exponentially (slope
    continuous) to x_k, [s_k + 1/2, 3/2] uniformly to the rest: n / 2 more cells."""
    from scipy.optimize import brentq

    w = length / 2 if mirrored else length
    sk, xk = knot
    if abs(n * sk - round(n * sk)) > 1e-9 or n % 4:
        raise ValueError(
            f"n = {n}: n * {sk} and n / 4 must be integers (knot and segments on nodes)"
        )
    g, span = reach, 0.5  # slopes at s_k: beta g / s_k = (xk - g) k / ((e^k - 1) span)
    target = beta * g * span / (sk * (xk - g))
    k = (
        0.0
        if abs(target - 1) < 1e-12
        else brentq(lambda k: k / np.expm1(k) - target if k else 1 - target, -60, 60)
    )
    s = np.linspace(0.0, 1.0 + span, int(round(n * (1 + span))) + 1)
    t = np.clip((s - sk) / span, 0.0, 1.0)
    grow = g + (xk - g) * (np.expm1(k * t) / np.expm1(k) if k else t)
    x = np.where(
        s <= sk,
        g * (np.minimum(s, sk) / sk) ** beta,
        np.where(s <= sk + span, grow, xk + (w - xk) * (s - sk - span) / (1 - sk)),
    )
    x[-1] = w
    return np.concatenate([x, length - x[::-1][1:]]) if mirrored else x


def quarter_mesh(
    size, n: int, beta: float = 2.5, knot: float | None = None, long_axes: bool = False
):
    """Vertices of the quarter's tensor mesh: n cells per graded half-axis in x and y
    (graded towards the faces x = 0, y = 0 only: the symmetry planes are smooth), 2 n in z.
    ``knot`` = s_k: the points a third of each side from a face (the 4 x 4 x 4 grid) are the
    nodes s = s_k of their graded end zones (needs n s_k integer). ``long_axes``: an axis
    longer than the shortest side gets the shortest's power zone and a stretch to its own
    third (``_long_axis``). Without it a 10:1 box's end-face cells are 2.5x coarser: at the
    loaded end edges order 2.19-2.28, extrapolant (n = 16, 20, 24) 6e-5 of max |u| off; with
    it (nu 0.49) orders 2.62, 2.60, 2.59 on the triples of n = 12..28, within 4.8e-6."""
    a, b, c = size
    reach = min(size) / 3 if long_axes else None
    k = (lambda L: (knot, L / 3)) if knot is not None else (lambda L: None)
    return [
        _half_axis(a / 2, False, n, beta, k(a), reach),
        _half_axis(b / 2, False, n, beta, k(b), reach),
        _half_axis(c, True, n, beta, k(c), reach),
    ]


QUARTER_FIXED = {0: [(2, 0)], 1: [(2, 0), (1, 1), (0, 1)], 2: [(2, 0), (0, 1)]}


def quarter_dofs(n: int) -> int:
    return 3 * (2 * n + 1) ** 2 * (4 * n + 1)


def quarter_shear_field(
    size,
    E,
    nu,
    s,
    n,
    beta: float = 2.5,
    knot: float | None = None,
    long_axes: bool = False,
    **solve_kw,
):
    """(vertices, U (3, nx, ny, nz), problem) of the quarter shear at n."""
    verts = quarter_mesh(size, n, beta, knot, long_axes)
    prob = BoxProblem(verts, E, nu, QUARTER_FIXED)
    F = face_load(verts, 2, 1, [s, 0.0, 0.0])
    return verts, prob.solve(F, **solve_kw), prob


def quarter_shear(
    size,
    E: float,
    nu: float,
    s: float,
    n: int,
    points,
    beta: float = 2.5,
    knot: float | None = None,
    **solve_kw,
) -> np.ndarray:
    """u (m, 3) at points (m, 3) of the full box [0, a] x [0, b] x [0, c] (mirrored into
    the quarter), Q2 hexahedra, n cells per graded half-axis in x and y, 2 n in z."""
    verts, U, _ = quarter_shear_field(size, E, nu, s, n, beta, knot, **solve_kw)
    q, flip = mirror_points(np.asarray(points, float), size)
    return mirror_signs(evaluate_grid(verts, U, q), flip)


def mirror_points(points, size):
    a, b, _ = size
    q = points.copy()
    sx, sy = q[:, 0] > a / 2, q[:, 1] > b / 2
    q[sx, 0] = a - q[sx, 0]
    q[sy, 1] = b - q[sy, 1]
    return q, (sx, sy)


def mirror_signs(vals, flip):
    sx, sy = flip
    vals = vals.copy()
    vals[sy, 1] *= -1
    vals[sx, 1:] *= -1
    return vals
