"""Point placement (Deussen 1995, Section 3): regular grids, seeded random points with
points on the boundary, and iterated Voronoi (Lloyd) relaxation.

Lloyd in 2-D is exact: the Voronoi cell of a point is the body polygon clipped by the
half-planes of its Delaunay neighbours' bisectors (this also clips to a non-convex
body). In 3-D the cells of a box are estimated from dense uniform samples assigned to
the nearest point (a KD-tree). Boundary points stay on the boundary: polygon vertices
and box corners are fixed, a point on a polygon edge moves along that edge (the
centroid projected onto it), a point on a box face keeps its face coordinate(s).
Per iteration the standard deviations of neighbour distances (Delaunay edges) and of
region sizes are recorded (Fig. 2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq
from scipy.spatial import Delaunay, cKDTree

from harness.errors import ModelError
from harness.geometry.bodies import BodyGeom, clip_halfplane, polygon_centroid


def grid_points(lo, hi, shape) -> np.ndarray:
    """Nodes of a regular grid with ``shape`` = (nx, ny[, nz]) nodes; cells are
    rectangular when the spacings differ. Node index = i + nx*(j + ny*k) (x fastest)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    shape = tuple(int(s) for s in shape)
    if len(shape) != len(lo) or min(shape) < 2:
        raise ModelError(
            f"grid {list(shape)} needs {len(lo)} entries >= 2",
            field="model.grid",
            fix="e.g. grid = [5, 5] for a 25-node plate",
        )
    axes = [np.linspace(lo[a], hi[a], shape[a]) for a in range(len(lo))]
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.stack([m.ravel(order="F") for m in mesh], axis=1)


def _spacing(n: int, volume: float, surface: float, edges: float, dim: int) -> float:
    """Spacing h of n roughly uniform points: n = V/h^d + S/(2 h^(d-1)) (+ L/(4h)) + 1."""
    if dim == 2:
        f = lambda h: volume / h**2 + surface / (2 * h) + 1 - n
    else:
        f = lambda h: volume / h**3 + surface / (2 * h**2) + edges / (4 * h) + 1 - n
    return brentq(f, 1e-9 * (volume ** (1 / dim)), 10 * (volume ** (1 / dim)) + surface)


def random_points(body: BodyGeom, n: int, seed: int, n_boundary: int | None = None) -> np.ndarray:
    """``n`` seeded random points: every body vertex (polygon vertex / box corner), points
    uniformly at random on the boundary (``n_boundary`` of them, default so that the
    boundary spacing matches the interior one), the rest uniformly inside."""
    rng = np.random.default_rng(seed)
    corners = body.corners
    if body.kind == "polygon":
        v = body.vertices
        seg = np.roll(v, -1, axis=0) - v
        L = np.linalg.norm(seg, axis=1)
        P = L.sum()
        if n_boundary is None:
            h = _spacing(n, body.volume, P, 0, 2)
            n_boundary = max(int(round(P / h)) - len(v), 0)
        n_in = n - len(v) - n_boundary
        if n_in < 0:
            raise ModelError(
                f"n_points = {n} is less than the {len(v)} vertices plus {n_boundary} "
                "boundary points",
                field="model.n_points",
                fix="give more points or a smaller n_boundary",
            )
        s = np.sort(rng.uniform(0, P, n_boundary))
        cum = np.concatenate([[0], np.cumsum(L)])
        e = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(v) - 1)
        bpts = v[e] + ((s - cum[e]) / L[e])[:, None] * seg[e]
        inner = _sample_inside(body, n_in, rng)
        return np.vstack([corners, bpts, inner])
    if body.kind != "box":
        raise ModelError(
            "random placement needs a rectangle, polygon or box",
            field="model.placement",
            fix="use placement = 'mesh' for mesh bodies",
        )
    lo, hi = body.lo, body.hi
    ext = hi - lo
    V = float(np.prod(ext))
    S = 2 * (ext[0] * ext[1] + ext[0] * ext[2] + ext[1] * ext[2])
    Ltot = 4 * ext.sum()
    h = _spacing(n, V, S, Ltot, 3)
    pts = [corners]
    # points on the 12 edges
    for a in range(3):
        m = max(int(round(ext[a] / h)) - 1, 0)
        b, c = [i for i in range(3) if i != a]
        for sb in (0, 1):
            for sc in (0, 1):
                q = np.empty((m, 3))
                q[:, a] = rng.uniform(lo[a], hi[a], m)
                q[:, b] = (lo, hi)[sb][b]
                q[:, c] = (lo, hi)[sc][c]
                pts.append(q)
    # points on the 6 faces
    for a in range(3):
        b, c = [i for i in range(3) if i != a]
        m = max(int(round(ext[b] * ext[c] / h**2 - (ext[b] + ext[c]) / h)), 0)
        for side in (0, 1):
            q = np.empty((m, 3))
            q[:, a] = (lo, hi)[side][a]
            q[:, b] = rng.uniform(lo[b], hi[b], m)
            q[:, c] = rng.uniform(lo[c], hi[c], m)
            pts.append(q)
    nb = sum(len(p) for p in pts)
    if n_boundary is not None or n - nb < 0:
        raise ModelError(
            f"n_points = {n} is too few for a box (needs more than {nb} boundary points)"
            if n - nb < 0
            else "n_boundary is only used in 2-D",
            field="model.n_points" if n - nb < 0 else "model.n_boundary",
        )
    pts.append(lo + rng.uniform(size=(n - nb, 3)) * ext)
    return np.vstack(pts)


