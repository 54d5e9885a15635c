"""An independent 3-D reference for the tests (and `springbench bench reference`): the
shear of a box (face z = 0 clamped, traction s along x on z = c) solved on a quarter
of the box with its own Q2 tensor-product assembly, its own graded mesh, its own solver,
point evaluation and Richardson extrapolation. Nothing here goes through reference/ or
harness/.

Symmetry: reflecting y about the middle maps the problem to itself (u_y odd, so u_y = 0
on the plane); reflecting x maps the load to its negative, so the solution is
antisymmetric (u_y = u_z = 0 on the plane x = a/2). The quarter [0, a/2] x [0, b/2] x
[0, c] with those conditions is the whole problem at a quarter of the unknowns.

Assembly (Kronecker). With a(u, v) = int lambda div u div v + 2 mu eps(u) : eps(v) and
2 eps(u) : eps(v) = sum_ij d_i u_j d_i v_j + d_j u_i d_i v_j, the block of test
component a and trial component b is

    K_ab = lambda G(a, b) + mu G(b, a) + delta_ab mu (G(x, x) + G(y, y) + G(z, z)),
    G(p, q)[i, j] = int d_p phi_i d_q phi_j     (i: test node, j: trial node).

On a tensor mesh of boxes with tensor-product Q2 basis phi_i = X_i(x) Y_i(y) Z_i(z),
G(p, q) = S_x (x) S_y (x) S_z (Kronecker), where per axis d S_d is the global 1-D matrix
A_d = int X' X' if d = p = q, B_d = int X'_i X_j if d = p != q, B_d^T if d = q != p, and
M_d = int X X otherwise. The 1-D element matrices of the quadratic Lagrange basis on
[0, h] (nodes 0, h/2, h) are exact rationals (below). Nodes are numbered
lexicographically with x slowest (index = (ix ny + iy) nz + iz) and the three
components are blocked: dof = component * N + node. The traction s e_x on z = c is
s (m_x (x) m_y (x) e_last) in the x block, m_d = int X_i.

Each Dirichlet condition fixes a component on a whole plane, so every component's free
dofs are a tensor product of per-axis sets: K on them is still a sum of Kronecker
products, applied matrix-free; its diagonal blocks K_aa = sum_d (mu + (lambda + mu)
delta_ad) A_d (x) M (x) M (A_d in position d) are inverted exactly by fast
diagonalisation (A_d V = M_d V diag(l_d) per axis): block-Jacobi-preconditioned CG, about
50 iterations for rtol 1e-13 at any size (true residual, checked, near 1e-10 at a million
dofs). ``quarter_shear_skfem``: the first version's scikit-fem assembly, a cross-check.

Mesh: power grading (beta = 2.5) towards the faces x = 0, y = 0, z = 0 and z = c only
(the product grades with beta = 3 towards every face). ``knot = 0.75`` puts the thirds of
the sides on nodes of every level (``extrapolated_shear``): on the sec6 cube's shear the
order is then 2.55-2.57 at n = 12..32 (edges of the loaded face; 3.0-3.1 elsewhere), the
extrapolant of n = 16, 20, 24 within 1e-6 of max |u| of that of n = 24, 28, 32.
``long_axes`` (a 10:1 box): ``quarter_mesh``. ``extrapolate_levels``' change is blind at
the point that fixes the order (both extrapolants agree there by construction).
"""

from __future__ import annotations

from fractions import Fraction as _F

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

# -- exact 1-D element matrices of the Q2 (quadratic Lagrange) basis on [0, h] -----------
# N0 = (1 - t)(1 - 2t), N1 = 4t(1 - t), N2 = t(2t - 1), t = x / h
ELEM_M = [[_F(4, 30), _F(2, 30), _F(-1, 30)],          # int N_i N_j dx / h
          [_F(2, 30), _F(16, 30), _F(2, 30)],
          [_F(-1, 30), _F(2, 30), _F(4, 30)]]
ELEM_A = [[_F(7, 3), _F(-8, 3), _F(1, 3)],             # int N_i' N_j' dx * h
          [_F(-8, 3), _F(16, 3), _F(-8, 3)],
          [_F(1, 3), _F(-8, 3), _F(7, 3)]]
ELEM_B = [[_F(-3, 6), _F(-4, 6), _F(1, 6)],            # int N_i' N_j dx (h-free)
          [_F(4, 6), _F(0), _F(-4, 6)],
          [_F(-1, 6), _F(4, 6), _F(3, 6)]]
