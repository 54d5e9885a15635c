"""``solve(case) -> ReferenceSolution``: the FEM reference of a case, refined until its
own error estimate is below the case's tolerance, cached on disk.

Two methods (``[reference] method``): ``graded`` (rectangles and boxes; the default for
boxes) solves Q2 meshes graded towards the faces on several levels and extrapolates
(reference/levels.py): the reference field is the extrapolant and the estimate is
per point. ``refine`` (any body) refines the case's mesh: a mesh body of triangles or
tetrahedra adaptively (reference/adaptive.py: residual indicators, Dörfler marking; the
estimate is per point, from the last changes between levels and their observed order),
any other body uniformly (reference/refine.py: the relative change from the previous
level, the same at every point). The finest solve is kept.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from functools import cached_property

import numpy as np
import skfem

from harness.case.elasticity import densities, element_stiffness
from harness.errors import ModelError
from reference import cache as _cache
from reference.adaptive import Changes, applies, solve_adaptive
from reference.fem import Discretisation
from reference.levels import Levels, n_dofs, solve_graded
from reference.locate import Locator
from reference.mesh import MESHES
from reference.problem import body_bbox, fixed_dofs
from reference.refine import solve_refined

MODAL_DOFS = {2: 400_000, 3: 120_000}   # graded: the modes come from the finest level at most this
# large (the Sec. 6 cube's 108k-dof level factorises in ~3 GB; its 152k one would pass 6 GB, and its
# shift-invert CG took > 15 min). Frequencies converge like h^(2p), far faster than the scored
# displacements that need the finer levels.


# -- the solution --------------------------------------------------------------------

class ErrorEstimate(dict):
    """The reference's own error: ``est[load]`` is the relative estimate of a load case
    (largest estimated error over the probe points / largest displacement), and
    ``est(points, load)`` the per-point estimate (n,) of |u_h - u| at points (n, dim),
    in displacement units. ``point_estimate`` supplies the latter."""

    def __init__(self, values: dict, point_estimate=None):
        super().__init__(values)
        self._point = point_estimate

    def __call__(self, points, load: str) -> np.ndarray:
        return self._point(np.asarray(points, float), load)


class ReferenceSolution:
    """FEM displacements of every load case of a case.

    Attributes: ``loads`` (names), ``error_estimate`` ({load: relative estimate}, and
    callable per point), ``met_tol``, ``n_dofs``, ``level`` (levels after the first),
    ``history`` (rows of n_dofs and the estimates per level), ``solver`` (one record
    per factorisation: method, residual), ``mesh`` (the finest), ``basis`` (scalar) and
    ``vector_basis`` for plots. With ``levels`` (the graded method), ``displacement``
    is the extrapolated field and ``nodal`` the finest level's. With ``changes`` (the
    adaptive method) the per-point estimate comes from the last changes between levels.
    """

    def __init__(self, case, mesh, U: dict, estimates: dict, history: list, key: str,
                 from_cache: bool = False, seconds: float = 0.0, solver: list | None = None,
                 levels: Levels | None = None, changes: Changes | None = None):
        self.case = case
        self.mesh = mesh
        self.dim = case.dim
        self.cell, self.order = case.reference.cell, case.reference.element
        self._U = U
        self.loads = tuple(U)
        self.levels = levels
        self.solver = list(solver or [])
        self.changes = changes
        point = self._level_estimate if levels is not None else (
            self._change_estimate if changes is not None else self._uniform_estimate)
        self.error_estimate = ErrorEstimate(estimates, point)
        self.history = history
        self.key = key
        self.from_cache = from_cache
        self.seconds = seconds
        self.level = len(history) - 1
        self.n_dofs = (n_dofs(levels.meshes[-1], self.dim) if levels is not None
                       else int(next(iter(U.values())).size) if U else 0)
        self._modal: dict = {}

    @cached_property
    def disc(self) -> Discretisation:
        return Discretisation(self.mesh, self.cell, self.order)

    @property
    def basis(self) -> skfem.CellBasis:
        return self.disc.basis

    @cached_property
    def modal_disc(self) -> Discretisation:
        """The discretisation of the modal solves: the finest mesh, or for the graded
        method the finest level with at most MODAL_DOFS dofs (the coarsest if none is)."""
        if self.levels is None:
            return self.disc
        sizes = [n_dofs(m, self.dim) for m in self.levels.meshes]
        k = max([i for i, n in enumerate(sizes) if n <= MODAL_DOFS[self.dim]], default=0)
        return self.disc if k == len(sizes) - 1 else self.levels.disc(self.levels.meshes[k])

    @property
    def modal_mesh(self):
        """The mesh the mode shapes live on (``modes`` gives them at its vertices)."""
        return self.modal_disc.mesh

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
        if self.levels is not None:
            return self.levels.evaluate(points, self._check_load(load))[0]
        return self.locator.evaluate(self.basis, self.nodal(load), points)

    def u_max(self, load: str) -> float:
        return float(np.linalg.norm(self.vertex_displacement(load), axis=1).max())

    @property
    def met_tol(self) -> bool:
        """Whether every load case's estimate is below the case's ``reference.tol``
        (False when there is no estimate: a single level is never trusted)."""
        return all(np.isfinite(v) and v < self.case.reference.tol for v in self.error_estimate.values())

    def _level_estimate(self, points, load: str) -> np.ndarray:
        return self.levels.evaluate(points, self._check_load(load))[1]

    def _change_estimate(self, points, load: str) -> np.ndarray:
        return self.changes.at(self.locator, self.basis, points, self._check_load(load))

    def _uniform_estimate(self, points, load: str) -> np.ndarray:
        """The load's relative estimate times its largest displacement at every point:
        the refinement estimate is a maximum over the probes, so it bounds each of them."""
        e = float(self.error_estimate[self._check_load(load)]) * self.u_max(load)
        return np.full(len(points), e)

    # -- modal analysis ---------------------------------------------------------------

    def _modal_solve(self, k: int, load: str):
        idx = self.loads.index(load)
        name = f"{self.key}-modal-{idx}-{k}"
        hit = _cache.load(name) if self.key else None
        if hit is not None:
            return hit["freqs"], hit["modes"]
        d = self.modal_disc
        case = self.case
        C = element_stiffness(case.material, d.centroids())
        rho = densities(case.material, d.centroids())
        K, M = d.stiffness(C), d.mass(rho)
        lc = next(l for l in case.loads if l.name == load)
        fx = fixed_dofs(d, case, lc, body_bbox(case, d.mesh))
        free = np.setdiff1d(np.arange(d.ndof), fx)
        Kf, Mf = K[free][:, free], M[free][:, free]
        k = min(k, len(free))
        if len(free) <= max(400, 3 * k):
            import scipy.linalg as sl
            lam, vec = sl.eigh(Kf.toarray(), Mf.toarray())
            lam, vec = lam[:k], vec[:, :k]
        else:
            from scipy.sparse.linalg import LinearOperator, eigsh

            from reference.solvers import inverse
            from reference.twolevel import prolongation
            P = prolongation(d)
            solve = inverse(Kf, np.repeat(d.doflocs.T, d.dim, axis=0)[free], None if P is None else P[free])
            opinv = None if solve is None else LinearOperator(Kf.shape, matvec=solve, dtype=float)
            lam, vec = eigsh(Kf.tocsc(), k=k, M=Mf.tocsc(), sigma=0.0, which="LM", OPinv=opinv,
                             v0=np.random.default_rng(0).standard_normal(Kf.shape[0]))  # seeded: same bits
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
        """Mode shapes (k, n_vertices, dim) at the vertices of ``modal_mesh``, M-orthonormal."""
        k = k or self.case.reference.modes or 6
        return self._modal_solve(k, self._check_load(load or self.loads[0]))[1][:, : self.modal_mesh.p.shape[1]]

    def mode_displacement(self, points, i: int, k: int | None = None, load: str | None = None) -> np.ndarray:
        """Mode i evaluated at points (n, dim)."""
        k = max(k or self.case.reference.modes or 6, i + 1)
        shapes = self._modal_solve(k, self._check_load(load or self.loads[0]))[1]
        d = self.modal_disc
        locator = self.locator if d.mesh is self.mesh else Locator(d.mesh)
        return locator.evaluate(d.basis, shapes[i], points)


# -- solve ----------------------------------------------------------------------------

def solve(case, *, cache: bool = True, status=lambda msg: None) -> ReferenceSolution:
    """The reference solution of every load case of a case.

    Parameters
    ----------
    case : harness.case.reader.Case
        The body, material, loads and ``[reference]`` settings (element, cell, tol,
        max_refine, solver, method).
    cache : bool
        Read a stored solution of the same inputs and code, and store a new one.
    status : callable
        Called with short progress messages during long solves.

    Returns
    -------
    ReferenceSolution
        Displacements of every load at any point (``evaluate``), with the estimated
        error there (``estimate``), the solve history, the solvers used and the modes.
    """
    if not case.loads:
        raise ModelError("the case has no load cases", file=str(case.path), field="loads",
                         fix="add loads.set or [[loads.case]]")
    key = _cache.case_key(case) if cache else ""
    names = [l.name for l in case.loads]
    graded = case.reference.method == "graded"
    if cache:
        hit = _cache.load(key)
        if hit is not None:
            est = {n: float(hit["estimate"][i]) for i, n in enumerate(names)}
            hist = [dict(zip(["n_dofs"] + names, row)) for row in hit["history"]]
            solver = [dict(method=str(m), residual=float(r)) for m, r in zip(hit["solver"], hit["residual"])]
            if graded:
                levels = Levels.from_arrays(case, names, hit)
                return _graded_solution(case, levels, est, hist, key, float(hit["seconds"]), solver, True)
            mesh = MESHES[case.reference.cell](hit["p"], hit["t"])
            U = {n: hit["u"][i] for i, n in enumerate(names)}
            return ReferenceSolution(case, mesh, U, est, hist, key, from_cache=True,
                                     seconds=float(hit["seconds"]), solver=solver,
                                     changes=Changes.from_arrays(names, hit))
    t0 = time.perf_counter()
    info: list = []
    changes = None
    if graded:
        levels, est, history = solve_graded(case, status, info)
    elif applies(case):
        mesh, U, est, history, changes = solve_adaptive(case, status, info)
    else:
        mesh, U, est, history = solve_refined(case, status, info)
    seconds = time.perf_counter() - t0
    solver = [dict(method=str(r.get("method", "")), residual=float(r.get("residual", np.nan))) for r in info]
    common = dict(estimate=np.array([est[n] for n in names]),
                  history=np.array([[h["n_dofs"]] + [h[n] for n in names] for h in history], float),
                  seconds=seconds, solver=np.array([r["method"] for r in solver]),
                  residual=np.array([r["residual"] for r in solver], float))
    if graded:
        if cache:
            _cache.save(key, **levels.to_arrays(names), **common)
        return _graded_solution(case, levels, est, history, key, seconds, solver, False)
    if cache:
        _cache.save(key, p=mesh.p, t=mesh.t, u=np.stack([U[n] for n in names]), **common,
                    **(changes.to_arrays(names) if changes is not None else {}))
    return ReferenceSolution(case, mesh, U, est, history, key, seconds=seconds, solver=solver, changes=changes)


class _FinestFields(Mapping):
    """{load: dof vector on the finest graded level}, each made when first asked for: a load
    that stopped early (a stretch) is interpolated onto the finest mesh, ~2 s a load on the
    10:1 box's million dofs, and most runs only evaluate the extrapolant at points."""

    def __init__(self, levels: Levels):
        self._levels, self._done = levels, {}

    def __getitem__(self, name):
        if name not in self._done:
            if name not in self._levels.fields:
                raise KeyError(name)
            self._done[name] = self._levels.finest_field(name)
        return self._done[name]

    def __iter__(self):
        return iter(self._levels.fields)

    def __len__(self):
        return len(self._levels.fields)


def _graded_solution(case, levels: Levels, est, history, key, seconds, solver, from_cache):
    U = _FinestFields(levels)
    return ReferenceSolution(case, levels.meshes[-1], U, est, history, key, from_cache=from_cache,
                             seconds=seconds, solver=solver, levels=levels)
