"""Exact mass moments of bodies (int x^j y^k z^l rho dV, j + k + l <= 2) and the
simplex quadrature they use: polygons and boxes in closed form, meshes by a degree-2
quadrature on their simplices (quads and hexahedra split)."""

from __future__ import annotations

import numpy as np

EXPONENTS = {
    2: [(0, 0), (1, 0), (0, 1), (1, 1), (2, 0), (0, 2)],
    3: [
        (0, 0, 0),
        (1, 0, 0),
        (0, 1, 0),
        (0, 0, 1),
        (1, 1, 0),
        (1, 0, 1),
        (0, 1, 1),
        (2, 0, 0),
        (0, 2, 0),
        (0, 0, 2),
    ],
}


def monomials(points: np.ndarray) -> np.ndarray:
    """A (k, n): every monomial of degree <= 2 (paper order) at every point."""
    x = np.asarray(points, float)
    return np.array([np.prod(x ** np.array(e), axis=1) for e in EXPONENTS[x.shape[1]]])


def polygon_moments(v: np.ndarray) -> np.ndarray:
    """Exact moments (1, x, y, xy, x^2, y^2) of a polygon (Green's theorem; unit density)."""
    v = np.asarray(v, float)
    x, y = v[:, 0], v[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    c = x * yn - xn * y
    return np.array(
        [
            c.sum() / 2,
            ((x + xn) * c).sum() / 6,
            ((y + yn) * c).sum() / 6,
            ((x * yn + 2 * x * y + 2 * xn * yn + xn * y) * c).sum() / 24,
            ((x * x + x * xn + xn * xn) * c).sum() / 12,
            ((y * y + y * yn + yn * yn) * c).sum() / 12,
        ]
    )


def box_moments(lo, hi) -> np.ndarray:
    """Exact moments of an axis-aligned box (any dim; unit density)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return np.array(
        [
            np.prod(
                [(hi[a] ** (e[a] + 1) - lo[a] ** (e[a] + 1)) / (e[a] + 1) for a in range(len(lo))]
            )
            for e in EXPONENTS[len(lo)]
        ]
    )


_TET_A, _TET_B = 0.5854101966249685, 0.1381966011250105


def _simplices(points: np.ndarray, cells) -> tuple[np.ndarray, np.ndarray]:
    """(simplices (m, dim + 1), their sizes (m,)): quads split into 2 triangles,
    hexahedra into 6 tetrahedra (exact when their faces are planar)."""
    simp = []
    for ctype, c in cells.items():
        c = np.asarray(c, int)
        if ctype in ("triangle", "tetra"):
            simp.append(c)
        elif ctype == "quad":
            simp += [c[:, [0, 1, 2]], c[:, [0, 2, 3]]]
        elif ctype == "hexahedron":
            for t in (
                [0, 1, 2, 6],
                [0, 2, 3, 6],
                [0, 3, 7, 6],
                [0, 7, 4, 6],
                [0, 4, 5, 6],
                [0, 5, 1, 6],
            ):
                simp.append(c[:, t])
    simp = np.concatenate(simp)
    p = points[simp]
    return simp, np.abs(np.linalg.det(p[:, 1:] - p[:, :1])) / (2 if points.shape[1] == 2 else 6)


def _quadrature(points: np.ndarray, cells) -> tuple[np.ndarray, np.ndarray]:
    """Points and weights exact for quadratics on the simplices of the mesh."""
    simp, vol = _simplices(points, cells)
    p = points[simp]
    d = points.shape[1]
    if d == 2:  # edge midpoints, weight A/3
        q = np.stack([(p[:, 0] + p[:, 1]) / 2, (p[:, 1] + p[:, 2]) / 2, (p[:, 0] + p[:, 2]) / 2], 1)
        w = np.repeat(vol[:, None] / 3, 3, 1)
    else:
        bary = np.full((4, 4), _TET_B) + np.eye(4) * (_TET_A - _TET_B)
        q = np.einsum("qk,nkd->nqd", bary, p)
        w = np.repeat(vol[:, None] / 4, 4, 1)
    return q.reshape(-1, d), w.ravel()


def mesh_moments(points: np.ndarray, cells, density=None) -> np.ndarray:
    """Moments of a mesh body; ``density`` is a function of points (m, dim) or None (1)."""
    q, w = _quadrature(np.asarray(points, float), cells)
    if density is not None:
        w = w * density(q)
    return monomials(q) @ w
