"""``solve(case) -> ReferenceSolution``: the FEM reference of a case, refined until its
own error estimate is below the case's tolerance.

Error estimate: after each uniform refinement, the largest difference at the probe
points (the vertices of the level-0 mesh, which every refined mesh keeps as its first
vertices) between this and the previous solve, relative to the largest displacement
there. Refinement stops when every load case is below ``reference.tol`` or after
``reference.max_refine`` refinements; the finer solve is kept and its estimate is that
of the coarser one (conservative).
"""

from __future__ import annotations

import time
from functools import cached_property

import numpy as np
import skfem

from harness.elasticity import densities, element_stiffness
from harness.errors import ModelError
from harness.parts import part_predicate
from reference import cache as _cache
from reference import solvers
from reference.fem import Discretisation
from reference.locate import Locator
from reference.mesh import MESHES, base_mesh

GRADE_PASSES = {2: 4, 3: 0}  # per level: extra halvings of the smallest element near a singular corner
# (2-D). In 3-D, grading towards the 12 box edges cost 9x the dofs for a 1.5x smaller
# estimate (unit cube, shear, P2), so 3-D refines uniformly.
MAX_DOFS = {2: 400_000, 3: 200_000}  # refinement stops before a level would exceed this
GRADE_SLOPE = 0.5  # element size / distance to the singular set in the graded zone


# -- materials and loads -------------------------------------------------------------

def body_bbox(case, mesh) -> tuple[np.ndarray, np.ndarray]:
    if case.body.shape == "mesh":
        return mesh.p.min(axis=1), mesh.p.max(axis=1)
    return case.body.bbox()


def fixed_dofs(d: Discretisation, case, load, bbox) -> np.ndarray:
    out = []
    for c in load.constraints:
        dofs = d.part_dofs(part_predicate(c.part, bbox, case.body.parts), c.components)
        if len(dofs) == 0:
            raise ModelError(f"load case '{load.name}': constraint part '{c.part}' contains no mesh node",
                             file=str(case.path), fix="enlarge the part or refine the mesh")
        out.append(dofs)
    fixed = np.unique(np.concatenate(out))
    try:
        d.check_rigid(fixed, load.name)
    except ModelError as exc:
        raise ModelError(exc.message, file=str(case.path), fix=exc.fix) from None
    return fixed


def load_vector(d: Discretisation, case, load, bbox, rho: np.ndarray) -> np.ndarray:
    F = np.zeros(d.ndof)
    for t in load.tractions:
        facets = d.part_facets(part_predicate(t.part, bbox, case.body.parts))
        if len(facets) == 0:
            raise ModelError(f"load case '{load.name}': traction part '{t.part}' has no boundary facets",
                             file=str(case.path), fix="put tractions on faces (2-D: edges) of the body")
        F += d.traction_load(facets, t.vector)
    f = np.zeros((d.nelems, d.dim))
    if load.gravity is not None:
        f += rho[:, None] * np.asarray(load.gravity, float)
    if load.body_force is not None:
        f += np.asarray(load.body_force, float)
    if np.any(f):
        F += d.body_load(f)
    return F


def solve_system(K, loads: dict, fixed: dict, method: str, d: Discretisation,
                 prescribed: dict | None = None) -> dict:
    """Solve K u = F per load with u = 0 (or ``prescribed[name]``) on the fixed dofs.
    Loads sharing a constraint set share one factorisation."""
    out = {}
    groups: dict[bytes, list[str]] = {}
    for name in loads:
        groups.setdefault(fixed[name].tobytes(), []).append(name)
    R = None
    for names in groups.values():
        fx = fixed[names[0]]
        free = np.setdiff1d(np.arange(d.ndof), fx)
        A = K[free][:, free]
        rhs = []
        for n in names:
            F = loads[n].copy()
            if prescribed and n in prescribed:
                F -= K[:, fx] @ prescribed[n]
            rhs.append(F[free])
        m = solvers.choose(method, len(free), d.dim)
        if m == "amg" and R is None:
            R = d.rigid_modes()
        x = solvers.solve(A, np.column_stack(rhs), m, None if R is None else R[free])
        for i, n in enumerate(names):
            u = np.zeros(d.ndof)
            u[free] = x[:, i]
            if prescribed and n in prescribed:
                u[fx] = prescribed[n]
            out[n] = u
    return out


