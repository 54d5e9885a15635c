"""The constrained box problem, matrix-free: per-component free dofs as tensor products,
the Kronecker operator, fast-diagonalisation block-Jacobi CG, and point evaluation."""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse.linalg as spla

from .q2 import axis_factor, axis_matrices, lame, q2_nodes, stiffness


def _mode(S, U, d: int):
    """Apply the matrix S (sparse or dense) along axis d of the 3-D array U."""
    if d == 0:
        return (S @ U.reshape(U.shape[0], -1)).reshape((S.shape[0],) + U.shape[1:])
    if d == 2:
        return (U.reshape(-1, U.shape[2]) @ S.T).reshape(U.shape[:2] + (S.shape[0],))
    V = np.moveaxis(U, 1, 0)
    W = (S @ V.reshape(V.shape[0], -1)).reshape((S.shape[0],) + V.shape[1:])
    return np.ascontiguousarray(np.moveaxis(W, 0, 1))


class BoxProblem:
    """Q2 linear elasticity on the tensor mesh of boxes with vertices ``vertices_xyz``
    (three 1-D arrays), with ``fixed[a]`` = list of (axis, end) planes on which component a
    is zero. Free dofs of component a: a tensor product of per-axis node sets."""

    def __init__(self, vertices_xyz, E: float, nu: float, fixed: dict):
        self.vertices = [np.asarray(v, float) for v in vertices_xyz]
        self.nodes = [q2_nodes(v) for v in self.vertices]
        self.shape = tuple(len(n) for n in self.nodes)
        self.N = int(np.prod(self.shape))
        self.lam, self.mu = lame(E, nu)
        self.mats = [axis_matrices(v) for v in self.vertices]
        self.free = []  # per component, per axis: free node indices
        for a in range(3):
            per_axis = []
            for d in range(3):
                keep = np.ones(self.shape[d], bool)
                for ax, end in fixed.get(a, ()):
                    if ax == d:
                        keep[-1 if end else 0] = False
                per_axis.append(np.flatnonzero(keep))
            self.free.append(per_axis)
        self.sizes = [int(np.prod([len(f) for f in fa])) for fa in self.free]
        self.offsets = np.concatenate([[0], np.cumsum(self.sizes)])
        self._fact = {}
        self._eig = [self._eigen(a) for a in range(3)]

    @property
    def n_dofs(self) -> int:
        return int(self.offsets[-1])

    def _S(self, p, q, d, a, b):
        """Factor on axis d of G(p, q), rows free for component a, cols free for b."""
        key = (p, q, d, a, b)
        if key not in self._fact:
            S = axis_factor(self.mats[d], p, q, d)
            self._fact[key] = S[self.free[a][d]][:, self.free[b][d]].tocsr()
        return self._fact[key]

    def _G(self, p, q, a, b, U):
        for d in range(3):
            U = _mode(self._S(p, q, d, a, b), U, d)
        return U

    def matvec(self, x):
        x = np.asarray(x, float).ravel()
        U = [
            x[self.offsets[b] : self.offsets[b + 1]].reshape([len(f) for f in self.free[b]])
            for b in range(3)
        ]
        out = []
        for a in range(3):
            y = 0.0
            for b in range(3):
                if a == b:
                    y = y + (self.lam + self.mu) * self._G(a, a, a, a, U[a])
                    for k in range(3):
                        y = y + self.mu * self._G(k, k, a, a, U[a])
                else:
                    y = (
                        y
                        + self.lam * self._G(a, b, a, b, U[b])
                        + self.mu * self._G(b, a, a, b, U[b])
                    )
            out.append(np.asarray(y).ravel())
        return np.concatenate(out)

    def _eigen(self, a):
        """Fast diagonalisation of K_aa: per axis the generalised eigenpairs of the free
        A_d and M_d (V^T M V = I) and the diagonal sum_d c_ad l_d."""
        Vs, lam = [], []
        for d in range(3):
            f = self.free[a][d]
            A = self.mats[d]["A"][f][:, f].toarray()
            M = self.mats[d]["M"][f][:, f].toarray()
            w, V = sla.eigh(A, M)
            Vs.append(V)
            lam.append(w)
        c = [self.mu + (self.lam + self.mu) * (d == a) for d in range(3)]
        D = (
            c[0] * lam[0][:, None, None]
            + c[1] * lam[1][None, :, None]
            + c[2] * lam[2][None, None, :]
        )
        return Vs, 1.0 / D

    def precondition(self, r):
        r = np.asarray(r, float).ravel()
        out = []
        for a in range(3):
            Vs, Dinv = self._eig[a]
            R = r[self.offsets[a] : self.offsets[a + 1]].reshape(Dinv.shape)
            for d in range(3):
                R = _mode(Vs[d].T, R, d)
            R = R * Dinv
            for d in range(3):
                R = _mode(Vs[d], R, d)
            out.append(R.ravel())
        return np.concatenate(out)

    def free_index(self) -> np.ndarray:
        """Indices of the free dofs (in this class's order) in the full blocked vector."""
        out = []
        for a in range(3):
            ix, iy, iz = np.meshgrid(*self.free[a], indexing="ij")
            out.append(a * self.N + (ix * self.shape[1] + iy) * self.shape[2] + iz)
        return np.concatenate([o.ravel() for o in out])

    def solve(self, F_full, rtol: float = 1e-13, maxiter: int = 3000, direct: bool | None = None):
        """Displacement (3, nx, ny, nz) on the Q2 node grid for the full load vector F_full."""
        idx = self.free_index()
        f = F_full[idx]
        if direct is None:
            direct = self.n_dofs <= 15_000
        if direct:
            K = stiffness(self.vertices, *self._E_nu())[idx][:, idx].tocsc()
            x = spla.spsolve(K, f)
            self.iterations = 0
        else:
            A = spla.LinearOperator((self.n_dofs,) * 2, matvec=self.matvec, dtype=float)
            P = spla.LinearOperator((self.n_dofs,) * 2, matvec=self.precondition, dtype=float)
            count = [0]
            x, info = spla.cg(
                A,
                f,
                rtol=rtol,
                atol=0.0,
                maxiter=maxiter,
                M=P,
                callback=lambda xk: count.__setitem__(0, count[0] + 1),
            )
            self.iterations = count[0]
            if info != 0:
                raise RuntimeError(f"independent CG did not converge ({count[0]} iterations)")
        self.residual = float(np.linalg.norm(self.matvec(x) - f) / np.linalg.norm(f))
        if not self.residual < 1e-9:
            raise RuntimeError(f"independent solve: true residual {self.residual:.2e}")
        u = np.zeros(3 * self.N)
        u[idx] = x
        return u.reshape((3,) + self.shape)

    def _E_nu(self):
        nu = self.lam / (2 * (self.lam + self.mu))
        return 2 * self.mu * (1 + nu), nu


def basis_1d(nodes_vertices, x):
    """(node indices (m, 3), values (m, 3)) of the 1-D Q2 basis at x on the mesh with these
    vertices (points outside are clamped to the end cells)."""
    v = np.asarray(nodes_vertices, float)
    e = np.clip(np.searchsorted(v, x, side="right") - 1, 0, len(v) - 2)
    t = (x - v[e]) / (v[e + 1] - v[e])
    vals = np.column_stack([(1 - t) * (1 - 2 * t), 4 * t * (1 - t), t * (2 * t - 1)])
    return 2 * e[:, None] + np.arange(3)[None, :], vals


def evaluate_grid(vertices_xyz, U, points) -> np.ndarray:
    """Values (m, 3) at points (m, 3) of the Q2 field U (3, nx, ny, nz)."""
    points = np.asarray(points, float)
    (ix, vx), (iy, vy), (iz, vz) = (basis_1d(vertices_xyz[d], points[:, d]) for d in range(3))
    out = np.zeros((len(points), 3))
    for i in range(3):
        for j in range(3):
            for k in range(3):
                w = vx[:, i] * vy[:, j] * vz[:, k]
                out += w[:, None] * U[:, ix[:, i], iy[:, j], iz[:, k]].T
    return out
