"""The anisotropic element model of Bourguignon & Cani (2000), as their program implements it.

Each tetrahedron or hexahedron carries three *axes of interest* through its rest
barycentre g, along a frame (f1, f2, f3) built from the fibre direction f1. An axis end
is where the line g + t f meets a face of the element; it is stored as weights of that
face's vertices (barycentric for a triangle, bilinear for a quad) and follows the
deformation as ``P = sum w_k x_k``. Forces (shared/reference-data/bourguignon2000/README):

- axial damped springs  F_k = -[ks_k (|l_k| - L0_k) + kd_k (dv_k . n_k)] n_k;
- angular springs       K12 = -ks4 (n1.n2 - c12), ... (c = 0 is the program's form:
  rest angle 90 degrees; ``rest_angle="rest"`` takes c from the rest shape);
  G1 = F1 + K12 n2 + K13 n3, ... ; +G_k at P_k, -G_k at P'_k, spread with the weights;
- volume: tet, f_i += -kvs (D - D0) (x_i - g)/|x_i - g| with D = sum_i |x_i - g|;
  hex, eight damped radial springs centre -> vertex (kvs, kvd).

Damping constants here are *physical* (N s/m). The program's are per step: its kd is
kd * h in physical units (see :func:`program_damping`).

``forces`` is plain numpy, vectorised over elements, and complex-safe so that
:func:`harness.mechanics.dynamics.jacobian` can differentiate it by the complex step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from harness.errors import ModelError
from harness.models.cells import cell_graph, hex_to_tets

TET_FACES = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]])
HEX_FACES = np.array(
    [[0, 1, 2, 3], [4, 5, 6, 7], [0, 4, 7, 3], [1, 5, 6, 2], [4, 5, 1, 0], [7, 6, 2, 3]]
)
EPSILON = 1e-6  # the Moller-Trumbore determinant threshold of the program


# -- small vector helpers written out component by component: the program's order ----------


def _dot(a, b):
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _cross(a, b):
    return np.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


def _norm(a):
    return np.sqrt(a[..., 0] * a[..., 0] + a[..., 1] * a[..., 1] + a[..., 2] * a[..., 2])


def frame(azimuth, elevation) -> np.ndarray:
    """Per-element frame (m, 3, 3): rows f1, f2, f3 of the program.

    f1 = (cos a cos e, sin e, sin a cos e), f2 = f1 x (1,0,0), f3 = f1 x f2. When f1 is
    along x (f2 vanishes) f2 = (0,0,1) x f1, which gives the hexa program's x, y, z axes.
    """
    a = np.atleast_1d(np.asarray(azimuth, float))
    e = np.atleast_1d(np.asarray(elevation, float))
    a, e = np.broadcast_arrays(a, e)
    f1 = np.stack([np.cos(a) * np.cos(e), np.sin(e), np.sin(a) * np.cos(e)], axis=-1)
    f2 = _cross(f1, np.array([1.0, 0.0, 0.0]))
    bad = _norm(f2) < 1e-8
    if bad.any():
        f2[bad] = _cross(np.array([0.0, 0.0, 1.0]), f1[bad])
    f3 = _cross(f1, f2)
    return np.stack([f1, f2, f3], axis=1)


def angles_of(directions) -> tuple[np.ndarray, np.ndarray]:
    """(azimuth, elevation) of unit vectors (m, 3) in the program's convention."""
    d = np.asarray(directions, float)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    return np.arctan2(d[:, 2], d[:, 0]), np.arcsin(np.clip(d[:, 1], -1, 1))


# -- axes of interest in the rest shape ----------------------------------------------------------


