"""Adaptive refinement of a user's mesh of triangles or tetrahedra (the ``refine``
method of mesh bodies): solve, compute the residual indicators of every load that is not
represented exactly (reference/estimator.py), mark by Dörfler's bulk criterion on their
sum (each load's indicators normalised by its total, so every load counts alike; at
least LEAST of the elements), bisect the marked elements (scikit-fem's longest-edge
bisection: nested meshes, the user's vertices keep their numbers) and repeat until the
estimate at the user's vertices is below ``reference.tol``, the steps are used up
(``max_refine`` times dim bisection steps) or the next mesh would pass the dof budget.
The parts are resolved on the user's mesh on every level (reference/meshparts.py).

The estimate is Richardson's over the levels, with the number of dofs N in place of
the mesh size (h_k = N_k^(-1/dim), ratio r_k = h_(k-1) / h_k): with the order p fitted to
the largest changes of the last levels (at most k + 1, the best a-priori order of the
displacement of degree-k elements), the error of the finest field u_k at a point is

    SAFETY * max(|u_k - u_(k-1)| / (r_k^p - 1),  |u_(k-1) - u_(k-2)| / ((r_(k-1)^p - 1) r_k^p))

(the second term: the previous pair's estimate carried forward, for points where the
last change happens to vanish; SAFETY = 3, as the graded method's). On nested meshes a
coarser level's field lies in the finest level's space, so both changes are kept as dof
vectors of the finest mesh and the estimate is exact to evaluate at any point. Measured
on 2-D holed and L-shaped plates against independent solves on the final mesh refined
twice (tests/test_adaptive.py does one): the largest estimate 3-10x the largest true
error at the user's vertices, and above the error at every vertex.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from harness.case.elasticity import densities, element_stiffness
from reference.estimator import doerfler, indicators
from reference.extrapolate import ORDER_RANGE, SAFETY
from reference.fem import Discretisation
from reference.locate import Locator
from reference.mesh import base_mesh
from reference.meshparts import UserMeshParts
from reference.problem import body_bbox, fixed_dofs, homogeneous_field, solve_mesh

THETA = 0.5          # Dörfler's bulk parameter: the marked elements carry this share of eta^2, ...
LEAST = 0.1          # ... and are at least this share of the elements: a step then adds >= ~25 %
# dofs (Dörfler's set alone added 2 % on a 10k-tet cylinder), and the estimate's
# 1 / (r^p - 1) does not blow a step's noise up (measured there, three steps, while the
# safety factor was 1.25: 53k dofs and a 1.7 % estimate without LEAST, 103k and 0.3 % with)
STEPS_PER_REFINE = {2: 2, 3: 3}   # bisection steps per [reference] max_refine: dim bisections
# of every element halve its size, so max_refine uniform refinements' worth of levels
MAX_DOFS = {2: 400_000, 3: 200_000}   # the finest level's dofs at most, ...
GROWTH = 1.0                          # ... or the user's mesh's own if larger: a 50k-tet mesh
# (214k dofs) is not refined (no estimate, as the verdict says): at 2x it took 18 min of AMG,
# against calibrate's 5-minute target for such a mesh
EXACT = 1e-9          # a change below this share of the largest displacement is rounding
FIT = 4               # changes the order is fitted to (a single ratio of two is noisy)
HIGHEST = {"P1": 2.0, "P2": 3.0}   # the observed order at most the a-priori best of the
# displacement, k + 1 for degree k (a faster first decay is the singularity being resolved)


@dataclass(frozen=True)
class Changes:
    """The last two changes between levels of each load, as dof vectors (ndof,) of the
    finest mesh (``d1`` = u_k - u_(k-1), ``d2`` = u_(k-1) - u_(k-2), zero when there
    are only two levels), and their weights ``coef`` (a1, a2), SAFETY included: the
    per-point estimate is max(a1 |d1(x)|, a2 |d2(x)|) (a plain |d1(x)| for a field
    represented exactly)."""
    d1: dict
    d2: dict
    coef: dict

    def at(self, locator: Locator, basis, points, load: str) -> np.ndarray:
        a1, a2 = self.coef[load]
        dim = points.shape[1]
        v = locator.evaluate(basis, np.column_stack([self.d1[load].reshape(-1, dim),
                                                     self.d2[load].reshape(-1, dim)]), points)
        e1, e2 = np.linalg.norm(v[:, :dim], axis=1), np.linalg.norm(v[:, dim:], axis=1)
        return np.maximum(a1 * e1, a2 * e2)

    def to_arrays(self, names) -> dict:
        return {"d1": np.stack([self.d1[n] for n in names]), "d2": np.stack([self.d2[n] for n in names]),
                "coef": np.array([self.coef[n] for n in names], float)}

    @classmethod
    def from_arrays(cls, names, arrays) -> "Changes | None":
        if "coef" not in arrays:
            return None
        return cls({n: arrays["d1"][i] for i, n in enumerate(names)},
                   {n: arrays["d2"][i] for i, n in enumerate(names)},
                   {n: tuple(arrays["coef"][i]) for i, n in enumerate(names)})


def n_dofs(mesh, order: str) -> int:
    """Vector dofs of a P1/P2 simplex mesh (P2: vertices and edge midpoints)."""
    dim = mesh.p.shape[0]
    ns = mesh.p.shape[1] + (0 if order == "P1" else (mesh.facets.shape[1] if dim == 2 else mesh.edges.shape[1]))
    return dim * ns


def fitted_order(changes, dofs, dim: int, highest: float = ORDER_RANGE[1]) -> float:
    """The order p (in h = N^(-1/dim)) of the largest changes between levels,
    c_j ~ K (h_(j-1)^p - h_j^p), fitted in log by least squares over the last FIT
    changes (dofs: the N of those levels and the one before), at most ``highest``;
    ORDER_RANGE's lowest, the most conservative, from a single change."""
    c = np.asarray(changes[-FIT:], float)
    if len(c) < 2:
        return ORDER_RANGE[0]
    h = np.asarray(dofs[-len(c) - 1:], float) ** (-1.0 / dim)
    p = np.linspace(ORDER_RANGE[0], highest, 401)
    res = np.log(c)[:, None] - np.log(h[:-1, None] ** p - h[1:, None] ** p)
    res -= res.mean(axis=0)
    return float(p[np.argmin((res ** 2).sum(axis=0))])


