"""The FEM problem of a case on one mesh: constraints, load vectors, the constrained
solves (loads that share constraints share one factorisation)."""

from __future__ import annotations

import dataclasses
import functools
import time

import numpy as np

from harness.case.elasticity import densities, element_stiffness
from harness.case.linear_states import linear_closed_form
from harness.case.loadsets import stress_field, stress_tensor
from harness.case.parts import geometric_tol, part_predicate
from harness.errors import ModelError
from reference.fem import Discretisation
from reference.lattice import Lattice
from reference.mirror import Mirror, plane_dofs
from reference.solvers import linearfield, sparse, tensorpre, tensorsolve, twolevel
from reference.solvers.plan import System, choose_plan
from reference.solvers.record import SolveRecord
from reference.solvers.sets import SetSolve, Shared, solve_sets


def body_bbox(case, mesh) -> tuple[np.ndarray, np.ndarray]:
    if case.body.shape == "mesh":
        return mesh.p.min(axis=1), mesh.p.max(axis=1)
    return case.body.bbox()


def predicate(case, name: str, bbox, parts=None):
    """The part's point predicate: harness.case.parts', or ``parts(name, bbox)`` when given
    (reference/adaptive/meshparts.py: a mesh body's parts resolved on the user's mesh)."""
    return part_predicate(name, bbox, case.body.parts) if parts is None else parts(name, bbox)


def fixed_dofs(
    d: Discretisation, case, load, bbox, mirror: Mirror = Mirror(), parts=None
) -> np.ndarray:
    """The load's constrained dofs (and, on a cut box, the cut planes' dofs). A part may
    miss a cut box when its mirror image is in it."""
    out = (
        [plane_dofs(d.doflocs, 0.5 * (bbox[0] + bbox[1]), mirror, geometric_tol(bbox))]
        if mirror
        else []
    )
    for c in load.constraints:
        dofs = d.part_dofs(predicate(case, c.part, bbox, parts), c.components)
        if len(dofs) == 0 and mirror:
            continue
        if len(dofs) == 0:
            raise ModelError(
                f"load case '{load.name}': constraint part '{c.part}' contains no mesh node",
                file=str(case.path),
                fix="enlarge the part or refine the mesh",
            )
        out.append(dofs)
    fixed = np.unique(np.concatenate(out))
    try:
        d.check_rigid(fixed, load.name)
    except ModelError as exc:
        raise ModelError(exc.message, file=str(case.path), fix=exc.fix) from None
    return fixed


def load_stress(load):
    """The stress of a stress load as Discretisation.stress_load takes it: a constant
    tensor (dim, dim), or for a linear field (``load.stress_gradient``) the function
    x (dim, ...) -> (dim, dim, ...)."""
    if load.stress_gradient is None:
        return stress_tensor(load.stress)
    return lambda x: np.moveaxis(stress_field(load, np.moveaxis(x, 0, -1)), (-2, -1), (0, 1))


def load_vector(
    d: Discretisation, case, load, bbox, rho: np.ndarray, mirror: Mirror = Mirror(), parts=None
) -> np.ndarray:
    F = np.zeros(d.ndof)
    for t in load.tractions:
        facets = d.part_facets(predicate(case, t.part, bbox, parts))
        if len(facets) == 0 and mirror:
            continue
        if len(facets) == 0:
            raise ModelError(
                f"load case '{load.name}': traction part '{t.part}' has no boundary facets",
                file=str(case.path),
                fix="put tractions on faces (2-D: edges) of the body",
            )
        F += d.traction_load(facets, t.vector)
        if t.twist is not None:
            F += d.twist_load(facets, t.twist)
    if load.stress is not None:
        F += d.stress_load(load_stress(load))
    f = np.zeros((d.nelems, d.dim))
    if load.gravity is not None:
        f += rho[:, None] * np.asarray(load.gravity, float)
    if load.body_force is not None:
        f += np.asarray(load.body_force, float)
    if np.any(f):
        F += d.body_load(f)
    return F