def _moller_trumbore(orig, dirn, v0, v1, v2):
    """The program's non-culling ray/triangle test (a *line* test: t may be negative)."""
    e1, e2 = v1 - v0, v2 - v0
    p = _cross(dirn, e2)
    det = _dot(e1, p)
    ok = ~((det > -EPSILON) & (det < EPSILON))
    inv = 1.0 / np.where(ok, det, 1.0)
    tv = orig - v0
    u = _dot(tv, p) * inv
    q = _cross(tv, e1)
    v = _dot(dirn, q) * inv
    hit = ok & ~((u < 0.0) | (u > 1.0)) & ~((v < 0.0) | (u + v > 1.0))
    return hit, u, v


def _tet_face_hits(X, g, f):
    """X (m,4,3) vertices, g (m,3), f (m,3) -> hit (m,4), point (m,4,3), weights (m,4,3)."""
    V = X[:, TET_FACES]  # (m, 4 faces, 3 vertices, 3)
    o, d = g[:, None, :], f[:, None, :]
    hit, u, v = _moller_trumbore(o, d, V[:, :, 0], V[:, :, 1], V[:, :, 2])
    w0 = (1.0 - u) - v
    ip = V[:, :, 0] * w0[..., None] + V[:, :, 1] * u[..., None] + V[:, :, 2] * v[..., None]
    A = 0.5 * _norm(_cross(V[:, :, 1] - V[:, :, 0], V[:, :, 2] - V[:, :, 0]))
    a0 = 0.5 * _norm(_cross(V[:, :, 1] - ip, V[:, :, 2] - ip))
    a1 = 0.5 * _norm(_cross(V[:, :, 0] - ip, V[:, :, 2] - ip))
    a2 = 0.5 * _norm(_cross(V[:, :, 0] - ip, V[:, :, 1] - ip))
    W = np.stack([a0 / A, a1 / A, a2 / A], axis=-1)
    return hit, ip, W


def _hex_face_hits(X, g, f):
    """X (m,8,3): each quad face is tested as triangles (q0,q1,q2) then (q0,q2,q3)."""
    Q = X[:, HEX_FACES]  # (m, 6, 4, 3)
    o, d = g[:, None, :], f[:, None, :]
    h1, u1, v1 = _moller_trumbore(o, d, Q[:, :, 0], Q[:, :, 1], Q[:, :, 2])
    h2, u2, v2 = _moller_trumbore(o, d, Q[:, :, 0], Q[:, :, 2], Q[:, :, 3])
    ip1 = (
        Q[:, :, 0] * ((1.0 - u1) - v1)[..., None]
        + Q[:, :, 1] * u1[..., None]
        + Q[:, :, 2] * v1[..., None]
    )
    ip2 = (
        Q[:, :, 0] * ((1.0 - u2) - v2)[..., None]
        + Q[:, :, 2] * u2[..., None]
        + Q[:, :, 3] * v2[..., None]
    )
    ip = np.where(h1[..., None], ip1, ip2)
    hit = h1 | h2
    l1, l3, l = Q[:, :, 1] - Q[:, :, 0], Q[:, :, 3] - Q[:, :, 0], ip - Q[:, :, 0]
    L1, L3, L = _norm(l1), _norm(l3), _norm(l)
    with np.errstate(invalid="ignore", divide="ignore"):
        c1 = _dot(l1, l) / (L1 * L)
        c3 = _dot(l3, l) / (L3 * L)
    c1 = np.where(L > 0, c1, 0.0)
    c3 = np.where(L > 0, c3, 0.0)
    zeta_c = (L1 - c1 * L) / L1  # the program's coefs[0] = 1 - zeta
    eta_c = (L3 - c3 * L) / L3  # coefs[1] = 1 - eta
    z, e = 1.0 - zeta_c, 1.0 - eta_c
    W = np.stack([zeta_c * eta_c, z * eta_c, z * e, zeta_c * e], axis=-1)
    return hit, ip, W


@dataclass(frozen=True)
class Axes:
    """Rest-state axes: for element i, end j (0..5 = f1, f1', f2, f2', f3, f3'):
    ``face[i, j]`` (local face index), ``nodes[i, j]`` (global ids of the face's vertices),
    ``weights[i, j]`` and the rest intersection ``points[i, j]``."""

    face: np.ndarray
    nodes: np.ndarray
    weights: np.ndarray
    points: np.ndarray