def _sample_inside(body: BodyGeom, m: int, rng) -> np.ndarray:
    out = np.zeros((0, body.dim))
    while len(out) < m:
        q = body.lo + rng.uniform(size=(2 * m + 16, body.dim)) * (body.hi - body.lo)
        q = q[body.contains(q) & ~body.on_boundary(q)]
        out = np.vstack([out, q])
    return out[:m]


# -- Lloyd / iterated Voronoi -----------------------------------------------------------


@dataclass(frozen=True, eq=False)
class LloydResult:
    """points after the iterations; std_distance / std_size (iterations + 1,) from the
    initial state on: std of Delaunay neighbour distances and of Voronoi region sizes;
    sizes (n,): region areas/volumes of the final points."""

    points: np.ndarray
    std_distance: np.ndarray
    std_size: np.ndarray
    sizes: np.ndarray


def neighbour_pairs(points: np.ndarray, body: BodyGeom | None = None) -> np.ndarray:
    """Delaunay edges (m, 2), i < j; with a polygon body, edges of triangles outside are dropped."""
    tri = Delaunay(points)
    simp = tri.simplices
    if body is not None and body.kind == "polygon":
        simp = simp[body.contains(points[simp].mean(axis=1))]
    d = points.shape[1]
    pairs = np.concatenate([simp[:, [i, j]] for i in range(d + 1) for j in range(i + 1, d + 1)])
    return np.unique(np.sort(pairs, axis=1), axis=0)


def voronoi_cells_2d(points: np.ndarray, body: BodyGeom) -> tuple[np.ndarray, np.ndarray]:
    """Exact areas (n,) and centroids (n, 2) of the Voronoi cells clipped to the polygon."""
    tri = Delaunay(points)
    indptr, nbrs = tri.vertex_neighbor_vertices
    areas = np.zeros(len(points))
    cents = points.copy()
    for i, p in enumerate(points):
        poly = body.vertices
        for j in nbrs[indptr[i] : indptr[i + 1]]:
            q = points[j]
            nrm = q - p
            poly = clip_halfplane(poly, nrm, nrm @ (0.5 * (p + q)))
            if len(poly) == 0:
                break
        a, c = polygon_centroid(poly)
        areas[i] = a
        if a > 0:
            cents[i] = c
    return areas, cents


def voronoi_cells_sampled(
    points: np.ndarray, body: BodyGeom, n_samples: int, rng
) -> tuple[np.ndarray, np.ndarray]:
    """Monte-Carlo volumes (n,) and centroids (n, dim) of the Voronoi cells inside the body."""
    q = body.lo + rng.uniform(size=(n_samples, body.dim)) * (body.hi - body.lo)
    if body.kind != "box":
        q = q[body.contains(q)]
    owner = cKDTree(points).query(q)[1]
    cnt = np.bincount(owner, minlength=len(points)).astype(float)
    sums = np.stack(
        [np.bincount(owner, q[:, a], minlength=len(points)) for a in range(body.dim)], axis=1
    )
    cents = np.where(cnt[:, None] > 0, sums / np.maximum(cnt, 1)[:, None], points)
    vol = cnt * (np.prod(body.hi - body.lo) * len(q) / n_samples) / max(len(q), 1)
    return vol, cents


def _constrain(
    body: BodyGeom, old: np.ndarray, new: np.ndarray, fixed: np.ndarray, edge: np.ndarray
) -> np.ndarray:
    """Keep boundary points on the boundary (see the module docstring)."""
    out = new.copy()
    out[fixed] = old[fixed]
    if body.kind == "polygon":
        v = body.vertices
        for i in np.flatnonzero((edge >= 0) & ~fixed):
            a, b = v[edge[i]], v[(edge[i] + 1) % len(v)]
            t = np.clip((new[i] - a) @ (b - a) / ((b - a) @ (b - a)), 1e-3, 1 - 1e-3)
            out[i] = a + t * (b - a)
    else:
        for side, bound in ((0, body.lo), (1, body.hi)):
            on = np.abs(old - bound) <= body.tol
            out[on] = np.broadcast_to(bound, old.shape)[on]
    return out


def lloyd(
    body: BodyGeom,
    points: np.ndarray,
    iterations: int,
    seed: int = 0,
    samples_per_point: int = 2000,
) -> LloydResult:
    """``iterations`` Lloyd steps: every point moves to the centroid of its Voronoi
    region clipped to the body (boundary points along the boundary)."""
    rng = np.random.default_rng(seed)
    pts = np.asarray(points, float).copy()
    corners = body.corners
    fixed = np.zeros(len(pts), bool)
    if len(corners):
        fixed = np.any(np.all(np.abs(pts[:, None, :] - corners[None]) <= body.tol, axis=2), axis=1)
    edge = body.boundary_edge(pts) if body.kind == "polygon" else np.full(len(pts), -1)

    def cells(p):
        if body.kind == "polygon":
            return voronoi_cells_2d(p, body)
        return voronoi_cells_sampled(p, body, samples_per_point * len(p), rng)

    sd, ss = [], []
    sizes, cents = cells(pts)
    for it in range(iterations + 1):
        pairs = neighbour_pairs(pts, body)
        sd.append(float(np.std(np.linalg.norm(pts[pairs[:, 0]] - pts[pairs[:, 1]], axis=1))))
        ss.append(float(np.std(sizes)))
        if it == iterations:
            break
        pts = _constrain(body, pts, cents, fixed, edge)
        sizes, cents = cells(pts)
    return LloydResult(pts, np.array(sd), np.array(ss), sizes)