# -- the solution --------------------------------------------------------------------

class ReferenceSolution:
    """FEM displacements of every load case of a case, on the finest mesh solved.

    Attributes: ``loads`` (names), ``error_estimate`` {load: relative estimate},
    ``n_dofs``, ``level`` (refinements done), ``history`` (rows of n_dofs and the
    estimates per level), ``mesh``, ``basis`` (scalar) and ``vector_basis`` for plots.
    """

    def __init__(self, case, mesh, U: dict, estimates: dict, history: list, key: str,
                 from_cache: bool = False, seconds: float = 0.0):
        self.case = case
        self.mesh = mesh
        self.dim = case.dim
        self.cell, self.order = case.reference.cell, case.reference.element
        self._U = U
        self.loads = tuple(U)
        self.error_estimate = estimates
        self.history = history
        self.key = key
        self.from_cache = from_cache
        self.seconds = seconds
        self.level = len(history) - 1
        self.n_dofs = int(next(iter(U.values())).size) if U else 0
        self._modal: dict = {}

    @cached_property
    def disc(self) -> Discretisation:
        return Discretisation(self.mesh, self.cell, self.order)

    @property
    def basis(self) -> skfem.CellBasis:
        return self.disc.basis

    @cached_property
    def vector_basis(self) -> skfem.CellBasis:
        return skfem.Basis(self.mesh, skfem.ElementVector(self.disc.elem), intorder=self.disc.q_mass)

    @cached_property
    def locator(self) -> Locator:
        return Locator(self.mesh)

    def _check_load(self, load) -> str:
        if load not in self._U:
            raise ModelError(f"unknown load case '{load}'", fix=f"one of: {', '.join(self.loads)}")
        return load

    def nodal(self, load: str) -> np.ndarray:
        """Displacement at every scalar dof location (ns, dim) (vertices first)."""
        return self._U[self._check_load(load)].reshape(-1, self.dim)

    def vertex_displacement(self, load: str) -> np.ndarray:
        """Displacement at the mesh vertices (n_vertices, dim)."""
        return self.nodal(load)[: self.mesh.p.shape[1]]

    def displacement(self, points, load: str) -> np.ndarray:
        """Displacement (n, dim) at points (n, dim) inside or on the body."""
        return self.locator.evaluate(self.basis, self.nodal(load), points)

    def u_max(self, load: str) -> float:
        return float(np.linalg.norm(self.vertex_displacement(load), axis=1).max())

    # -- modal analysis ---------------------------------------------------------------

    def _modal_solve(self, k: int, load: str):
        idx = self.loads.index(load)
        name = f"{self.key}-modal-{idx}-{k}"
        hit = _cache.load(name) if self.key else None
        if hit is not None:
            return hit["freqs"], hit["modes"]
        d = self.disc
        case = self.case
        C = element_stiffness(case.material, d.centroids())
        rho = densities(case.material, d.centroids())
        K, M = d.stiffness(C), d.mass(rho)
        lc = next(l for l in case.loads if l.name == load)
        fx = fixed_dofs(d, case, lc, body_bbox(case, self.mesh))
        free = np.setdiff1d(np.arange(d.ndof), fx)
        Kf, Mf = K[free][:, free], M[free][:, free]
        k = min(k, len(free))
        if len(free) <= max(400, 3 * k):
            import scipy.linalg as sl
            lam, vec = sl.eigh(Kf.toarray(), Mf.toarray())
            lam, vec = lam[:k], vec[:, :k]
        else:
            from scipy.sparse.linalg import eigsh
            lam, vec = eigsh(Kf.tocsc(), k=k, M=Mf.tocsc(), sigma=0.0, which="LM")
        order = np.argsort(lam)
        lam, vec = lam[order], vec[:, order]
        modes = np.zeros((k, d.ndof))
        modes[:, free] = vec.T
        freqs = np.sqrt(np.maximum(lam, 0)) / (2 * np.pi)
        modes = modes.reshape(k, d.ns, d.dim)
        if self.key:
            _cache.save(name, freqs=freqs, modes=modes)
        return freqs, modes

    def frequencies(self, k: int | None = None, load: str | None = None) -> np.ndarray:
        """First k natural frequencies (Hz for SI inputs) with the constraints of load
        case ``load`` (default: the first), from the consistent mass matrix."""
        k = k or self.case.reference.modes or 6
        return self._modal_solve(k, self._check_load(load or self.loads[0]))[0]

    def modes(self, k: int | None = None, load: str | None = None) -> np.ndarray:
        """Mode shapes (k, n_vertices, dim) at the mesh vertices, M-orthonormal."""
        k = k or self.case.reference.modes or 6
        return self._modal_solve(k, self._check_load(load or self.loads[0]))[1][:, : self.mesh.p.shape[1]]

    def mode_displacement(self, points, i: int, k: int | None = None, load: str | None = None) -> np.ndarray:
        """Mode i evaluated at points (n, dim)."""
        k = max(k or self.case.reference.modes or 6, i + 1)
        shapes = self._modal_solve(k, self._check_load(load or self.loads[0]))[1]
        return self.locator.evaluate(self.basis, shapes[i], points)