def solve_system(
    K,
    loads: dict,
    fixed: dict,
    method: str,
    d: Discretisation,
    prescribed: dict | None = None,
    records: list | None = None,
    C: np.ndarray | None = None,
    guess: dict | None = None,
) -> dict:
    """Solve K u = F per load with u = 0 (or ``prescribed[name]``) on the fixed dofs.
    Loads sharing a constraint set share one factorisation; ``records`` (a list) gets a
    SolveRecord of each (reference/solvers/record.py) with the loads named. ``K``: the
    stiffness, or a function that assembles it (called only when needed). The plan of
    each (reference/solvers/plan.py) decides: a group whose solution is a linear field (a
    stretch) is found without a solve (reference/solvers/linearfield.py, method
    'linear'); a Q2 system on a tensor mesh with one elastic tensor ``C`` is solved
    without assembling K (reference/solvers/tensorsolve.py, from the initial guesses
    ``guess`` {load: dof vector} when given) and else gets the fast-diagonalisation
    preconditioner (reference/solvers/tensorpre.py); a large P2/Q2 system gets its P1/Q1
    subspace for the two-level method (reference/solvers/twolevel.py)."""
    groups: dict[bytes, list[str]] = {}
    for name in loads:
        groups.setdefault(fixed[name].tobytes(), []).append(name)
    assembled = [K if not callable(K) else None]

    def stiffness():
        if assembled[0] is None:
            assembled[0] = K()
        return assembled[0]

    tensor_mesh = (
        C is not None
        and method in ("auto", "tensor")
        and d.order == "P2"
        and d.cell in ("quad", "hex")
    )
    lat = Lattice.q2(d.doflocs) if tensor_mesh and not prescribed else None
    C0 = None if lat is None else tensorsolve.homogeneous(C)
    op = None if C0 is None else tensorsolve.operator(lat, C0)
    solved, left = {}, []  # solved: group -> (names, x, record, free dofs)
    for j, names in enumerate(groups.values()):
        fx = fixed[names[0]]
        plan = choose_plan(
            System(d.ndof - len(fx), d.dim, method, ndof=d.ndof, matrix_free=op is not None)
        )
        F = np.column_stack([loads[n] for n in names])
        found, tried = None, None
        if not prescribed:
            found = _linear_field(stiffness, op, d, F, fx)
        if found is None and plan.matrix_free:
            x0 = None if not guess or any(n not in guess for n in names) else guess
            x, rec = tensorsolve.solve(op, F, fx, _stack(x0, names))
            found, tried = ((x, rec), None) if x is not None else (None, rec)
        if found is not None:
            solved[j] = (names, *found, d.ndof - len(fx))
        else:
            left.append((j, names, fx, tried, plan))
    if left:
        solved.update(_factorised(stiffness(), left, loads, d, method, prescribed, C, tensor_mesh))
    out = {}
    for j in sorted(solved):
        names, x, rec, nfree = solved[j]
        if records is not None:
            records.append(dataclasses.replace(rec, loads=tuple(names), n=nfree))
        out.update({n: x[:, i] for i, n in enumerate(names)})
    return out


def _stack(guess: dict | None, names) -> np.ndarray | None:
    return None if guess is None else np.column_stack([guess[n] for n in names])


def _linear_field(stiffness, op, d: Discretisation, F: np.ndarray, fx: np.ndarray):
    """(x, record) when the loads' solution is a linear field (reference/solvers/
    linearfield.py: no solve), else None."""
    t0 = time.perf_counter()
    if op is not None:
        apply, norm = op.apply_dofs, op.norm_bound()
    else:
        apply, norm = stiffness().__matmul__, float(abs(stiffness()).sum(axis=1).max())
    found = linearfield.solve(apply, d.doflocs, F, fx, norm)
    if found is None:
        return None
    return found[0], SolveRecord("linear", found[1], sparse.RTOL, 0, time.perf_counter() - t0)


def _factorised(Kf, left, loads, d, method, prescribed, C, tensor_mesh) -> dict:
    """{group: (names, u (ndof, m), record, free dofs)} of the groups ``left`` (j, names,
    held dofs, the failed matrix-free record or None, plan), solved on the assembled
    stiffness side by side (reference/solvers/sets.py)."""
    R = d.rigid_modes()
    coords = np.repeat(d.doflocs.T, d.dim, axis=0)  # location of each interleaved dof
    P = twolevel.prolongation(d) if left[0][4].coarse else None
    tasks = []
    for _, names, fx, tried, _ in left:
        free = np.setdiff1d(np.arange(d.ndof), fx)
        rhs = []
        for n in names:
            F = loads[n].copy()
            if prescribed and n in prescribed:
                F -= Kf[:, fx] @ prescribed[n]
            rhs.append(F[free])
        tasks.append(SetSolve(tuple(names), free, np.column_stack(rhs), tried))
    tensor_of = None
    if tensor_mesh:
        tensor_of = functools.partial(tensorpre.preconditioner, d.doflocs, C=C)
    shared = Shared(Kf, method, R, coords, P, tensor_of)
    out = {}
    for (j, names, fx, _, _), task, (x, rec) in zip(left, tasks, solve_sets(shared, tasks)):
        u = np.zeros((d.ndof, len(names)))
        u[task.free] = x.reshape(len(task.free), -1)
        for i, n in enumerate(names):
            if prescribed and n in prescribed:
                u[fx, i] = prescribed[n]
        out[j] = (names, u, rec, len(task.free))
    return out