ELEM_m = [_F(1, 6), _F(4, 6), _F(1, 6)]                 # int N_i dx / h

_M, _A, _B, _m = (np.array(e, float) for e in (ELEM_M, ELEM_A, ELEM_B, ELEM_m))


def lame(E: float, nu: float) -> tuple[float, float]:
    return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))


def q2_nodes(vertices) -> np.ndarray:
    """The Q2 nodes of a 1-D mesh: the vertices and the cell midpoints, in order."""
    v = np.asarray(vertices, float)
    return np.insert(v, np.arange(1, len(v)), 0.5 * (v[:-1] + v[1:]))


def axis_matrices(vertices) -> dict:
    """Global 1-D Q2 matrices of a mesh with these vertices: M, A, B (B[i, j] = int X_i' X_j),
    the load vector m (int X_i) as sparse CSR / dense."""
    v = np.asarray(vertices, float)
    h = np.diff(v)
    ne = len(h)
    nodes = 2 * np.arange(ne)[:, None] + np.arange(3)[None, :]            # (ne, 3)
    rows = np.repeat(nodes, 3, axis=1).ravel()
    cols = np.tile(nodes, (1, 3)).ravel()
    n = 2 * ne + 1

    def glob(elem, scale):
        data = (scale[:, None, None] * elem[None]).ravel()
        return sp.csr_matrix((data, (rows, cols)), shape=(n, n))

    m = np.zeros(n)
    np.add.at(m, nodes, h[:, None] * _m[None])
    return dict(M=glob(_M, h), A=glob(_A, 1.0 / h), B=glob(_B, np.ones(ne)), m=m)


def _factor(mats, p, q, d):
    if d == p and d == q:
        return mats["A"]
    if d == p:
        return mats["B"]
    if d == q:
        return mats["B"].T.tocsr()
    return mats["M"]


def stiffness(vertices_xyz, E: float, nu: float) -> sp.csr_matrix:
    """The full (unconstrained) Q2 stiffness on the tensor mesh, components blocked,
    assembled with scipy.sparse.kron."""
    lam, mu = lame(E, nu)
    mats = [axis_matrices(v) for v in vertices_xyz]

    def G(p, q):
        return sp.kron(sp.kron(_factor(mats[0], p, q, 0), _factor(mats[1], p, q, 1)),
                       _factor(mats[2], p, q, 2), format="csr")

    L = G(0, 0) + G(1, 1) + G(2, 2)
    blocks = [[None] * 3 for _ in range(3)]
    for a in range(3):
        for b in range(3):
            K = lam * G(a, b) + mu * G(b, a)
            if a == b:
                K = K + mu * L
            blocks[a][b] = K
    return sp.bmat(blocks, format="csr")


def face_load(vertices_xyz, axis: int, end: int, vector) -> np.ndarray:
    """Load vector (3 N,) of a constant traction ``vector`` on the face axis = end
    (0: lower, 1: upper) of the box: per component t_a (x) of m_d on the other axes and
    the unit vector of the face's node on ``axis``."""
    mats = [axis_matrices(v) for v in vertices_xyz]
    parts = []
    for d in range(3):
        if d == axis:
            e = np.zeros(len(mats[d]["m"]))
            e[-1 if end else 0] = 1.0
            parts.append(e)
        else:
            parts.append(mats[d]["m"])
    f = np.kron(np.kron(parts[0], parts[1]), parts[2])
    return np.concatenate([t * f for t in vector])


# -- the constrained problem, matrix-free ----------------------------------------------

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
        self.free = []                          # per component, per axis: free node indices
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
            S = _factor(self.mats[d], p, q, d)
            self._fact[key] = S[self.free[a][d]][:, self.free[b][d]].tocsr()
        return self._fact[key]

    def _G(self, p, q, a, b, U):
        for d in range(3):
            U = _mode(self._S(p, q, d, a, b), U, d)
        return U

    def matvec(self, x):
        x = np.asarray(x, float).ravel()
        U = [x[self.offsets[b]:self.offsets[b + 1]].reshape([len(f) for f in self.free[b]]) for b in range(3)]
        out = []
        for a in range(3):
            y = 0.0
            for b in range(3):
                if a == b:
                    y = y + (self.lam + self.mu) * self._G(a, a, a, a, U[a])
                    for k in range(3):
                        y = y + self.mu * self._G(k, k, a, a, U[a])
                else:
                    y = y + self.lam * self._G(a, b, a, b, U[b]) + self.mu * self._G(b, a, a, b, U[b])
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
        D = (c[0] * lam[0][:, None, None] + c[1] * lam[1][None, :, None] + c[2] * lam[2][None, None, :])
        return Vs, 1.0 / D

    def precondition(self, r):
        r = np.asarray(r, float).ravel()
        out = []
        for a in range(3):
            Vs, Dinv = self._eig[a]
            R = r[self.offsets[a]:self.offsets[a + 1]].reshape(Dinv.shape)
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
            x, info = spla.cg(A, f, rtol=rtol, atol=0.0, maxiter=maxiter, M=P,
                              callback=lambda xk: count.__setitem__(0, count[0] + 1))
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