def coefficients(p: float, dofs, dim: int) -> tuple:
    """(a1, a2): the last and the previous change scaled to the finest level's error,
    h_k^p / (h_(k-1)^p - h_k^p) and h_k^p / (h_(k-2)^p - h_(k-1)^p) (0 with two levels)."""
    h = np.asarray(dofs[-3:], float) ** (-p / dim)       # h^p
    a1 = h[-1] / (h[-2] - h[-1])
    return a1, (h[-1] / (h[-3] - h[-2]) if len(h) == 3 else 0.0)


def _interpolate(coarse: Discretisation, fields: np.ndarray, fine: Discretisation) -> np.ndarray:
    """Coarse fields (ns_c, m) at the fine mesh's dof locations (ns_f, m): exact, the
    meshes being nested and the element the same."""
    return Locator(coarse.mesh).evaluate(coarse.basis, fields, fine.doflocs.T)


def _marked(case, d: Discretisation, U: dict, loads, parts) -> np.ndarray:
    """Dörfler's set for the sum of the loads' indicators, each normalised by its total."""
    cent = d.centroids()
    C, rho = element_stiffness(case.material, cent), densities(case.material, cent)
    bbox = body_bbox(case, d.mesh)
    fixed = {l.name: fixed_dofs(d, case, l, bbox, parts=parts) if l.constraints else np.zeros(0, np.int64)
             for l in loads}
    total = np.zeros(d.nelems)
    for eta2 in indicators(d, case, loads, U, C, rho, bbox, fixed, parts).values():
        if eta2.sum() > 0:
            total += eta2 / eta2.sum()
    return doerfler(total, THETA, LEAST)


