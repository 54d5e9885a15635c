"""Adaptive refinement of a user's mesh of triangles or tetrahedra (the ``refine``
method of mesh bodies): solve, compute the residual indicators of every load that is not
represented exactly (reference/adaptive/estimator.py), mark by Dörfler's bulk criterion on their
sum (each load's indicators normalised by its total, so every load counts alike; at
least LEAST of the elements), bisect the marked elements (scikit-fem's longest-edge
bisection: nested meshes, the user's vertices keep their numbers) and repeat until the
estimate at the user's vertices is below ``reference.tol`` for every scored load (the
held-out ones, or all of a case that holds none out), the steps are used up (``max_refine``
times dim bisection steps) or the next mesh would pass the dof budget. The parts are
resolved on the user's mesh on every level (reference/adaptive/meshparts.py).

From ``max_refine = UNTIL_TOL`` (calibrate's default) the levels are not counted: they run
until tol or the dof cap TARGET_DOFS, deterministic (the same dofs every run: no clock),
and ``Stop`` records which ended them. Measured on a 1006-tet gmsh ellipsoid 0.4 x 0.2 x
0.14 m (nu 0.3, calibrate's end loads), each level's largest change at the user's vertices
against the 265k-dof level fits C (N^-a - 265k^-a) with a = 0.70-0.80 for the held-out
loads (the clamp's edge on the curved surface: about h^2.2): a true error of 0.6-1.1 % at
265k dofs, where the estimate is 1.1-1.7 % (1.4-1.8x; 1.2-3.8x on the coarser levels),
so its 1 % needs ~500k dofs. The same ellipsoid at nu 0.45 met tol at 600k dofs (held-out
estimates 0.69-0.93 %; 1.2-1.6 % at 266k). tests/reference/test_loop.py checks the
estimate against an independent finer solve (tests/independent/simplex.py).

The estimate is Richardson's over the levels (reference/adaptive/wide.py). A mesh no
refinement of fits in the dof budget (a 50k-tet cylinder: 214k dofs) gets its
levels i and j from coarser meshes of its body instead (reference/adaptive/coarse.py: a tensor
grid of the bounding box with COARSE of its vertices, the cells whose centroid lies
outside dropped), on which the user's own system is solved in the subspace of the
coarse fields interpolated into its space (its geometry, parts and loads exactly;
Galerkin orthogonality makes each the best approximation of the user's solution there).
Only the largest change follows the user's error (the coarse meshes' pointwise errors
have their own pattern), so the estimate is that bound, uniform over the points
(``Changes.uniform``). Measured against independent finer solves: a 2-D holed plate,
1.5-4x the largest true error (tests/reference/test_coarse.py); a 9k-tet cylinder (nu 0.45, sag,
tip, torsion, levels of 1.9k and 4.5k dofs, against the 103k-dof adaptive solve, whose
own error is not far below): 1.2-1.4x.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from harness.case.elasticity import densities, element_stiffness
from harness.errors import ModelError
from reference.adaptive.coarse import galerkin_solve, grid_mesh
from reference.adaptive.estimator import doerfler, indicators
from reference.adaptive.meshparts import UserMeshParts
from reference.adaptive.wide import (
    HIGHEST,
    WIDE,
    Changes,
    carry,
    n_dofs,
    prune,
    wide_changes,
)
from reference.fem import Discretisation
from reference.mesh import base_mesh
from reference.problem import (
    body_bbox,
    fixed_dofs,
    homogeneous_field,
    load_vector,
    solve_mesh,
    solve_system,
)

THETA = 0.5  # Dörfler's bulk parameter: the marked elements carry this share of eta^2, ...
LEAST = 0.1  # ... and are at least this share of the elements: a step then adds >= ~25 %
# dofs (Dörfler's set alone added 2 % on a 10k-tet cylinder), and the estimate's
# 1 / (r^p - 1) does not blow a step's noise up (there, three steps at a safety factor of
# 1.25: 53k dofs and a 1.7 % estimate without LEAST, 103k and 0.3 % with)
STEPS_PER_REFINE = {2: 2, 3: 3}  # bisection steps per [reference] max_refine: dim bisections
# of every element halve its size, so max_refine uniform refinements' worth of levels
MAX_DOFS = {2: 400_000, 3: 200_000}  # the finest level's dofs at most, ...
GROWTH = 1.0  # ... or the user's mesh's own if larger: a 50k-tet mesh
# (214k dofs) is not refined (at 2x it took 18 min of AMG, against calibrate's 5-minute
# target for such a mesh) but estimated from COARSE levels (below)
COARSE = (1 / (3 * WIDE**2), 1 / WIDE**2)  # a mesh no refinement of fits in the budget:
# the estimate's levels i and j are coarser meshes of its body with about these shares of
# its vertices (reference/adaptive/coarse.py; ~1/30 and ~1/10 of its dofs). Their Galerkin matrices
# couple dofs a cell further than a native stiffness (~465 nonzeros a row, ~5x), so at
# 1/4 of the vertices (72k dofs on the 50k-tet cylinder) the direct solve ran > 6 min
# and 5.7 GB; at 1/16, 20k dofs, ~20 s. A refinement adds at least ~25 % dofs:
GROWTH_MIN = 1.25
COARSE_MAX_DOFS = 25_000  # the finer coarse level has at most about these dofs (the shares shrink
# alike: a 200k-tet body's 1/10 level, 69k dofs and 32 M nonzeros, took ~190 s of its 5 clamp sets)
UNTIL_TOL = 100  # [reference] max_refine at or above this: the levels are not counted but
# end at tol on every scored load or at the dof cap TARGET_DOFS (calibrate's default), ...
TARGET_DOFS = {2: 400_000, 3: 600_000}  # ... the finest level's dofs at most (or the user's
# mesh's own if larger; the 1k-tet gmsh ellipsoid at nu 0.45: 12 levels, 1,107 s on a busy
# 2-core machine (375 s to the 266k-dof level), peak 8.0 GB, its solve's workers included), ...
TARGET_ROOM = WIDE  # ... a mesh is refined only when the cap leaves room for this growth
# (the estimate needs levels WIDE apart; a larger one is estimated from COARSE levels), and
# the levels end without marking where GROWTH_MIN more dofs would pass the cap (the last
# level's indicators: ~1 min and ~4.8 GB at 400k dofs). Marking as the counted levels: by
# Dörfler's set of every clamped load's indicators, LEAST at least (on the ellipsoid, marking
# by the held-out loads alone gave 8 % smaller held-out estimates at 262k dofs and 4-8x
# larger side states; LEAST 0.02 the same true error at 222k dofs as 0.1 at 265k, 36 % slower)


@dataclass(frozen=True)
class Stop:
    """Why the levels ended: ``reason`` "tol" (every scored load's estimate below tol),
    "cap" (the next level, ``next_dofs`` if made, would pass the dof cap ``cap``), "steps"
    (max_refine's bisection steps used), "single" (max_refine 0: one level, no estimate),
    "exact" (every load in closed form) or "coarse" (a mesh too large to refine, estimated
    from coarser meshes of its body); ``n_dofs`` the finest level's dofs."""

    reason: str
    n_dofs: int
    cap: int
    next_dofs: int = 0

    def describe(self) -> str:
        """The reason as a clause of a sentence."""
        n, cap = f"{self.n_dofs:,}", f"{self.cap:,}"
        return {
            "tol": f"every scored load met tol at {n} dofs",
            "cap": f"stopped at the dof cap: {n} dofs, the next level would have "
            + (f"{self.next_dofs:,}" if self.next_dofs else f"at least {GROWTH_MIN:g}x as many")
            + f" (cap {cap})",
            "steps": f"max_refine's bisection steps used at {n} dofs (cap {cap})",
            "single": "one level (max_refine 0): no estimate",
            "exact": "every load in closed form",
            "coarse": f"the mesh's {n} dofs are too many to refine within the cap of {cap}: "
            "estimated from coarser meshes of its body",
        }[self.reason]

    def to_arrays(self) -> dict:
        return {
            "stop_reason": np.array(self.reason),
            "stop_dofs": np.array([self.n_dofs, self.cap, self.next_dofs], np.int64),
        }

    @classmethod
    def from_arrays(cls, arrays) -> "Stop | None":
        if "stop_reason" not in arrays:
            return None
        n, cap, nxt = (int(v) for v in arrays["stop_dofs"])
        return cls(str(arrays["stop_reason"]), n, cap, nxt)


def _marked(case, d: Discretisation, U: dict, loads, parts) -> tuple[np.ndarray, np.ndarray]:
    """(Dörfler's set, the sum of the loads' indicators, each normalised by its total)."""
    cent = d.centroids()
    C, rho = element_stiffness(case.material, cent), densities(case.material, cent)
    bbox = body_bbox(case, d.mesh)
    fixed = {
        l.name: fixed_dofs(d, case, l, bbox, parts=parts)
        if l.constraints
        else np.zeros(0, np.int64)
        for l in loads
    }
    total = np.zeros(d.nelems)
    for eta2 in indicators(d, case, loads, U, C, rho, bbox, fixed, parts).values():
        if eta2.sum() > 0:
            total += eta2 / eta2.sum()
    return doerfler(total, THETA, LEAST), total


def _within_cap(mesh, marked: np.ndarray, total: np.ndarray, cap: int, element: str):
    """The finest refinement of ``mesh`` within ``cap`` dofs that refines the elements of
    ``marked`` with the largest indicators ``total`` (a prefix in their order, found by
    bisection: refinement closes conformingly, so more marked elements never give fewer
    dofs); None when none adds GROWTH_MIN of the dofs (the levels then end at the cap)."""
    order = marked[np.argsort(-total[marked], kind="stable")]
    lo, hi, best = 1, len(order) - 1, None
    while lo <= hi:
        m = (lo + hi) // 2
        finer = mesh.refined(order[:m])
        if n_dofs(finer, element) <= cap:
            best, lo = finer, m + 1
        else:
            hi = m - 1
    return best


def applies(case) -> bool:
    """Whether the ``refine`` reference of ``case`` refines adaptively: a mesh body of
    triangles or tetrahedra (boxes, rectangles and polygons keep reference/adaptive/refine.py's
    uniform and graded refinement)."""
    return case.body.shape == "mesh" and case.reference.cell in ("tri", "tet")


def scored_loads(case) -> tuple[str, ...]:
    """The loads whose estimates the levels drive below ``reference.tol``: the held-out
    and validation ones this case solves (what scores a model and what accepts a fit), or
    every load of a case that holds none of them out (a sub-case of some of its loads). Training
    states are judged against the rules' errors on them instead
    (harness/scoring.py ``unresolved_training``)."""
    names = tuple(l.name for l in case.loads)
    scored = tuple(case.heldout) + tuple(case.validation)
    return tuple(n for n in scored if n in names) or names


@dataclass(frozen=True)
class Plan:
    """How one adaptive solve refines: at most ``steps`` bisection steps and ``cap`` dofs; a
    mesh is refined only when the cap leaves room for a growth of ``room``, else estimated
    from coarser meshes of its body; ``ahead``: the levels end before marking when the
    least growth of a step (GROWTH_MIN) would pass the cap."""

    steps: int
    cap: int
    room: float
    ahead: bool = False


def plan(case, ndof: int) -> Plan:
    """The Plan of ``case`` on a user's mesh of ``ndof`` dofs: max_refine below UNTIL_TOL
    counts the levels (max_refine x dim bisection steps within MAX_DOFS); from UNTIL_TOL
    the levels run until tol on every scored load or TARGET_DOFS (either cap, or the
    user's mesh's own dofs if more)."""
    dim, levels = case.dim, case.reference.max_refine
    steps = STEPS_PER_REFINE[dim] * levels
    if levels >= UNTIL_TOL:
        cap = max(TARGET_DOFS[dim], int(GROWTH * ndof))
        return Plan(steps, cap, TARGET_ROOM, ahead=True)
    return Plan(steps, max(MAX_DOFS[dim], int(GROWTH * ndof)), GROWTH_MIN)


def solve_adaptive(case, status=lambda msg: None, records: list | None = None):
    """(finest mesh, {load: dofs}, {load: relative estimate}, history rows, Changes or
    None with a single level, Stop): levels until every scored load's estimate is below
    tol (:func:`scored_loads`), the steps are used up or the next level would pass the
    dof cap (:func:`plan`)."""
    spec = case.reference
    mesh = base_mesh(case)
    d = Discretisation(mesh, spec.cell, spec.element)
    C0 = element_stiffness(case.material, d.centroids())
    solved = [l for l in case.loads if homogeneous_field(d, case, l, C0) is None]
    # closed forms: exact
    need = {l.name for l in solved}
    est = {l.name: (float("nan") if l.name in need else 0.0) for l in case.loads}
    parts = UserMeshParts(case, mesh)
    how = plan(case, d.ndof)
    if not solved:
        how = dataclasses.replace(how, steps=0)
    if how.steps and how.room * d.ndof > how.cap:  # too large to refine: coarser meshes of its body
        status(
            f"FEM on the mesh ({d.ndof} dofs, {d.nelems} elements; too large to refine within "
            f"{how.cap} dofs: the estimate comes from coarser meshes of its body)"
        )
        return _coarse_only(case, d, parts, est, how.cap, status, records)
    return _refine_levels(case, d, solved, parts, est, how, status, records)


def _probe(nv0: int, dim: int):
    """|v| at the user's vertices (the first nv0 of every level) of a dof vector v."""
    return lambda v: np.linalg.norm(v[: nv0 * dim].reshape(nv0, dim), axis=1)


def _coarse_only(case, d: Discretisation, parts, est: dict, cap: int, status, records):
    """solve_adaptive's answer for a mesh too large to refine: its own solve, estimated
    from the COARSE levels (a uniform bound)."""
    names = [l.name for l in case.loads]
    probe = _probe(d.mesh.p.shape[1], case.dim)
    U, kept = _with_coarse(case, d, parts, status, records)
    changes = None
    if kept:
        highest = HIGHEST[case.reference.element]
        changes = wide_changes(kept, d.ndof, U, names, case.dim, highest, probe, est)
        changes = Changes(
            changes.d1,
            changes.d2,
            changes.coef,
            {n: est[n] * max(float(probe(U[n]).max()), 1e-300) for n in names},
        )
    history = [dict(n_dofs=int(d.ndof), **est)]
    return d.mesh, U, est, history, changes, Stop("coarse", int(d.ndof), cap)


def _refine_levels(case, d: Discretisation, solved, parts, est: dict, how: Plan, status, records):
    """solve_adaptive's levels from the user's mesh (d), as ``how`` plans them."""
    spec, dim = case.reference, case.dim
    steps, cap = how.steps, how.cap
    names = [l.name for l in case.loads]
    nv0 = d.mesh.p.shape[1]
    p0 = d.mesh.p.copy()
    probe = _probe(nv0, dim)
    targets = scored_loads(case)
    history, kept, changes = [], [], None  # kept: earlier levels (dofs, {load: field})
    for k in range(steps + 1):
        status(f"FEM adaptive level {k} ({d.ndof} dofs, {d.nelems} elements)")
        U = solve_mesh(case, d.mesh, records=records, disc=d, parts=parts)
        if kept:
            changes = wide_changes(kept, d.ndof, U, names, dim, HIGHEST[spec.element], probe, est)
        history.append(dict(n_dofs=int(d.ndof), **est))
        if k >= 1 and all(est[n] < spec.tol for n in targets):
            return d.mesh, U, est, history, changes, Stop("tol", int(d.ndof), cap)
        if k == steps:
            reason = "steps" if steps else ("single" if solved else "exact")
            return d.mesh, U, est, history, changes, Stop(reason, int(d.ndof), cap)
        if how.ahead and GROWTH_MIN * d.ndof > cap:
            status(f"FEM: a next adaptive level would exceed {cap} dofs; stopping")
            return d.mesh, U, est, history, changes, Stop("cap", int(d.ndof), cap)
        marked, total = _marked(case, d, U, solved, parts)
        finer = d.mesh.refined(marked)
        if how.ahead and n_dofs(finer, spec.element) > cap:  # the largest indicators that fit
            part = _within_cap(d.mesh, marked, total, cap, spec.element)
            if part is not None and n_dofs(part, spec.element) >= GROWTH_MIN * d.ndof:
                finer = part
        if not np.allclose(finer.p[:, :nv0], p0):
            raise RuntimeError("refinement renumbered the vertices")  # scikit-fem contract
        if n_dofs(finer, spec.element) > cap:
            status(f"FEM: the next adaptive level would exceed {cap} dofs; stopping")
            stop = Stop("cap", int(d.ndof), cap, n_dofs(finer, spec.element))
            return d.mesh, U, est, history, changes, stop
        kept = prune(kept + [(d.ndof, U)])
        fd = Discretisation(finer, spec.cell, spec.element)
        kept = carry(kept, d, fd, [l.name for l in solved])  # closed forms: no change
        d = fd
    raise AssertionError("unreachable: the last level returns")


def _with_coarse(case, d: Discretisation, parts, status, records):
    """({load: dofs} on d's mesh, [(dofs, {load: field at d's dofs})] of the COARSE
    levels): d's system assembled once, solved, and solved again in the subspaces of the
    coarser meshes of its body (reference/adaptive/coarse.py: its geometry, parts and loads
    exactly); no coarse level when a coarse mesh cannot be made."""
    spec = case.reference
    cent = d.centroids()
    C, rho = element_stiffness(case.material, cent), densities(case.material, cent)
    bbox = body_bbox(case, d.mesh)
    exact = {l.name: u for l in case.loads if (u := homogeneous_field(d, case, l, C)) is not None}
    chosen = [l for l in case.loads if l.name not in exact]
    fixed = {l.name: fixed_dofs(d, case, l, bbox, parts=parts) for l in chosen}
    F = {l.name: load_vector(d, case, l, bbox, rho, parts=parts) for l in chosen}
    K = d.stiffness(C)
    U = {**solve_system(K, F, fixed, spec.solver, d, records=records), **exact}
    kept = []
    shrink = min(1.0, COARSE_MAX_DOFS / (COARSE[-1] * d.ndof))
    for share in COARSE:
        cm = grid_mesh(d.mesh, share * shrink)
        if cm is None:
            return U, []
        cd = Discretisation(cm, spec.cell, spec.element)
        status(f"FEM coarse level for the estimate ({cd.ndof} dofs, {cd.nelems} elements)")
        try:
            kept.append(
                (cd.ndof, {**galerkin_solve(K, F, fixed, spec.solver, cd, d, records), **exact})
            )
        except ModelError as exc:  # e.g. a grid too coarse for the clamp to leave it a field
            status(f"FEM: no coarse level ({exc.message}); no estimate")
            return U, []
    return U, kept
