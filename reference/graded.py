"""Graded tensor-product meshes of rectangles and boxes, refined in levels.

Elastic solutions on a box are singular along its edges (where a clamped or loaded face
meets a free one), and uniform P2 tetrahedra converge there only like h^1.1 at the
scored points. A tensor mesh whose nodes along each axis follow a power law
x = w (i / n)^beta towards both ends of the axis (the end zones, w = half the shortest
side) puts small cells along every face, edge and corner; the middle of a long axis gets
uniform cells as large as the largest graded one. Level k has ``n_k`` cells per end zone
(and the middle's cells scale with it): one family of meshes, uniformly refined in the
parameter s = i / n, which is what Richardson extrapolation over the levels needs.
"""

from __future__ import annotations

import numpy as np
import skfem

GRADE_EXPONENT = 3.0   # beta, and ZONE: the end zones' width / the shortest side. Measured on the
ZONE = 0.5             # sec6 cube's shear against an independent solve (tests/independent_elasticity.py)
MESHES = {2: skfem.MeshQuad, 3: skfem.MeshHex}


def axis_nodes(length: float, shortest: float, n: int, beta: float = GRADE_EXPONENT,
               zone: float = ZONE) -> np.ndarray:
    """Node coordinates in [0, length]: ``n`` power-graded cells in each end zone of
    width zone * min(length, shortest) (at most half the axis), uniform cells in between
    (an even number, as many as keep them no larger than the largest graded cell at n,
    proportional to n), so the axis is symmetric and its midpoint is a node."""
    if n < 1:
        raise ValueError("need at least one cell per end zone")
    w = min(zone * shortest, 0.5 * length)
    end = w * np.linspace(0.0, 1.0, n + 1) ** beta
    middle = length - 2 * w
    if middle <= 1e-12 * length:
        return np.concatenate([end, length - end[::-1][1:]])
    # largest graded cell ~ beta w / n (its limit for large n keeps the count proportional to n);
    # an even count puts a vertex on the mid-plane, where reference/symmetry.py cuts the box
    m = 2 * max(1, int(np.ceil(middle * n / (2 * beta * w) - 1e-9)))
    mid = w + middle * np.linspace(0.0, 1.0, m + 1)[1:-1]
    return np.concatenate([end, mid, length - end[::-1]])


def graded_axes(origin, size, n: int, beta: float = GRADE_EXPONENT, zone: float = ZONE) -> list:
    """The node coordinates along each axis of the graded mesh of [origin, origin + size]."""
    origin, size = np.asarray(origin, float), np.asarray(size, float)
    shortest = float(size.min())
    return [o + axis_nodes(s, shortest, n, beta, zone) for o, s in zip(origin, size)]


def tensor_mesh(axes) -> skfem.Mesh:
    return MESHES[len(axes)].init_tensor(*axes)


def graded_mesh(origin, size, n: int, beta: float = GRADE_EXPONENT, zone: float = ZONE) -> skfem.Mesh:
    """Quadrilateral (2-D) or hexahedral (3-D) tensor mesh of [origin, origin + size]
    graded towards every face, ``n`` cells per end zone."""
    return tensor_mesh(graded_axes(origin, size, n, beta, zone))


def probe_points(origin, size, per_axis: int = 9) -> np.ndarray:
    """A tensor grid of points (per_axis along every axis, faces, edges and corners
    included) on which the levels are compared to fit the order and decide when to stop."""
    origin, size = np.asarray(origin, float), np.asarray(size, float)
    axes = [o + np.linspace(0.0, s, per_axis) for o, s in zip(origin, size)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(size))


def level_divisions(first: int, levels: int) -> list[int]:
    """Cells per end zone of levels 0..levels: first, first + 1, ... (ratios near 1 keep
    the finest level affordable; extrapolation uses the true ratio n_k+1 / n_k)."""
    return [first + k for k in range(levels + 1)]
