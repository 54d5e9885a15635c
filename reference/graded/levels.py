"""The ``graded`` reference of rectangles and boxes: Q2 quadrilaterals/hexahedra graded
towards every face (reference/graded/meshes.py), solved on levels of n = divisions / 2,
+ 1, + 2, ... cells per end zone (every second n skipped between the first three and
the last three, see :func:`next_divisions`), and Richardson-extrapolated over the last
three levels (reference/graded/extrapolate.py). The extrapolant is the reference field;
the difference of the last two extrapolants is its per-point error estimate. A load
whose last two levels
agree to rounding (a field the mesh represents exactly, like the stretches' linear
closed form) stops refining; the others go on until every estimate at the probe points
is below ``reference.tol``, ``reference.max_refine`` levels are done, or the next level
would pass the dof budget. A load with mirror symmetry is solved on the half, quarter or
eighth of the box it determines and unfolded (reference/graded/symmetry.py).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from harness.linalg.sparse import single_thread_blas
from reference.fem import Discretisation
from reference.graded.extrapolate import FORMAL_ORDER, extrapolate, observed_order
from reference.graded.meshes import (
    axis_maps,
    graded_axes,
    graded_mesh,
    probe_points,
    q2_doflocs,
    tensor_mesh,
)
from reference.graded.symmetry import lower_half, mirror_of, unfold
from reference.lattice import Lattice
from reference.mirror import Mirror
from reference.problem import solve_mesh

FIRST = 2  # cells per end zone at level 0 when [reference] divisions is not set
# (divisions counts cells along the shortest side: two end zones)
# the largest system one level may solve (3-D: ~15 s a factorisation)
MAX_DOFS = {2: 400_000, 3: 64_000}
# ... with the fast-diagonalisation CG (solver 'auto' or 'tensor',
# reference/solvers/tensorpre.py): no factorisation, K applied without assembly
# (reference/solvers/tensorsolve.py), ~80-110 iterations at nu = 0.49; the limit is time
# (the 10:1 box's nine loads: 103 s to n = 10, 252k-dof quarters)
TENSOR_MAX_DOFS = {2: 2_000_000, 3: 400_000}
WORKERS = min(2, len(os.sched_getaffinity(0)))  # threads solving a cut's load groups side by side
EXACT = 1e-6  # relative change between two levels below which a field is exact
# (its levels differ by the solves' rounding only): the 10:1 box's stretch-x at nu = 0.49, a
# linear field, changes by 1.2e-9 and then 1.7e-7 from level to level (Cholesky residuals ~1e-8 on
# that ill-conditioned system); at 1e-9 it stayed active and its full-box solves took most of the
# time. Fields that converge change by 1e-4..1e-2 between levels


def n_dofs(mesh, dim: int) -> int:
    """Q2 dofs of a tensor mesh: (2 cells + 1) nodes along each axis."""
    return _dofs([np.unique(mesh.p[a]) for a in range(dim)], dim)


def _dofs(axes, dim: int) -> int:
    return dim * int(np.prod([2 * len(x) - 1 for x in axes]))


@dataclass
class Levels:
    """The solved levels: ``ns`` cells per end zone, ``meshes``, per load the
    (level, dof vector) pairs kept (the last three; for a load found exact, the two
    that agree, the coarser last: it is the field used) and the observed order."""

    dim: int
    origin: np.ndarray = None
    size: np.ndarray = None
    ns: list = field(default_factory=list)
    meshes: list = field(default_factory=list)
    fields: dict = field(default_factory=dict)
    orders: dict = field(default_factory=dict)
    _eval: dict = field(default_factory=dict, repr=False)

    def add_mesh(self, n: int, mesh):
        self.ns.append(n)
        self.meshes.append(mesh)

    def disc(self, mesh) -> Discretisation:
        return Discretisation(mesh, "quad" if self.dim == 2 else "hex", "P2")

    def _evaluator(self, k: int) -> Lattice:
        if k not in self._eval:
            self._eval[k] = Lattice.of(q2_doflocs(self.meshes[k]))
        return self._eval[k]

    def solve(self, case, k: int, axes: list, mirrors: dict, records=None) -> dict:
        """Level k's displacements {load: whole-box dof vector} of the loads in
        ``mirrors`` ({name: Mirror}): each group of loads with the same mirror solved on
        its cut of the box (reference/graded/symmetry.py) and unfolded. Groups that cut the box
        alike (the shears come in pairs) share one discretisation, built when their cut
        comes and dropped after it, and are solved side by side in WORKERS threads (the
        CG's compiled products and BLAS release the GIL; each keeps its own records, so
        the results and their order do not depend on the threads)."""
        groups: dict[Mirror, list[str]] = {}
        for name, mirror in mirrors.items():
            groups.setdefault(mirror, []).append(name)
        cuts: dict[tuple, list] = {}
        out = {}
        for mirror, names in groups.items():
            if not mirror:
                out.update(solve_mesh(case, self.meshes[k], loads=set(names), records=records))
            else:
                cuts.setdefault(tuple(sorted(mirror.axes)), []).append((mirror, sorted(names)))
        for cut in sorted(cuts):
            members = sorted(cuts[cut], key=lambda m: m[1])
            d = self.disc(tensor_mesh(lower_half(axes, members[0][0])))
            half, stiffness = Lattice.of(d.doflocs), {}

            def one(member):
                mirror, names = member
                rec: list = []
                U = solve_mesh(
                    case,
                    d.mesh,
                    loads=set(names),
                    records=rec,
                    mirror=mirror,
                    disc=d,
                    stiffness=stiffness,
                    guess=self.guess(d.doflocs, names),
                )
                return {n: unfold(self._evaluator(k), half, U[n], mirror) for n in names}, rec

            self._evaluator(k)
            if len(members) > 1 and WORKERS > 1:
                with single_thread_blas(), ThreadPoolExecutor(min(WORKERS, len(members))) as pool:
                    done = list(pool.map(one, members))
            else:
                done = [one(m) for m in members]
            for U, rec in done:
                out.update(U)
                if records is not None:
                    records.extend(rec)
        return out

    def guess(self, doflocs: np.ndarray, names) -> dict:
        """{load: its last level's field interpolated at ``doflocs`` (dim, ns)} of the loads
        solved before: initial guesses of the next level's iterative solves."""
        return {
            n: self.at(doflocs.T, k, u).ravel()
            for n in names
            for k, u in self.fields.get(n, [])[-1:]
        }

    def at(self, points, k: int, u: np.ndarray, average: np.ndarray | None = None) -> np.ndarray:
        """Level k's field u at points by cubic interpolation of its nodal values
        (reference/lattice.py: O(h^4) everywhere), averaged over a window of cells
        along the axes ``average`` (m, dim) marks (the swing with the point's place in
        its cell then averages out, so the levels extrapolate cleanly)."""
        ev = self._evaluator(k)
        points = np.asarray(points, float)
        if average is None or not average.any():
            return ev.evaluate(u.reshape(-1, self.dim), points)
        return ev.evaluate_window(
            u.reshape(-1, self.dim), points, axis_maps(self.size, self.ns[k]), self.origin, average
        )

    def window_axes(self, points, n: int) -> np.ndarray:
        """(m, dim): the axes along which the window (one cell each way) fits inside the
        box at level n, and so at every finer level; never along an axis on whose end
        faces a point lies (there the cell coordinate is fixed and nothing swings)."""
        t = np.stack(
            [a.t(points[:, d] - self.origin[d]) for d, a in enumerate(axis_maps(self.size, n))],
            axis=1,
        )
        cells = np.array([a.cells for a in axis_maps(self.size, n)])
        return (t >= 1.0 - 1e-9) & (t <= cells - 1.0 + 1e-9)

    def values(self, points, load: str):
        """The load's kept levels evaluated at points: ([(n, dim) arrays], [h]); every
        level averaged along the same axes (those that fit at the coarsest of them)."""
        pairs = self.fields[load]
        points = np.asarray(points, float)
        average = (
            None
            if self.origin is None
            else self.window_axes(points, min(self.ns[k] for k, _ in pairs))
        )
        return (
            [self.at(points, k, u, average) for k, u in pairs],
            [1.0 / self.ns[k] for k, _ in pairs],
        )

    def evaluate(self, points, load: str):
        """(extrapolated displacement (n, dim), estimate of its error (n,)) at points."""
        vals, h = self.values(np.asarray(points, float), load)
        return extrapolate(vals, h, self.orders.get(load, float("nan")))

    def finest_field(self, load: str) -> np.ndarray:
        """The load's dof vector on the finest mesh: its own if solved there, else its
        (exactly represented) last field interpolated at the finest dof locations."""
        k, u = self.fields[load][-1]
        if k == len(self.meshes) - 1:
            return u
        return self.at(q2_doflocs(self.meshes[-1]).T, k, u).ravel()

    def to_arrays(self, names) -> dict:
        out = {
            "ns": np.asarray(self.ns, np.int64),
            "orders": np.array([self.orders.get(n, np.nan) for n in names]),
        }
        for i, n in enumerate(names):
            out[f"lv{i}"] = np.array([k for k, _ in self.fields[n]], np.int64)
            for k, u in self.fields[n]:
                out[f"u{i}_{k}"] = u
        return out

    @classmethod
    def from_arrays(cls, case, names, arrays) -> "Levels":
        lo, hi = case.body.bbox()
        lev = cls(case.dim, np.asarray(lo, float), np.asarray(hi - lo, float))
        for n in arrays["ns"]:
            lev.add_mesh(int(n), graded_mesh(lo, hi - lo, int(n)))
        for i, name in enumerate(names):
            lev.fields[name] = [(int(k), arrays[f"u{i}_{int(k)}"]) for k in arrays[f"lv{i}"]]
            if np.isfinite(arrays["orders"][i]):
                lev.orders[name] = float(arrays["orders"][i])
        return lev


def solve_graded(case, status=lambda msg: None, records: list | None = None):
    """(Levels, {load: relative estimate}, history rows) of a rectangle or box case."""
    spec = case.reference
    lo, hi = case.body.bbox()
    size = hi - lo
    names = [l.name for l in case.loads]
    probes = probe_points(lo, size)
    lev = Levels(
        case.dim, np.asarray(lo, float), np.asarray(size, float), fields={n: [] for n in names}
    )
    active = list(names)
    est = {n: float("nan") for n in names}
    mirrors = {l.name: mirror_of(case, l) for l in case.loads}
    history = []
    # divisions: cells along the shortest side
    first = -(-spec.divisions // 2) if spec.divisions else FIRST
    cap = (TENSOR_MAX_DOFS if spec.solver in ("auto", "tensor") else MAX_DOFS)[case.dim]

    def largest(n: int) -> int:
        axes = graded_axes(lo, size, n)
        return max(_dofs(lower_half(axes, mirrors[name]), case.dim) for name in active)

    k, n = 0, first
    while n <= first + spec.max_refine:
        if k > 0 and largest(n) > cap:
            status(
                f"FEM: the next graded level (a system of {largest(n)} dofs) would exceed "
                f"{cap}; stopping"
            )
            break
        axes = graded_axes(lo, size, n)
        mesh = tensor_mesh(axes)
        dofs = n_dofs(mesh, case.dim)
        status(
            f"FEM graded level {k} ({n} cells per end zone, {dofs} dofs, "
            f"largest system {largest(n)}, "
            f"{len(active)} loads)"
        )
        lev.add_mesh(n, mesh)
        U = lev.solve(case, k, axes, {name: mirrors[name] for name in active}, records=records)
        for name in active:
            lev.fields[name] = (lev.fields[name] + [(k, U[name])])[-3:]
        for name in list(active):
            vals, h = lev.values(probes, name)
            if len(vals) < 2:
                continue
            scale = max(float(np.linalg.norm(vals[-1], axis=1).max()), 1e-300)
            if np.abs(vals[-1] - vals[-2]).max() <= EXACT * scale:
                active.remove(name)  # represented exactly: no further level helps;
                lev.orders.pop(name, None)  # the coarser of the two (less rounding) goes last
                lev.fields[name] = lev.fields[name][-1:] + lev.fields[name][-2:-1]
            # a higher observed order is the next terms at work, not the leading one
            elif len(vals) >= 3:
                lev.orders[name] = min(FORMAL_ORDER, observed_order(vals[-3:], h[-3:]))
            _, e = extrapolate(vals, h, lev.orders.get(name, float("nan")))
            est[name] = float(e.max()) / scale
        history.append(dict(n_dofs=dofs, **est))
        if not active or (k >= 2 and max(est.values()) < spec.tol):
            break
        last = next((m for m in range(first + spec.max_refine, n, -1) if largest(m) <= cap), n + 1)
        k, n = k + 1, next_divisions(n, first, last)
    return lev, est, history


def next_divisions(n: int, first: int, last: int) -> int:
    """The level after n cells per end zone, ``last`` the finest one allowed: the first
    three and the last three levels are consecutive (the extrapolation and its order use
    the last three), every second n between them is skipped (those levels only decide
    when to stop; the 10:1 box at nu = 0.49 goes 2, 3, 4, 6, 8, 9, 10)."""
    if n < first + 2 or n >= last - 3:
        return n + 1
    return min(n + 2, last - 2)