# -- solve ----------------------------------------------------------------------------

def solve_mesh(case, mesh) -> dict:
    """Displacements {load: (ndof,)} of every load case of ``case`` on ``mesh``."""
    d = Discretisation(mesh, case.reference.cell, case.reference.element)
    cent = d.centroids()
    C = element_stiffness(case.material, cent)
    rho = densities(case.material, cent)
    bbox = body_bbox(case, mesh)
    fixed = {l.name: fixed_dofs(d, case, l, bbox) for l in case.loads}
    F = {l.name: load_vector(d, case, l, bbox, rho) for l in case.loads}
    K = d.stiffness(C)
    return solve_system(K, F, fixed, case.reference.solver, d)


def singular_distance(case, x: np.ndarray) -> np.ndarray | None:
    """Distance of points x (n, dim) to where elastic solutions are singular: the
    corners of a rectangle or polygon (and in 2-D the corners of material regions, which
    include the points where an interface meets the boundary), the edges of a box.
    None for mesh bodies."""
    body = case.body
    if body.shape == "polygon":
        v = np.asarray(body.vertices, float)
        return np.linalg.norm(x[:, None, :] - v[None], axis=2).min(axis=1)
    if body.shape not in ("rectangle", "box"):
        return None
    lo, hi = body.bbox()
    d = np.minimum(np.abs(x - lo), np.abs(x - hi))
    if case.dim == 2:
        dist = np.linalg.norm(d, axis=1)
        for r in case.material.regions:  # where a material interface meets the boundary
            corners = np.array([[a, b] for a in (r.lo[0], r.hi[0]) for b in (r.lo[1], r.hi[1])])
            corners = np.clip(corners, lo, hi)
            dist = np.minimum(dist, np.linalg.norm(x[:, None, :] - corners[None], axis=2).min(axis=1))
        return dist
    return np.min([np.hypot(d[:, a], d[:, b]) for a, b in ((0, 1), (0, 2), (1, 2))], axis=0)


def element_size(mesh) -> np.ndarray:
    """Longest edge of each element."""
    x = mesh.p[:, mesh.t]  # dim, nverts, ne
    k = x.shape[1]
    return np.max([np.linalg.norm(x[:, i] - x[:, j], axis=0) for i in range(k) for j in range(i + 1, k)], axis=0)