def solve_mesh(
    case,
    mesh,
    loads=None,
    records: list | None = None,
    mirror: Mirror = Mirror(),
    disc: Discretisation | None = None,
    parts=None,
    stiffness: dict | None = None,
    guess: dict | None = None,
) -> dict:
    """Displacements {load: (ndof,)} of the load cases of ``case`` on ``mesh`` (all, or
    those named in ``loads``). ``records``: a list that gets one SolveRecord per
    factorisation (reference/solvers/record.py). ``mirror``: ``mesh`` is the lower part of the
    case's box cut at these mid-planes, and every load named has that parity
    (reference/graded/symmetry.py). ``disc``: the mesh's Discretisation if already built.
    ``parts``: part predicates in place of harness.case.parts' (see :func:`predicate`).
    ``stiffness``: a dict that keeps K (once assembled) and C under ``id(disc)`` for the
    next call on the same discretisation (the graded levels' shears cut the box alike in
    pairs). ``guess``: initial guesses {load: dof vector} for an iterative solve."""
    d = disc or Discretisation(mesh, case.reference.cell, case.reference.element)
    cent = d.centroids()
    kept = (stiffness or {}).get(id(d))
    C = element_stiffness(case.material, cent) if kept is None else kept[1]
    rho = densities(case.material, cent)
    bbox = body_bbox(case, mesh)
    chosen = [l for l in case.loads if loads is None or l.name in loads]
    exact = {l.name: u for l in chosen if (u := homogeneous_field(d, case, l, C)) is not None}
    chosen = [l for l in chosen if l.name not in exact]
    if not chosen:
        return exact
    fixed = {l.name: fixed_dofs(d, case, l, bbox, mirror, parts) for l in chosen}
    F = {l.name: load_vector(d, case, l, bbox, rho, mirror, parts) for l in chosen}
    held = {} if kept is None else kept[0]  # K, once something asks for it

    def K():
        if "K" not in held:
            held["K"] = d.stiffness(C)
        return held["K"]

    if stiffness is not None:
        stiffness[id(d)] = (held, C)
    return {
        **solve_system(K, F, fixed, case.reference.solver, d, records=records, C=C, guess=guess),
        **exact,
    }


def homogeneous_field(d: Discretisation, case, load, C: np.ndarray) -> np.ndarray | None:
    """The dof vector of a homogeneous or linear stress load (``load.stress``, with or
    without ``stress_gradient``; constraints at point parts) on a body of one elastic
    tensor: its exact solution is linear or quadratic
    (harness.case.linear_states.linear_closed_form), which the element interpolates
    exactly (a quadratic: P2 on simplices, Q2 on cells mapped by their vertices), so the
    FEM would return it to rounding (tests/case/test_any_shape.py and
    tests/case/test_linear_states.py check that it does). None when the load, the element
    or the material does not allow it: then it is solved."""
    C0 = tensorsolve.homogeneous(C)
    if load.stress is None or C0 is None:
        return None
    if load.stress_gradient is not None and not quadratic_exact(d):
        return None
    anchors = []
    for c in load.constraints:
        box = (case.body.parts or {}).get(c.part)
        if box is None or not np.allclose(box[0], box[1]):
            return None
        anchors.append(np.asarray(box[0], float))
    return linear_closed_form(load, d.doflocs.T, np.linalg.inv(C0), anchors).ravel()


def quadratic_exact(d: Discretisation) -> bool:
    """Whether the nodal interpolant of every quadratic field is exact: a degree-2
    element on a mesh of straight (vertex-mapped) cells."""
    return d.order == "P2" and d.mesh.doflocs.shape[1] == d.mesh.p.shape[1]