def applies(case) -> bool:
    """Whether the ``refine`` reference of ``case`` refines adaptively: a mesh body of
    triangles or tetrahedra (boxes, rectangles and polygons keep reference/refine.py's
    uniform and graded refinement)."""
    return case.body.shape == "mesh" and case.reference.cell in ("tri", "tet")


def solve_adaptive(case, status=lambda msg: None, info: list | None = None):
    """(finest mesh, {load: dofs}, {load: relative estimate}, history rows, Changes or
    None with a single level)."""
    spec = case.reference
    mesh = base_mesh(case)
    nv0, dim = mesh.p.shape[1], case.dim
    names = [l.name for l in case.loads]
    d = Discretisation(mesh, spec.cell, spec.element)
    C0 = element_stiffness(case.material, d.centroids())
    solved = [l for l in case.loads if homogeneous_field(d, case, l, C0) is None]
    est = {n: (float("nan") if any(l.name == n for l in solved) else 0.0) for n in names}   # closed forms: exact
    parts = UserMeshParts(case, mesh)
    budget = max(MAX_DOFS[dim], int(GROWTH * d.ndof))
    steps = STEPS_PER_REFINE[dim] * spec.max_refine if solved else 0
    history, dofs, largest = [], [], {n: [] for n in names}
    prev = changes = None

    def probe(v):
        return np.linalg.norm(v[: nv0 * dim].reshape(nv0, dim), axis=1)
    for k in range(steps + 1):
        status(f"FEM adaptive level {k} ({d.ndof} dofs, {d.nelems} elements)")
        U = solve_mesh(case, d.mesh, info=info, disc=d, parts=parts)
        dofs.append(d.ndof)
        if prev is not None:
            d1, d2 = _changes(prev, d, U, names)
            coef = {}
            for n in names:
                scale = max(float(probe(U[n]).max()), 1e-300)
                e1, e2 = probe(d1[n]), probe(d2[n])
                largest[n].append(float(e1.max()))
                coef[n] = (1.0, 0.0) if e1.max() <= EXACT * scale else tuple(
                    SAFETY * a for a in coefficients(fitted_order(largest[n], dofs, dim, HIGHEST[spec.element]),
                                                     dofs, dim))
                est[n] = float(np.maximum(coef[n][0] * e1, coef[n][1] * e2).max() / scale)
            changes = Changes(d1, d2, coef)
        history.append(dict(n_dofs=int(d.ndof), **est))
        if k == steps or (k >= 1 and max(est.values()) < spec.tol):
            break
        finer = d.mesh.refined(_marked(case, d, U, solved, parts))
        if not np.allclose(finer.p[:, :nv0], mesh.p):
            raise RuntimeError("refinement renumbered the vertices")  # scikit-fem contract
        if n_dofs(finer, spec.element) > budget:
            status(f"FEM: the next adaptive level would exceed {budget} dofs; stopping")
            break
        prev = (d, U, changes.d1 if changes else {n: np.zeros_like(U[n]) for n in names})
        d = Discretisation(finer, spec.cell, spec.element)
    return d.mesh, U, est, history, changes


def _changes(prev, d: Discretisation, U: dict, names) -> tuple[dict, dict]:
    """({load: u_k - u_(k-1)}, {load: u_(k-1) - u_(k-2)}) on this level's mesh, from the
    previous level's (Discretisation, fields, changes)."""
    pd, pU, pD1 = prev
    dim = d.dim
    old = _interpolate(pd, np.column_stack([pU[n].reshape(-1, dim) for n in names]
                                           + [pD1[n].reshape(-1, dim) for n in names]), d)
    m = len(names) * dim
    return ({n: U[n] - old[:, i * dim:(i + 1) * dim].ravel() for i, n in enumerate(names)},
            {n: old[:, m + i * dim:m + (i + 1) * dim].ravel() for i, n in enumerate(names)})