def refine(case, mesh, h: float, passes: int):
    """Uniform refinement to size h, then (simplices only) local bisections until every
    element near the singular set is no larger than max(GRADE_SLOPE * distance,
    h / 2**passes): a geometric grading that keeps corner/edge singularities from
    dominating the error while adding only O(passes) layers of elements."""
    mesh = mesh.refined()
    if passes == 0 or not isinstance(mesh, (skfem.MeshTri, skfem.MeshTet)):
        return mesh
    h_min = h * 0.5 ** passes
    for _ in range(passes + 2):
        dist = singular_distance(case, mesh.p[:, mesh.t].mean(axis=1).T)
        if dist is None:
            break
        target = np.maximum(GRADE_SLOPE * dist, h_min)
        marked = np.flatnonzero(element_size(mesh) > 1.5 * target)
        if len(marked) == 0:
            break
        mesh = mesh.refined(marked)
    return mesh


def _relative_change(U, V, nv, dim) -> float:
    a, b = U[: nv * dim].reshape(nv, dim), V[: nv * dim].reshape(nv, dim)
    scale = np.linalg.norm(b, axis=1).max()
    return float(np.linalg.norm(a - b, axis=1).max() / scale) if scale > 0 else 0.0


def solve(case, *, cache: bool = True, status=lambda msg: None) -> ReferenceSolution:
    """The reference solution of every load case of ``case`` (harness.cases.Case)."""
    if not case.loads:
        raise ModelError("the case has no load cases", file=str(case.path), field="loads",
                         fix="add loads.set or [[loads.case]]")
    key = _cache.case_key(case) if cache else ""
    names = [l.name for l in case.loads]
    if cache:
        hit = _cache.load(key)
        if hit is not None:
            mesh = MESHES[case.reference.cell](hit["p"], hit["t"])
            U = {n: hit["u"][i] for i, n in enumerate(names)}
            est = {n: float(hit["estimate"][i]) for i, n in enumerate(names)}
            hist = [dict(zip(["n_dofs"] + names, row)) for row in hit["history"]]
            return ReferenceSolution(case, mesh, U, est, hist, key, from_cache=True,
                                     seconds=float(hit["seconds"]))
    t0 = time.perf_counter()
    mesh = base_mesh(case)
    base = mesh
    nv0 = mesh.p.shape[1]
    p0 = mesh.p.copy()
    status(f"FEM level 0 ({case.dim * mesh.p.shape[1]} vertex dofs)")
    U = solve_mesh(case, mesh)
    est = {n: float("nan") for n in names}
    history = [dict(n_dofs=next(iter(U.values())).size, **est)]
    for level in range(1, case.reference.max_refine + 1):
        h = float(element_size(base).max()) / 2 ** level
        if next(iter(U.values())).size * 2 ** case.dim > MAX_DOFS[case.dim]:
            status(f"FEM: next level would exceed {MAX_DOFS[case.dim]} dofs; stopping")
            break
        finer = refine(case, mesh, h, GRADE_PASSES[case.dim] * level if getattr(case.reference, "grade", True) else 0)
        if not np.allclose(finer.p[:, :nv0], p0):
            raise RuntimeError("refinement renumbered the vertices")  # scikit-fem contract
        status(f"FEM level {level} ({case.dim * finer.p.shape[1]} vertex dofs)")
        V = solve_mesh(case, finer)
        est = {n: _relative_change(U[n], V[n], nv0, case.dim) for n in names}
        mesh, U = finer, V
        history.append(dict(n_dofs=next(iter(U.values())).size, **est))
        if max(est.values()) < case.reference.tol:
            break
    seconds = time.perf_counter() - t0
    if cache:
        _cache.save(key, p=mesh.p, t=mesh.t, u=np.stack([U[n] for n in names]),
                    estimate=np.array([est[n] for n in names]),
                    history=np.array([[h["n_dofs"]] + [h[n] for n in names] for h in history], float),
                    seconds=seconds)
    return ReferenceSolution(case, mesh, U, est, history, key, seconds=seconds)
