"""The reference's methods, one object each, so that a solution never asks which method
made it. Each has

- ``solve(case, status, records) -> (method, estimates, history)`` (a classmethod): the
  solved fields, the relative estimate of every load and the rows of the levels;
- ``evaluate(points, load)``: the displacement (n, dim) at points (n, dim);
- ``estimate(points, load)``: the estimated error |u_h - u| (n,) there;
- ``to_arrays(names)`` / ``from_arrays(case, names, arrays)``: the cache's arrays;
- ``mesh``, ``fields`` ({load: dof vector on ``mesh``}), ``n_dofs`` and ``modal_disc``
  (the discretisation of the modal solves).

``graded`` (boxes): Q2 levels graded towards the faces, extrapolated (reference/graded/);
``adaptive`` (a user's triangles or tetrahedra): residual-driven refinement
(reference/adaptive/adapt.py); ``refine`` (any other body): uniform refinement
(reference/adaptive/refine.py). A load whose solution the element holds exactly is put
in closed form by every method alike (reference/problem.py ``homogeneous_field``).
"""

from __future__ import annotations

from collections.abc import Mapping
from functools import cached_property

import numpy as np

from reference.adaptive.adapt import Stop, solve_adaptive
from reference.adaptive.adapt import applies as adaptive_applies
from reference.adaptive.refine import solve_refined
from reference.adaptive.wide import Changes
from reference.fem import Discretisation
from reference.graded.levels import Levels, n_dofs, solve_graded
from reference.locate import Locator
from reference.mesh import MESHES

MODAL_DOFS = {2: 400_000, 3: 120_000}  # graded: the modes come from the finest level at most this
# large (the Sec. 6 cube's 108k-dof level factorises in ~3 GB; its 152k one would pass 6 GB, and its
# shift-invert CG took > 15 min). Frequencies converge like h^(2p), far faster than the scored
# displacements that need the finer levels.


class _OnMesh:
    """What every method has on its finest mesh ``mesh``: the discretisation and the point
    locator, made when first asked for; ``stop`` (why its levels ended: an adaptive
    method's reference/adaptive/adapt.py Stop, None for the others)."""

    stop = None

    @cached_property
    def disc(self) -> Discretisation:
        return Discretisation(self.mesh, self.case.reference.cell, self.case.reference.element)

    @cached_property
    def locator(self) -> Locator:
        return Locator(self.mesh)


class Refined(_OnMesh):
    """The finest of uniformly refined meshes; its estimate is the relative change from
    the previous level, the same at every point."""

    name = "refine"

    def __init__(self, case, mesh, fields: Mapping, estimates: dict):
        self.case, self.mesh, self.fields = case, mesh, fields
        self.dim = case.dim
        self._estimates = dict(estimates)

    @classmethod
    def solve(cls, case, status, records):
        mesh, U, est, history = solve_refined(case, status, records)
        return cls(case, mesh, U, est), est, history

    @property
    def modal_disc(self) -> Discretisation:
        return self.disc

    @property
    def n_dofs(self) -> int:
        return int(next(iter(self.fields.values())).size) if self.fields else 0

    def evaluate(self, points, load: str) -> np.ndarray:
        return self.locator.evaluate(
            self.disc.basis, self.fields[load].reshape(-1, self.dim), points
        )

    def u_max(self, load: str) -> float:
        nodal = self.fields[load].reshape(-1, self.dim)[: self.mesh.p.shape[1]]
        return float(np.linalg.norm(nodal, axis=1).max())

    def estimate(self, points, load: str) -> np.ndarray:
        """The load's relative estimate times its largest displacement at every point:
        the refinement estimate is a maximum over the probes, so it bounds each of them."""
        return np.full(len(points), float(self._estimates[load]) * self.u_max(load))

    def to_arrays(self, names) -> dict:
        return dict(p=self.mesh.p, t=self.mesh.t, u=np.stack([self.fields[n] for n in names]))

    @classmethod
    def from_arrays(cls, case, names, arrays: dict, estimates: dict):
        mesh = MESHES[case.reference.cell](arrays["p"], arrays["t"])
        return cls(case, mesh, {n: arrays["u"][i] for i, n in enumerate(names)}, estimates)


class Adaptive(Refined):
    """The finest of adaptively refined meshes; the estimate per point comes from the
    last changes between levels and their observed order (``changes``; None after a
    single level: then as :class:`Refined`); ``stop``: why the levels ended."""

    name = "adaptive"

    def __init__(
        self,
        case,
        mesh,
        fields: Mapping,
        estimates: dict,
        changes: Changes | None,
        stop: Stop | None = None,
    ):
        super().__init__(case, mesh, fields, estimates)
        self.changes, self.stop = changes, stop

    @classmethod
    def solve(cls, case, status, records):
        mesh, U, est, history, changes, stop = solve_adaptive(case, status, records)
        return cls(case, mesh, U, est, changes, stop), est, history

    def estimate(self, points, load: str) -> np.ndarray:
        if self.changes is None:
            return super().estimate(points, load)
        return self.changes.at(self.locator, self.disc.basis, points, load)

    def to_arrays(self, names) -> dict:
        return {
            **super().to_arrays(names),
            **(self.changes.to_arrays(names) if self.changes is not None else {}),
            **(self.stop.to_arrays() if self.stop is not None else {}),
        }

    @classmethod
    def from_arrays(cls, case, names, arrays: dict, estimates: dict):
        mesh = MESHES[case.reference.cell](arrays["p"], arrays["t"])
        return cls(
            case,
            mesh,
            {n: arrays["u"][i] for i, n in enumerate(names)},
            estimates,
            Changes.from_arrays(names, arrays),
            Stop.from_arrays(arrays),
        )


class Graded(_OnMesh):
    """Q2 levels of a box extrapolated: the field and its estimate per point are the
    extrapolant's (``levels``); ``fields`` are the finest level's."""

    name = "graded"

    def __init__(self, case, levels: Levels):
        self.case, self.levels = case, levels
        self.dim = case.dim
        self.mesh = levels.meshes[-1]
        self.fields = _FinestFields(levels)

    @classmethod
    def solve(cls, case, status, records):
        levels, est, history = solve_graded(case, status, records)
        return cls(case, levels), est, history

    @cached_property
    def modal_disc(self) -> Discretisation:
        """The finest level with at most MODAL_DOFS dofs (the coarsest if none is)."""
        sizes = [n_dofs(m, self.dim) for m in self.levels.meshes]
        k = max([i for i, n in enumerate(sizes) if n <= MODAL_DOFS[self.dim]], default=0)
        return self.disc if k == len(sizes) - 1 else self.levels.disc(self.levels.meshes[k])

    @property
    def n_dofs(self) -> int:
        return n_dofs(self.mesh, self.dim)

    def evaluate(self, points, load: str) -> np.ndarray:
        return self.levels.evaluate(points, load)[0]

    def estimate(self, points, load: str) -> np.ndarray:
        return self.levels.evaluate(points, load)[1]

    def to_arrays(self, names) -> dict:
        return self.levels.to_arrays(names)

    @classmethod
    def from_arrays(cls, case, names, arrays: dict, estimates: dict):
        return cls(case, Levels.from_arrays(case, names, arrays))


def method_of(case):
    """The method class that solves ``case`` (its ``[reference] method``, resolved)."""
    if case.reference.method == "graded":
        return Graded
    return Adaptive if adaptive_applies(case) else Refined


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