# -- the quarter shear ------------------------------------------------------------------

def _half_axis(length: float, mirrored: bool, n: int, beta: float, knot=None, reach=None) -> np.ndarray:
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
        x = w * s ** beta
    else:
        sk, xk = knot
        if abs(n * sk - round(n * sk)) > 1e-9:
            raise ValueError(f"n = {n}: n * {sk} must be an integer to put the knot on a node")
        x = np.where(s <= sk, xk * (np.minimum(s, sk) / sk) ** beta, xk + (w - xk) * (s - sk) / (1 - sk))
    return np.concatenate([x, length - x[::-1][1:]]) if mirrored else x


def _long_axis(length, mirrored, n, beta, knot, reach):
    """s in [0, s_k] -> [0, reach] by the power law, [s_k, s_k + 1/2] exponentially (slope
    continuous) to x_k, [s_k + 1/2, 3/2] uniformly to the rest: n / 2 more cells."""
    from scipy.optimize import brentq
    w = length / 2 if mirrored else length
    sk, xk = knot
    if abs(n * sk - round(n * sk)) > 1e-9 or n % 4:
        raise ValueError(f"n = {n}: n * {sk} and n / 4 must be integers (knot and segments on nodes)")
    g, span = reach, 0.5    # slopes at s_k: beta g / s_k = (xk - g) k / ((e^k - 1) span)
    target = beta * g * span / (sk * (xk - g))
    k = 0.0 if abs(target - 1) < 1e-12 else brentq(lambda k: k / np.expm1(k) - target if k else 1 - target, -60, 60)
    s = np.linspace(0.0, 1.0 + span, int(round(n * (1 + span))) + 1)
    t = np.clip((s - sk) / span, 0.0, 1.0)
    grow = g + (xk - g) * (np.expm1(k * t) / np.expm1(k) if k else t)
    x = np.where(s <= sk, g * (np.minimum(s, sk) / sk) ** beta,
                 np.where(s <= sk + span, grow, xk + (w - xk) * (s - sk - span) / (1 - sk)))
    x[-1] = w
    return np.concatenate([x, length - x[::-1][1:]]) if mirrored else x


def quarter_mesh(size, n: int, beta: float = 2.5, knot: float | None = None, long_axes: bool = False):
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
    return [_half_axis(a / 2, False, n, beta, k(a), reach), _half_axis(b / 2, False, n, beta, k(b), reach),
            _half_axis(c, True, n, beta, k(c), reach)]


QUARTER_FIXED = {0: [(2, 0)], 1: [(2, 0), (1, 1), (0, 1)], 2: [(2, 0), (0, 1)]}


def quarter_dofs(n: int) -> int:
    return 3 * (2 * n + 1) ** 2 * (4 * n + 1)


def quarter_shear_field(size, E, nu, s, n, beta: float = 2.5, knot: float | None = None,
                        long_axes: bool = False, **solve_kw):
    """(vertices, U (3, nx, ny, nz), problem) of the quarter shear at n."""
    verts = quarter_mesh(size, n, beta, knot, long_axes)
    prob = BoxProblem(verts, E, nu, QUARTER_FIXED)
    F = face_load(verts, 2, 1, [s, 0.0, 0.0])
    return verts, prob.solve(F, **solve_kw), prob


def quarter_shear(size, E: float, nu: float, s: float, n: int, points, beta: float = 2.5,
                  knot: float | None = None, **solve_kw) -> np.ndarray:
    """u (m, 3) at points (m, 3) of the full box [0, a] x [0, b] x [0, c] (mirrored into
    the quarter), Q2 hexahedra, n cells per graded half-axis in x and y, 2 n in z."""
    verts, U, _ = quarter_shear_field(size, E, nu, s, n, beta, knot, **solve_kw)
    q, flip = _mirror(np.asarray(points, float), size)
    return _signs(evaluate_grid(verts, U, q), flip)


