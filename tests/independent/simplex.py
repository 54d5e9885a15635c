"""An independent P2 solve of linear elasticity on a tetrahedral mesh nested in a user's mesh,
for the truth of the adaptive reference's estimate on rounded bodies
(tests/reference/test_loop.py): scikit-fem's own elasticity and load forms, its own
constraint sets and SuperLU (a pyamg-preconditioned CG when large); nothing goes through
reference/ or harness/.

A part is a box resolved on the user's mesh as the product defines it
(docs/reference-fem.md): a point belongs to it when the user's entity it lies on (the
vertices with a positive barycentric coordinate in its user tetrahedron) has all its
vertices in the box. A constraint holds every P2 dof at such a point; a traction acts on
the boundary facets whose vertices and centroid belong to the part."""

from __future__ import annotations

import numpy as np
import pyamg
import scipy.sparse.linalg as spla
import skfem
from scipy.spatial import cKDTree
from skfem.models.elasticity import lame_parameters, linear_elasticity

BARY = 1e-9  # a barycentric coordinate below this is zero (the point lies on a face)
NEAREST = 24  # user tetrahedra tried per point (nearest centroids)
DIRECT_MAX = 60_000  # free dofs up to which SuperLU solves (else AMG-preconditioned CG)


def closure(user: skfem.MeshTet, flag: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(n,) whether each point x (3, n) inside the user's mesh lies on a user entity whose
    vertices are all flagged (flag: (n_user_vertices,) bool)."""
    corners = user.p[:, user.t].transpose(2, 1, 0)  # ne, 4, 3
    inv = np.linalg.inv((corners[:, 1:] - corners[:, :1]).transpose(0, 2, 1))
    k = min(NEAREST, user.t.shape[1])
    _, cand = cKDTree(corners.mean(axis=1)).query(x.T, k=k)
    cand = cand.reshape(x.shape[1], k)
    rel = x.T[:, None, :] - corners[cand, 0]
    lam = np.einsum("nkij,nkj->nki", inv[cand], rel)
    lam = np.concatenate([1.0 - lam.sum(axis=2, keepdims=True), lam], axis=2)
    best = np.argmax(lam.min(axis=2), axis=1)
    rows = np.arange(x.shape[1])
    lam, elem = lam[rows, best], cand[rows, best]
    return np.all(flag[user.t[:, elem].T] | (lam < BARY), axis=1)


def part(user: skfem.MeshTet, lo, hi):
    """The point predicate x (3, n) -> (n,) of the box [lo, hi] resolved on ``user``."""
    lo, hi = np.asarray(lo, float)[:, None], np.asarray(hi, float)[:, None]
    flag = np.all((user.p >= lo) & (user.p <= hi), axis=0)
    return lambda x: closure(user, flag, np.asarray(x, float))


def solve(mesh: skfem.MeshTet, E: float, nu: float, clamp, loads) -> tuple:
    """(basis, {name: u}): P2 displacements on ``mesh`` clamped at the points of ``clamp``
    (a point predicate) under ``loads`` {name: (traction, gravity)}: a traction
    (predicate, vector) on the boundary facets of the predicate's part, a body force
    (a vector, density 1); either may be None. One factorisation for all of them."""
    b = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementTetP2()), intorder=4)
    K = skfem.asm(linear_elasticity(*lame_parameters(E, nu)), b)
    F = np.column_stack([_load(b, *pair) for pair in loads.values()])
    fixed = np.flatnonzero(clamp(b.doflocs))  # interleaved: dof 3 node + component
    free = np.setdiff1d(np.arange(b.N), fixed)
    A = K[free][:, free].tocsc()
    if len(free) <= DIRECT_MAX:
        x = spla.splu(A, permc_spec="COLAMD").solve(F[free])
    else:
        x = np.column_stack([_cg(A, F[free, i], b.doflocs[:, free]) for i in range(F.shape[1])])
    u = np.zeros_like(F)
    u[free] = x
    return b, {name: u[:, i] for i, name in enumerate(loads)}


def _load(b: skfem.Basis, traction, gravity) -> np.ndarray:
    """The load vector of a traction (predicate, vector) and a body force (vector)."""
    F = np.zeros(b.N)
    if gravity is not None:
        g = np.asarray(gravity, float)
        F += skfem.asm(skfem.LinearForm(lambda v, w: sum(g[i] * v[i] for i in range(3))), b)
    if traction is not None:
        on, t = traction[0], np.asarray(traction[1], float)
        mesh = b.mesh
        bf = mesh.boundary_facets()
        nodes = mesh.facets[:, bf]
        ok = on(mesh.p[:, nodes.ravel()]).reshape(nodes.shape).all(axis=0)
        ok &= on(mesh.p[:, nodes].mean(axis=1))
        fb = skfem.FacetBasis(mesh, b.elem, facets=bf[ok], intorder=4)
        F += skfem.asm(skfem.LinearForm(lambda v, w: sum(t[i] * v[i] for i in range(3))), fb)
    return F


def _cg(A, f, x) -> np.ndarray:
    """A^-1 f by CG preconditioned by smoothed aggregation with the rigid-body modes of
    the dofs at x (3, n) (interleaved components), to a relative residual of 1e-12."""
    comp = np.arange(A.shape[0]) % 3
    x = x - x.mean(axis=1, keepdims=True)
    B = np.zeros((A.shape[0], 6))
    for c in range(3):
        B[comp == c, c] = 1.0
    for m, (i, j) in enumerate(((0, 1), (1, 2), (0, 2))):
        B[comp == i, 3 + m] = -x[j, comp == i]
        B[comp == j, 3 + m] = x[i, comp == j]
    ml = pyamg.smoothed_aggregation_solver(A.tocsr(), B=B, max_coarse=2000)
    u, info = spla.cg(A, f, rtol=1e-12, atol=0.0, maxiter=4000, M=ml.aspreconditioner())
    if info != 0:
        raise RuntimeError(f"CG did not converge ({info})")
    return u


def at_vertices(b: skfem.Basis, u: np.ndarray, n: int) -> np.ndarray:
    """The displacement (n, 3) at the mesh's first n vertices."""
    return u[b.nodal_dofs[:, :n]].T
