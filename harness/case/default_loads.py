"""Held-out structural loads for any mesh (what ``calibrate`` scores a fit on without
fitting it): the body is clamped at the low end of its longest axis and loaded across
it, the way a bar, a beam or an organ held at one end is.

- ``sag``: gravity (9.81 m/s^2) along the body's thinnest other axis, the clamp holding;
- ``tip``: a traction s along the same axis on the high end's surface;
- ``torsion`` (3-D): the twist t = tau e_axis x (x - c) on the same surface (c its
  centroid: a torque, no resultant), tau = s / r with r the largest distance of its
  nodes from the long axis through their centroid, so the peak traction is s.

The ends are slabs across the longest axis, 5 % of its length thick, thickened (x 1.5 at
a time) until the clamp holds three non-collinear boundary nodes (two in 2-D) and the tip
holds a boundary facet; both are boxes in ``[body.parts]`` (``clamp``, ``tip``). Either
may instead be a named group of the mesh (``calibrate --clamp`` / ``--load-region``).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

from harness.errors import SpringbenchError
from harness.io.meshfile import boundary_facets

SLAB = 0.05
GRAVITY = 9.81


@dataclass(frozen=True)
class EndLoads:
    axis: int                      # the longest axis: clamp at its low end, tip at its high end
    across: int                    # the load direction (the thinnest other axis)
    clamp: tuple | str             # (lo, hi) boxes, or the names of mesh groups
    tip: tuple | str
    thickness: float
    radius: float = math.nan       # of the tip about the long axis (the torsion's tau = s / radius)
    dim: int = 3

    @property
    def names(self) -> tuple[str, ...]:
        return ("sag", "tip", "torsion") if self.dim == 3 else ("sag", "tip")

    def describe(self) -> str:
        a, b = "xyz"[self.axis], "xyz"[self.across]
        where = lambda p, end: f"group '{p}'" if isinstance(p, str) else f"the {a}-{end} end"   # noqa: E731
        twist = f" and 'torsion' (a twist about {a}, peak traction = the tip's)" if self.dim == 3 else ""
        slabs = "" if isinstance(self.clamp, str) and isinstance(self.tip, str) else \
            f" (slabs {self.thickness:.3g} thick)"
        return (f"held-out loads: 'sag' (gravity along -{b}), 'tip' (traction along -{b}){twist} on "
                f"{where(self.tip, 'max')}, {where(self.clamp, 'min')} clamped{slabs}")

    def toml(self, s: float) -> tuple[str, str]:
        """([body.parts] lines, [[loads.case]] tables) of the loads, tip traction s."""
        dim = self.dim
        g = [0.0] * dim
        g[self.across] = -GRAVITY
        t = [0.0] * dim
        t[self.across] = -float(s)
        part = lambda b: (f"{{ group = {json.dumps(b)} }}" if isinstance(b, str) else      # noqa: E731
                          f"{{ box = [{list(map(float, b[0]))}, {list(map(float, b[1]))}] }}")
        clamp = '[[loads.case.constraint]]\npart = "clamp"\ncomponents = "all"\n'
        cases = (f'[[loads.case]]\nname = "sag"\ngravity = {g}\n{clamp}'
                 f'[[loads.case]]\nname = "tip"\n{clamp}[[loads.case.traction]]\npart = "tip"\nvector = {t}\n')
        if dim == 3:
            w = [0.0] * 3
            w[self.axis] = float(s) / self.radius
            cases += f'[[loads.case]]\nname = "torsion"\n{clamp}[[loads.case.traction]]\npart = "tip"\ntwist = {w}\n'
        return f"clamp = {part(self.clamp)}\ntip = {part(self.tip)}\n", cases


def end_loads(points: np.ndarray, cells, clamp: str | None = None, tip: str | None = None,
              groups=None) -> EndLoads:
    """The clamp and tip slabs of a mesh (points (n, dim), meshio-style cells), or the
    mesh groups named ``clamp`` / ``tip`` (``groups``: harness.io.meshfile.Mesh.groups)."""
    points = np.asarray(points, float)
    dim = points.shape[1]
    lo, hi = points.min(axis=0), points.max(axis=0)
    size = hi - lo
    axis = int(np.argmax(size))
    others = [a for a in range(dim) if a != axis]
    across = min(others, key=lambda a: size[a])
    facets = boundary_facets(cells)
    bnodes = np.unique(np.concatenate([f.ravel() for f in facets]))
    pad = 1e-6 * float(size.max())

    def nodes_of(name):
        g = groups[name]
        return np.unique(np.concatenate([c.ravel() for c in g.cells.values()] + [g.nodes]).astype(int))

    def holds(nodes):
        c = points[nodes] - points[nodes].mean(axis=0) if len(nodes) else np.zeros((0, dim))
        return len(nodes) >= dim and np.linalg.matrix_rank(c, tol=1e-9 * size.max()) >= dim - 1
    if clamp is not None and not holds(nodes_of(clamp)):
        raise SpringbenchError(f"group '{clamp}' cannot clamp the body ({dim} nodes not on one line needed)",
                               field="--clamp", fix="name a face group of the mesh")
    t = SLAB * size[axis]
    while t <= 0.5 * size[axis]:
        x = points[:, axis]
        clamp_ok = clamp is not None or holds(bnodes[x[bnodes] <= lo[axis] + t])
        tip_ok = tip is not None or any(np.any(np.all(x[f] >= hi[axis] - t, axis=1)) for f in facets)
        if clamp_ok and tip_ok:
            clamp_hi, tip_lo = hi + pad, lo - pad
            clamp_hi[axis] = lo[axis] + t
            tip_lo[axis] = hi[axis] - t
            held = nodes_of(tip) if tip is not None else bnodes[x[bnodes] >= hi[axis] - t]
            return EndLoads(axis, across, clamp if clamp is not None else (tuple(lo - pad), tuple(clamp_hi)),
                            tip if tip is not None else (tuple(tip_lo), tuple(hi + pad)), t,
                            _radius(points, facets, held, axis) if dim == 3 else math.nan, dim)
        t *= 1.5
    raise SpringbenchError("no end of the mesh's longest axis can be clamped (too few boundary nodes there)",
                           field="mesh", fix="refine the mesh, or pass --heldout none")


def _radius(points, facets, held, axis: int) -> float:
    """Largest distance from the long axis through c of the held nodes, c the area
    centroid of the boundary facets they hold (where the twist's c lies)."""
    inside = np.zeros(len(points), bool)
    inside[held] = True
    area, moment = 0.0, 0.0
    for f in facets:
        x = points[f[inside[f].all(axis=1)]]
        for i in range(1, x.shape[1] - 1):      # fan triangles (x0, xi, xi+1)
            a = 0.5 * np.linalg.norm(np.cross(x[:, i] - x[:, 0], x[:, i + 1] - x[:, 0]), axis=1)
            area += a.sum()
            moment = moment + (a[:, None] * (x[:, 0] + x[:, i] + x[:, i + 1]) / 3).sum(axis=0)
    if area == 0:
        raise SpringbenchError("the loaded region holds no boundary facet", field="--load-region",
                               fix="name a group of the mesh's surface")
    r = points[held] - moment / area
    r[:, axis] = 0.0
    return float(np.linalg.norm(r, axis=1).max())
