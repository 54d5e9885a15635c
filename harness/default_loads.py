"""Held-out structural loads for any mesh (what ``calibrate`` scores a fit on without
fitting it): the body is clamped at the low end of its longest axis and loaded across
it, the way a bar, a beam or an organ held at one end is.

- ``sag``: gravity (9.81 m/s^2) along the body's thinnest other axis, the clamp holding;
- ``tip``: a traction s along the same axis on the high end's surface.

The ends are slabs across the longest axis, 5 % of its length thick, thickened (x 1.5 at
a time) until the clamp holds three non-collinear boundary nodes (two in 2-D) and the tip
holds a boundary facet; both are boxes in ``[body.parts]`` (``clamp``, ``tip``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from harness.errors import SpringbenchError
from harness.meshfile import boundary_facets

SLAB = 0.05
GRAVITY = 9.81


@dataclass(frozen=True)
class EndLoads:
    axis: int                      # the longest axis: clamp at its low end, tip at its high end
    across: int                    # the load direction (the thinnest other axis)
    clamp: tuple                   # (lo, hi) boxes
    tip: tuple
    thickness: float

    def describe(self) -> str:
        a, b = "xyz"[self.axis], "xyz"[self.across]
        return (f"held-out loads: 'sag' (gravity along -{b}) and 'tip' (traction along -{b} on the {a}-max end), "
                f"the {a}-min end clamped (slabs {self.thickness:.3g} thick)")

    def toml(self, s: float) -> tuple[str, str]:
        """([body.parts] lines, [[loads.case]] tables) of the two loads, tip traction s."""
        dim = len(self.clamp[0])
        g = [0.0] * dim
        g[self.across] = -GRAVITY
        t = [0.0] * dim
        t[self.across] = -float(s)
        box = lambda b: f"{{ box = [{list(map(float, b[0]))}, {list(map(float, b[1]))}] }}"   # noqa: E731
        clamp = '[[loads.case.constraint]]\npart = "clamp"\ncomponents = "all"\n'
        return (f"clamp = {box(self.clamp)}\ntip = {box(self.tip)}\n",
                f'[[loads.case]]\nname = "sag"\ngravity = {g}\n{clamp}'
                f'[[loads.case]]\nname = "tip"\n{clamp}[[loads.case.traction]]\npart = "tip"\nvector = {t}\n')


def end_loads(points: np.ndarray, cells) -> EndLoads:
    """The clamp and tip slabs of a mesh (points (n, dim), meshio-style cells)."""
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
    t = SLAB * size[axis]
    while t <= 0.5 * size[axis]:
        x = points[:, axis]
        in_clamp = bnodes[x[bnodes] <= lo[axis] + t]
        tip_ok = any(np.any(np.all(x[f] >= hi[axis] - t, axis=1)) for f in facets)
        c = points[in_clamp] - points[in_clamp].mean(axis=0) if len(in_clamp) else np.zeros((0, dim))
        if len(in_clamp) >= dim and np.linalg.matrix_rank(c, tol=1e-9 * size.max()) >= dim - 1 and tip_ok:
            clamp_hi, tip_lo = hi + pad, lo - pad
            clamp_hi[axis] = lo[axis] + t
            tip_lo[axis] = hi[axis] - t
            return EndLoads(axis, across, (tuple(lo - pad), tuple(clamp_hi)), (tuple(tip_lo), tuple(hi + pad)), t)
        t *= 1.5
    raise SpringbenchError("no end of the mesh's longest axis can be clamped (too few boundary nodes there)",
                           field="mesh", fix="refine the mesh, or pass --heldout none")