def find_axes(points, cells, azimuth, elevation, seed: int = 0, frames=None) -> Axes:
    """Axes of interest of every element, exactly as the original program finds them.
    ``frames`` (m, 3, 3) (rows f1, f2, f3) replaces the frame built from azimuth and
    elevation (e.g. a frame turned rigidly about an axis, which :func:`frame` cannot give).

    For each of the six directions (f1, -f1, f2, -f2, f3, -f3) the faces are tried in the
    program's order and the first one the line through g crosses is taken, skipping a hit
    that repeats the previous end (so -f1 yields the other end of the f1 chord). If no
    face is hit the direction is perturbed by up to 1e-6 (seeded; the program used rand()).
    """
    points = np.asarray(points, float)
    cells = np.asarray(cells)
    m, nv = cells.shape
    if nv not in (4, 8):
        raise ModelError(f"elements with {nv} nodes: need tetrahedra (4) or hexahedra (8)")
    X = points[cells]
    g = (
        0.25 * (((X[:, 0] + X[:, 1]) + X[:, 2]) + X[:, 3])
        if nv == 4
        else 0.125
        * (
            ((((((X[:, 0] + X[:, 1]) + X[:, 2]) + X[:, 3]) + X[:, 4]) + X[:, 5]) + X[:, 6])
            + X[:, 7]
        )
    )
    hits_of = _tet_face_hits if nv == 4 else _hex_face_hits
    faces = TET_FACES if nv == 4 else HEX_FACES
    F = (
        frame(np.broadcast_to(azimuth, (m,)), np.broadcast_to(elevation, (m,)))
        if frames is None
        else np.broadcast_to(np.asarray(frames, float), (m, 3, 3))
    )
    dirs = np.stack([F[:, 0], -F[:, 0], F[:, 1], -F[:, 1], F[:, 2], -F[:, 2]], axis=1)
    face = np.full((m, 6), -1)
    pts = np.zeros((m, 6, 3))
    wts = np.zeros((m, 6, faces.shape[1]))
    rng = np.random.default_rng(seed)
    prev = np.full((m, 3), np.nan)
    # a hit within tol of the previous end is "the same point" (the program tests ==; a line
    # through an edge gives two faces' copies of one point that may differ by rounding)
    tol = 1e-6 * np.max(_norm(X[:, :, None] - X[:, None, :]).reshape(m, -1), axis=1)
    for i in range(6):
        hit, ip, W = hits_of(X, g, dirs[:, i])
        ok = hit & ~(_norm(ip - prev[:, None, :]) <= tol[:, None])
        j = np.argmax(ok, axis=1)
        found = ok[np.arange(m), j]
        for el in np.flatnonzero(~found):  # rare: a line through an edge or a vertex
            for _ in range(100):
                d = dirs[el, i] + 1e-6 * rng.random(3)
                h1, ip1, W1 = hits_of(X[el : el + 1], g[el : el + 1], d[None])
                ok1 = h1[0] & ~(_norm(ip1[0] - prev[el]) <= tol[el])
                if ok1.any():
                    jj = int(np.argmax(ok1))
                    face[el, i], pts[el, i], wts[el, i] = jj, ip1[0, jj], W1[0, jj]
                    break
            else:
                raise ModelError(f"element {el}: axis end {i} meets no face (degenerate element?)")
        sel = np.flatnonzero(found)
        face[sel, i] = j[sel]
        pts[sel, i] = ip[sel, j[sel]]
        wts[sel, i] = W[sel, j[sel]]
        prev = pts[:, i]
    nodes = cells[np.arange(m)[:, None, None], faces[face]]
    return Axes(face, nodes, wts, pts)


# -- the model --------------------------------------------------------------------------------


