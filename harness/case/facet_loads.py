"""Nodal forces of a traction on a part's boundary facets: the one path every spring
network's traction loads take (harness.mechanics.statics), the same facets and the same
integral as the FEM's load vector (reference.fem.Discretisation.part_facets).

A mesh body's facets are the mesh's boundary facets on the part (all vertices and the
centroid on it, as the FEM selects them), whose vertices must be nodes. A box or polygon
body's flat parts are the part's nodes tiled in their plane: a tensor grid of nodes in
rectangles (the bilinear hats' tributary areas), other nodes in a Delaunay triangulation
(2-D: consecutive segments). A traction t(x) = v + w x (x - c) (linear in x; c the facets'
area centroid) is integrated against linear hats: f_i = |S| / (k (k + 1)) (t_i + sum_j t_j)
on a simplex of k vertices, which is exact, so the forces have the FEM's resultant and
torque (quads: fans about their centre).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay, QhullError, cKDTree

from harness.errors import ModelError
from harness.io.meshfile import mesh_surface


def part_facets(points: np.ndarray, case, on_part) -> list[np.ndarray]:
    """Node indices of the part's boundary facets, one (m, k) array per facet size (k = 2
    in 2-D, 3 or 4 in 3-D)."""
    body = case.body
    if body.shape != "mesh":
        return [_planar_triangles(points, on_part)]
    mpoints, facets, _ = mesh_surface(body.file, body.format)
    tol = 1e-8 * float(np.ptp(mpoints, axis=0).max())
    dist, node = cKDTree(points).query(mpoints)
    out = []
    for fac in facets:
        ok = on_part(mpoints[fac.ravel()].T).reshape(fac.shape).all(axis=1)
        ok[ok] = on_part(mpoints[fac[ok]].mean(axis=1).T)
        if np.any(dist[fac[ok]] > tol):
            raise ModelError(
                "a traction on a mesh body needs a node at every vertex of its facets",
                field="model.placement",
                fix="use placement = 'mesh' (the mesh's own vertices)",
            )
        out.append(node[fac[ok]])
    return out


def _planar_triangles(points: np.ndarray, on_part) -> np.ndarray:
    """A flat part's nodes tiled in their plane: (m, 2) consecutive segments in 2-D; in 3-D
    (m, 4) rectangles when the nodes form a tensor grid in the plane, else (m, 3) Delaunay
    triangles; only tiles whose centroid is on the part."""
    idx = np.flatnonzero(on_part(points.T))
    dim = points.shape[1]
    if len(idx) < dim:
        return np.zeros((0, dim), int)
    q = points[idx] - points[idx].mean(axis=0)
    _, _, vt = np.linalg.svd(q, full_matrices=False)
    if dim == 2:
        order = idx[np.argsort(q @ vt[0])]
        seg = np.stack([order[:-1], order[1:]], axis=1)
        return seg[on_part(points[seg].mean(axis=1).T)]
    uv = q @ vt[:2].T
    normal = int(np.argmax(np.abs(vt[2])))
    if np.isclose(abs(vt[2][normal]), 1.0):  # a face of an axis-aligned box: its own two axes
        uv = points[idx][:, [a for a in range(3) if a != normal]]
    tiles = _grid_rectangles(idx, uv)
    if tiles is None:
        try:
            tiles = idx[Delaunay(uv).simplices]
        except QhullError:  # the nodes lie on a line: no area to carry
            return np.zeros((0, 3), int)
    return tiles[on_part(points[tiles].mean(axis=1).T)]


def planar_forces(points: np.ndarray, on_part, vector) -> np.ndarray:
    """Nodal forces (n, dim) of a constant traction on a flat part given by its predicate
    (the nodes tiled in their plane, as a box body's faces are)."""
    return facet_forces(points, [_planar_triangles(points, on_part)], vector)


def _grid_rectangles(idx: np.ndarray, uv: np.ndarray) -> np.ndarray | None:
    """The rectangles (m, 4), in order around each, of nodes ``idx`` whose plane coordinates
    ``uv`` (n, 2) form a full tensor grid (at least 2 x 2), else None."""
    ru, iu = np.unique(np.round(uv[:, 0], 12), return_inverse=True)
    rv, iv = np.unique(np.round(uv[:, 1], 12), return_inverse=True)
    if len(ru) * len(rv) != len(idx) or len(ru) < 2 or len(rv) < 2:
        return None
    grid = np.full((len(ru), len(rv)), -1)
    grid[iu, iv] = idx
    if np.any(grid < 0):
        return None
    return np.stack([grid[:-1, :-1], grid[1:, :-1], grid[1:, 1:], grid[:-1, 1:]], axis=-1).reshape(
        -1, 4
    )


def _simplices(facets: np.ndarray):
    """Facets (m, k) as simplices whose vertices are weighted nodes: (ids, weights), each
    (m', k', 4). Segments and triangles as they are; a quad as four triangles fanned about
    its centre (the mean of its corners, so its share goes to them equally)."""
    if facets.shape[1] < 4:
        ids = np.repeat(facets[..., None], 4, axis=2)
        return ids, np.broadcast_to([1.0, 0.0, 0.0, 0.0], ids.shape)
    ids, wts = [], []
    for i in range(4):
        corner = lambda j: np.repeat(facets[:, [j], None], 4, axis=2)  # noqa: E731
        ids.append(np.concatenate([facets[:, None, :], corner(i), corner((i + 1) % 4)], axis=1))
        w = np.zeros((len(facets), 3, 4))
        w[:, 0], w[:, 1:, 0] = 0.25, 1.0
        wts.append(w)
    return np.concatenate(ids), np.concatenate(wts)


def facet_forces(points: np.ndarray, facets: list[np.ndarray], vector, twist=None) -> np.ndarray:
    """Nodal forces (n, dim) of t(x) = vector + twist x (x - c) on ``facets`` (the arrays
    of part_facets). Exact against linear hats on segments and triangles; on a quad, for
    a constant traction on a parallelogram."""
    n, dim = points.shape
    pairs = [_simplices(np.asarray(f, int)) for f in facets if len(f)]
    if not pairs:
        return np.zeros((n, dim))
    ids = np.concatenate([i for i, _ in pairs])
    wts = np.concatenate([w for _, w in pairs])
    x = np.einsum("mkj,mkjd->mkd", wts, points[ids])
    e = x[:, 1:] - x[:, :1]
    size = (
        np.linalg.norm(e[:, 0], axis=1)
        if x.shape[1] == 2
        else 0.5 * np.linalg.norm(np.cross(e[:, 0], e[:, 1]), axis=1)
    )
    t = np.broadcast_to(np.asarray(vector, float), x.shape).copy()
    if twist is not None:
        c = np.einsum("m,md->d", size, x.mean(axis=1)) / size.sum()
        t += np.cross(np.asarray(twist, float), x - c)
    k = x.shape[1]
    share = size[:, None, None] / (k * (k + 1)) * (t + t.sum(axis=1, keepdims=True))  # (m, k, dim)
    f = np.zeros((n, dim))
    np.add.at(f, ids.ravel(), (wts[..., None] * share[:, :, None, :]).reshape(-1, dim))
    return f