def _mirror(points, size):
    a, b, _ = size
    q = points.copy()
    sx, sy = q[:, 0] > a / 2, q[:, 1] > b / 2
    q[sx, 0] = a - q[sx, 0]
    q[sy, 1] = b - q[sy, 1]
    return q, (sx, sy)


def _signs(vals, flip):
    sx, sy = flip
    vals = vals.copy()
    vals[sy, 1] *= -1
    vals[sx, 1:] *= -1
    return vals


# -- the first version's scikit-fem assembly, kept as a cross-check ---------------------

def quarter_shear_skfem(size, E: float, nu: float, s: float, n: int, points, beta: float = 2.5) -> np.ndarray:
    """The same discrete problem as ``quarter_shear`` assembled by scikit-fem's own
    elasticity forms (slow: for small n only), solved directly."""
    import skfem
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    class _Mapping(skfem.MappingIsoparametric):
        def invF(self, x, tind=None, newton_max_iters=50, newton_tol=1e-12):
            return super().invF(x, tind=tind, newton_max_iters=newton_max_iters, newton_tol=1e-13)

    a, b, c = size
    mesh = skfem.MeshHex.init_tensor(*quarter_mesh(size, n, beta))
    mapping = _Mapping(mesh, mesh.elem(), mesh.bndelem)
    e = skfem.ElementVector(skfem.ElementHex2())
    basis = skfem.Basis(mesh, e, mapping=mapping, intorder=4)
    K = skfem.asm(linear_elasticity(*lame_parameters(E, nu)), basis)
    top = mesh.facets_satisfying(lambda x: np.isclose(x[2], c), boundaries_only=True)
    fb = skfem.FacetBasis(mesh, e, facets=top, mapping=mapping, intorder=4)
    F = skfem.asm(skfem.LinearForm(lambda v, w: s * np.asarray(v)[0]), fb)     # t . v, t = s e_x
    D = basis.get_dofs(lambda x: np.isclose(x[2], 0.0)).all()
    Dy = basis.get_dofs(lambda x: np.isclose(x[1], b / 2)).all("u^2")
    Dx = basis.get_dofs(lambda x: np.isclose(x[0], a / 2)).all(["u^2", "u^3"])
    fixed = np.unique(np.concatenate([D, Dy, Dx]))
    u = np.zeros(K.shape[0])
    free = np.setdiff1d(np.arange(K.shape[0]), fixed)
    u[free] = spla.spsolve(K[free][:, free].tocsc(), F[free])
    q, flip = _mirror(np.asarray(points, float), size)
    vals = basis.probes(q.T) @ u          # component-major: all u_x, then u_y, then u_z
    m = len(q)
    return _signs(np.column_stack([vals[:m], vals[m:2 * m], vals[2 * m:]]), flip)


# -- levels and Richardson extrapolation -----------------------------------------------

def shear_levels(size, E, nu, s, points, levels, beta: float = 2.5, knot: float | None = None, status=None,
                 long_axes: bool = False):
    """[(n, u (m, 3), n_dofs, seconds, CG iterations)] of the quarter shear at each level."""
    import time
    out = []
    for n in levels:
        t0 = time.perf_counter()
        verts, U, prob = quarter_shear_field(size, E, nu, s, n, beta, knot, long_axes)
        q, flip = _mirror(np.asarray(points, float), size)
        u = _signs(evaluate_grid(verts, U, q), flip)
        out.append((n, u, prob.n_dofs, time.perf_counter() - t0, prob.iterations))
        if status:
            status(out[-1])
    return out


def extrapolated_shear(size, E, nu, s, points, levels=(6, 8, 10), beta: float = 2.5, knot: float | None = None,
                       long_axes: bool = False):
    """(extrapolated u (m, 3), its estimate (largest change of the extrapolant between the
    last two pairs of levels, relative to max |u|), the observed order). ``knot`` (e.g.
    0.75, every n a multiple of 4): the thirds of the sides are nodes of every level, so
    the convergence is regular (without it the points move within their cells and the
    order on the sec6 cube's 4 x 4 x 4 grid wanders between 1 and 4; with it, 2.56)."""
    vals = [u for _, u, *_ in shear_levels(size, E, nu, s, points, levels, beta, knot, long_axes=long_axes)]
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
    f = lambda p: (h0 ** p - h1 ** p) / (h1 ** p - h2 ** p) - target   # noqa: E731 - increasing in p
    return float(brentq(f, 0.1, 10.0))


def _richardson(coarse, fine, hc, hf, p):
    return fine + (fine - coarse) / ((hc / hf) ** p - 1.0)