def _per_element(value, m, k, name):
    a = np.asarray(value, float)
    if a.ndim == 0:
        a = np.full((m, k), float(a))
    elif a.shape == (k,):
        a = np.tile(a, (m, 1))
    elif a.shape == (m,) and k == 1:
        a = a[:, None]
    if a.shape != (m, k):
        raise ModelError(
            f"{name}: expected a number, {k} numbers or an array ({m}, {k}); got shape {a.shape}"
        )
    return a if k > 1 else a[:, 0]


def program_damping(kd_program, dt: float):
    """The program's per-step damping constant -> physical (N s/m): kd * h."""
    return np.asarray(kd_program, float) * dt


@dataclass(frozen=True, eq=False)
class AnisotropicBody:
    """Bourguignon-Cani elements on a tet or hex mesh. Arrays per element (m):
    ks (m, 6) = ks1..ks6, kd (m, 3) physical, kvs, kvd (m,), L0 (m, 3) rest axis lengths,
    cos0 (m, 3) rest cosines of the pairs (12, 13, 23) (zero: the program's form),
    D0 (m,) (tet: rest sum of centre distances) or (m, 8) (hex: rest radii)."""

    points: np.ndarray
    cells: np.ndarray
    axes: Axes
    ks: np.ndarray
    kd: np.ndarray
    kvs: np.ndarray
    kvd: np.ndarray
    L0: np.ndarray
    cos0: np.ndarray
    D0: np.ndarray
    volume: bool = True

    @property
    def n_nodes(self) -> int:
        return len(self.points)

    @property
    def is_hex(self) -> bool:
        return self.cells.shape[1] == 8

    def tets(self) -> np.ndarray:
        """The elements as tetrahedra (hexahedra split into six) for volume measures."""
        return self.cells if not self.is_hex else hex_to_tets(self.cells)

    def node_graph(self) -> sp.csr_matrix:
        """n x n pattern: nodes that share an element."""
        return cell_graph(self.cells, self.n_nodes)

    def _scatter(self):
        S = getattr(self, "_S", None)
        if S is None:
            m, _, k = self.axes.nodes.shape
            cols = np.concatenate([self.axes.nodes.ravel(), self.cells.ravel()])
            S = sp.csr_matrix(
                (np.ones(len(cols)), (cols, np.arange(len(cols)))), shape=(self.n_nodes, len(cols))
            )
            object.__setattr__(self, "_S", S)
        return S

    def _end_forces(self, l, dv=None) -> np.ndarray:
        """Forces (m, 6, 3) on the six axis ends (P1, P1', P2, ...) from the axis vectors
        l (m, 3, 3) and their rates dv: the damped axial springs and the program's angular
        terms -ks (n_i . n_j - cos0) pulling each axis towards the other two."""
        L = np.sqrt(np.sum(l * l, axis=-1))
        n = l / L[..., None]
        s = self.ks[:, :3] * (L - self.L0)
        if dv is not None:
            s = s + self.kd * np.sum(dv * n, axis=-1)
        F = -s[..., None] * n
        n1, n2, n3 = n[:, 0], n[:, 1], n[:, 2]
        K12 = -(self.ks[:, 3] * (np.sum(n1 * n2, -1) - self.cos0[:, 0]))[:, None]
        K13 = -(self.ks[:, 4] * (np.sum(n1 * n3, -1) - self.cos0[:, 1]))[:, None]
        K23 = -(self.ks[:, 5] * (np.sum(n2 * n3, -1) - self.cos0[:, 2]))[:, None]
        G1 = F[:, 0] + K12 * n2 + K13 * n3
        G2 = F[:, 1] + K12 * n1 + K23 * n3
        G3 = F[:, 2] + K13 * n1 + K23 * n2
        return np.stack([G1, -G1, G2, -G2, G3, -G3], axis=1)

    def forces(self, x, v=None) -> np.ndarray:
        """Internal forces (n, 3) at positions x (n, 3) and velocities v (m/s)."""
        I, W = self.axes.nodes, self.axes.weights
        m = len(I)
        P = np.einsum("mek,mekd->med", W, x[I])
        dv = None
        if v is not None:
            V = np.einsum("mek,mekd->med", W, v[I])
            dv = V[:, 0::2] - V[:, 1::2]
        Gend = self._end_forces(P[:, 0::2] - P[:, 1::2], dv)
        contrib = [(W[..., None] * Gend[:, :, None, :]).reshape(-1, 3)]
        Xc = x[self.cells]
        nv = self.cells.shape[1]
        if self.volume:
            g = Xc.mean(axis=1)
            d = Xc - g[:, None, :]
            D = np.sqrt(np.sum(d * d, axis=-1))
            nd = d / D[..., None]
            if not self.is_hex:
                fv = -(self.kvs * (D.sum(axis=1) - self.D0))[:, None, None] * nd
            else:
                sv = self.kvs[:, None] * (D - self.D0)
                if v is not None:
                    Vc = v[self.cells]
                    sv = sv + self.kvd[:, None] * np.sum(
                        (Vc - Vc.mean(axis=1)[:, None]) * nd, axis=-1
                    )
                fv = -sv[..., None] * nd
        else:
            fv = np.zeros((m, nv, 3), dtype=np.result_type(x, float))
        contrib.append(fv.reshape(-1, 3))
        return self._scatter() @ np.concatenate(contrib)

    def _onehot(self):
        """(m, 6, k, nv) 0/1: which element vertex each axis end's face vertex is."""
        H = getattr(self, "_H", None)
        if H is None:
            H = (self.axes.nodes[..., None] == self.cells[:, None, None, :]).astype(float)
            object.__setattr__(self, "_H", H)
        return H

    def element_forces(self, X) -> np.ndarray:
        """Static forces (m, nv, 3) of each element on its own vertices, X = x[cells]
        (m, nv, 3): the terms of :meth:`forces` (without damping) before assembly, so that
        each element can be differentiated on its own (:meth:`tangent_stiffness`)."""
        H, W = self._onehot(), self.axes.weights
        P = np.einsum("mekn,mek,mnd->med", H, W, X)
        Gend = self._end_forces(P[:, 0::2] - P[:, 1::2])
        out = np.einsum("mekn,mek,med->mnd", H, W, Gend)
        if self.volume:
            d = X - X.mean(axis=1)[:, None, :]
            D = np.sqrt(np.sum(d * d, axis=-1))
            nd = d / D[..., None]
            if self.is_hex:
                out = out - (self.kvs[:, None] * (D - self.D0))[..., None] * nd
            else:
                out = out - (self.kvs * (D.sum(axis=1) - self.D0))[:, None, None] * nd
        return out

    def tangent_stiffness(self, x=None, h: float = 1e-30) -> sp.csr_matrix:
        """K = -d forces / d x at x (default rest), (3n, 3n): each element's Jacobian by the
        complex step on its own vertices (3 nv evaluations for all elements at once, exact
        to rounding), assembled. Equals ``harness.mechanics.dynamics.stiffness`` at a fraction of
        the cost (that one colours the whole mesh)."""
        x = self.points if x is None else np.asarray(x, float)
        X = x[self.cells]
        m, nv, _ = X.shape
        blocks = np.empty((m, nv, 3, nv, 3))  # d f[a, i] / d x[b, j]
        for b in range(nv):
            for j in range(3):
                Xc = X.astype(complex)
                Xc[:, b, j] += 1j * h
                blocks[:, :, :, b, j] = np.imag(self.element_forces(Xc)) / h
        dof = 3 * self.cells[:, :, None] + np.arange(3)  # (m, nv, 3)
        rows = np.broadcast_to(dof[:, :, :, None, None], blocks.shape).ravel()
        cols = np.broadcast_to(dof[:, None, None, :, :], blocks.shape).ravel()
        N = 3 * self.n_nodes
        return sp.csr_matrix((-blocks.ravel(), (rows, cols)), shape=(N, N))

    def energy(self, x) -> float:
        """Potential of the conservative parts (axial, the angular terms read as
        0.5 ks (cos - cos0)^2, volume); the program's angular force is not its exact gradient."""
        P = np.einsum("mek,mekd->med", self.axes.weights, x[self.axes.nodes])
        l = P[:, 0::2] - P[:, 1::2]
        L = np.linalg.norm(l, axis=-1)
        n = l / L[..., None]
        c = np.stack(
            [
                np.sum(n[:, 0] * n[:, 1], -1),
                np.sum(n[:, 0] * n[:, 2], -1),
                np.sum(n[:, 1] * n[:, 2], -1),
            ],
            axis=1,
        )
        e = 0.5 * np.sum(self.ks[:, :3] * (L - self.L0) ** 2) + 0.5 * np.sum(
            self.ks[:, 3:] * (c - self.cos0) ** 2
        )
        if self.volume:
            Xc = x[self.cells]
            D = np.linalg.norm(Xc - Xc.mean(axis=1)[:, None], axis=-1)
            if self.is_hex:
                e += 0.5 * np.sum(self.kvs[:, None] * (D - self.D0) ** 2)
            else:
                e += 0.5 * np.sum(self.kvs * (D.sum(axis=1) - self.D0) ** 2)
        return float(e)


