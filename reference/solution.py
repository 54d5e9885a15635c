"""``solve(case) -> ReferenceSolution``: the FEM reference of a case, refined until its
own error estimate is below the case's tolerance, cached on disk.

Two methods (``[reference] method``): ``graded`` (rectangles and boxes; the default for
boxes) solves Q2 meshes graded towards the faces on several levels and extrapolates
(reference/graded/levels.py): the reference field is the extrapolant and the estimate is
per point. ``refine`` (any body) refines the case's mesh: a mesh body of triangles or
tetrahedra adaptively (reference/adaptive/adapt.py: residual indicators, Dörfler marking; the
estimate is per point, from the last changes between levels and their observed order),
any other body uniformly (reference/adaptive/refine.py: the relative change from the previous
level, the same at every point). The finest solve is kept. Each is one object of
reference/methods.py, which the solution asks for its values and estimates.
"""

from __future__ import annotations

import time
from functools import cached_property

import numpy as np
import skfem

from harness.case.elasticity import densities, element_stiffness
from harness.errors import ModelError
from reference import cache as _cache
from reference.adaptive.adapt import scored_loads
from reference.fem import Discretisation
from reference.locate import Locator
from reference.methods import method_of
from reference.problem import body_bbox, fixed_dofs
from reference.solvers.record import SolveRecord

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
    ``history`` (rows of n_dofs and the estimates per level), ``solver`` (one
    SolveRecord per factorisation), ``method`` (the object of reference/methods.py that
    holds the fields: its values and estimates are the solution's), ``mesh`` (the
    finest), ``basis`` (scalar) and ``vector_basis`` for plots.
    """

    def __init__(
        self,
        case,
        method,
        estimates: dict,
        history: list,
        key: str,
        from_cache: bool = False,
        seconds: float = 0.0,
        solver: list | None = None,
    ):
        self.case = case
        self.method = method
        self.mesh = method.mesh
        self.dim = case.dim
        self.cell, self.order = case.reference.cell, case.reference.element
        self._U = method.fields
        self.loads = tuple(self._U)
        self.solver = list(solver or [])
        self.error_estimate = ErrorEstimate(estimates, self._estimate)
        self.history = history
        self.key = key
        self.from_cache = from_cache
        self.seconds = seconds
        self.level = len(history) - 1
        self.n_dofs = method.n_dofs
        self._modal: dict = {}

    @property
    def levels(self):
        """The graded method's levels (None for the others)."""
        return getattr(self.method, "levels", None)

    @property
    def changes(self):
        """The adaptive method's last changes between levels (None for the others)."""
        return getattr(self.method, "changes", None)

    @property
    def stop(self):
        """Why the adaptive method's levels ended (reference/adaptive/adapt.py Stop; None
        for the other methods)."""
        return self.method.stop

    @property
    def targets(self) -> tuple[str, ...]:
        """The loads whose estimates ``tol`` applies to: the held-out loads, or every load
        of a case that holds none out (reference/adaptive/adapt.py ``scored_loads``)."""
        return scored_loads(self.case)

    @property
    def disc(self) -> Discretisation:
        return self.method.disc

    @property
    def basis(self) -> skfem.CellBasis:
        return self.disc.basis

    @property
    def modal_disc(self) -> Discretisation:
        """The discretisation of the modal solves: the finest mesh, or for the graded
        method the finest level with at most its MODAL_DOFS dofs."""
        return self.method.modal_disc

    @property
    def modal_mesh(self):
        """The mesh the mode shapes live on (``modes`` gives them at its vertices)."""
        return self.modal_disc.mesh

    @cached_property
    def vector_basis(self) -> skfem.CellBasis:
        return skfem.Basis(
            self.mesh, skfem.ElementVector(self.disc.elem), intorder=self.disc.q_mass
        )

    @property
    def locator(self) -> Locator:
        return self.method.locator

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
        return self.method.evaluate(points, self._check_load(load))

    def u_max(self, load: str) -> float:
        return float(np.linalg.norm(self.vertex_displacement(load), axis=1).max())

    @property
    def met_tol(self) -> bool:
        """Whether every load case's estimate is below the case's ``reference.tol``
        (False when there is no estimate: a single level is never trusted)."""
        return all(
            np.isfinite(v) and v < self.case.reference.tol for v in self.error_estimate.values()
        )

    def _estimate(self, points, load: str) -> np.ndarray:
        return self.method.estimate(np.asarray(points, float), self._check_load(load))

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

            from reference.solvers.sparse import inverse
            from reference.solvers.twolevel import prolongation

            P = prolongation(d)
            solve = inverse(
                Kf, np.repeat(d.doflocs.T, d.dim, axis=0)[free], None if P is None else P[free]
            )
            opinv = None if solve is None else LinearOperator(Kf.shape, matvec=solve, dtype=float)
            # seeded: same bits
            lam, vec = eigsh(
                Kf.tocsc(),
                k=k,
                M=Mf.tocsc(),
                sigma=0.0,
                which="LM",
                OPinv=opinv,
                v0=np.random.default_rng(0).standard_normal(Kf.shape[0]),
            )
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
        return self._modal_solve(k, self._check_load(load or self.loads[0]))[1][
            :, : self.modal_mesh.p.shape[1]
        ]

    def mode_displacement(
        self, points, i: int, k: int | None = None, load: str | None = None
    ) -> np.ndarray:
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
        raise ModelError(
            "the case has no load cases",
            file=str(case.path),
            field="loads",
            fix="add loads.set or [[loads.case]]",
        )
    key = _cache.case_key(case) if cache else ""
    names = [l.name for l in case.loads]
    method = method_of(case)
    if cache:
        hit = _cache.load(key)
        if hit is not None:
            est = {n: float(hit["estimate"][i]) for i, n in enumerate(names)}
            hist = [dict(zip(["n_dofs"] + names, row)) for row in hit["history"]]
            solver = [SolveRecord(str(m), float(r)) for m, r in zip(hit["solver"], hit["residual"])]
            return ReferenceSolution(
                case,
                method.from_arrays(case, names, hit, est),
                est,
                hist,
                key,
                from_cache=True,
                seconds=float(hit["seconds"]),
                solver=solver,
            )
    t0 = time.perf_counter()
    records: list = []
    solved, est, history = method.solve(case, status, records)
    seconds = time.perf_counter() - t0
    solver = [SolveRecord(r.method, r.residual) for r in records]
    if cache:
        _cache.save(
            key,
            **solved.to_arrays(names),
            estimate=np.array([est[n] for n in names]),
            history=np.array([[h["n_dofs"]] + [h[n] for n in names] for h in history], float),
            seconds=seconds,
            solver=np.array([r.method for r in solver]),
            residual=np.array([r.residual for r in solver], float),
        )
    return ReferenceSolution(case, solved, est, history, key, seconds=seconds, solver=solver)