def build_anisotropic(
    points,
    cells,
    *,
    azimuth=0.0,
    elevation=np.pi / 2,
    ks=2.5,
    kd=0.0,
    kvs=0.0,
    kvd=0.0,
    volume: bool = True,
    rest_angle: str = "program",
    seed: int = 0,
    frames=None,
) -> AnisotropicBody:
    """Build the model. ``ks`` one number, six (ks1..ks6) or (m, 6); ``kd`` (physical
    N s/m) one number, three or (m, 3); ``kvs``/``kvd`` one number or (m,); azimuth and
    elevation (radians) one value or one per element. ``rest_angle``: "program" (90
    degrees) or "rest" (the rest shape's angles, for non-orthogonal frames). ``frames``
    (m, 3, 3) or (3, 3): explicit element frames instead of azimuth/elevation."""
    points = np.asarray(points, float)
    cells = np.asarray(cells, dtype=np.int64)
    m = len(cells)
    if rest_angle not in ("program", "rest"):
        raise ModelError(f"rest_angle '{rest_angle}': use 'program' or 'rest'")
    axes = find_axes(points, cells, azimuth, elevation, seed, frames)
    l = axes.points[:, 0::2] - axes.points[:, 1::2]
    L0 = _norm(l)
    if np.any(L0 <= 0):
        raise ModelError(f"{int(np.sum(L0 <= 0))} axes of zero rest length (flat elements?)")
    if rest_angle == "rest":
        n = l / L0[..., None]
        cos0 = np.stack(
            [_dot(n[:, 0], n[:, 1]), _dot(n[:, 0], n[:, 2]), _dot(n[:, 1], n[:, 2])], axis=1
        )
    else:
        cos0 = np.zeros((m, 3))
    X = points[cells]
    nv = cells.shape[1]
    g = (
        0.25 * (((X[:, 0] + X[:, 1]) + X[:, 2]) + X[:, 3])
        if nv == 4
        else 0.125
        * (
            ((((((X[:, 0] + X[:, 1]) + X[:, 2]) + X[:, 3]) + X[:, 4]) + X[:, 5]) + X[:, 6])
            + X[:, 7]
        )
    )
    Dk = _norm(X - g[:, None])
    D0 = Dk if nv == 8 else ((Dk[:, 0] + Dk[:, 1]) + Dk[:, 2]) + Dk[:, 3]
    return AnisotropicBody(
        points,
        cells,
        axes,
        _per_element(ks, m, 6, "ks"),
        _per_element(kd, m, 3, "kd"),
        _per_element(kvs, m, 1, "kvs"),
        _per_element(kvd, m, 1, "kvd"),
        L0,
        cos0,
        D0,
        bool(volume),
    )
