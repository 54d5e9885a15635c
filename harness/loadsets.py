"""Load cases: constraints and tractions on named parts, body forces.

The standard sets ``basic2d`` (Deussen 1995 Fig. 4) and ``basic3d`` (Fig. 7) are
defined here once, exactly as ``shared/DESIGN.md`` states, and every consumer (the
FEM reference, the spring networks, the anisotropic model) applies these objects.
A new load set is one function registered in ``LOAD_SETS``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

AXES = "xyz"


@dataclass(frozen=True)
class Constraint:
    """Displacement components ``components`` (0=x, 1=y, 2=z) are zero on ``part``."""
    part: str
    components: tuple[int, ...]


@dataclass(frozen=True)
class Traction:
    """A constant traction ``vector`` (force per area in 3-D, per length in 2-D with unit
    thickness) on the boundary ``part``."""
    part: str
    vector: tuple[float, ...]


@dataclass(frozen=True)
class LoadCase:
    """One static load case. ``gravity`` is an acceleration (force = density * g);
    ``body_force`` a force per volume; both may be None."""
    name: str
    constraints: tuple[Constraint, ...]
    tractions: tuple[Traction, ...] = ()
    gravity: tuple[float, ...] | None = None
    body_force: tuple[float, ...] | None = None

    @property
    def parts(self) -> set[str]:
        return {c.part for c in self.constraints} | {t.part for t in self.tractions}


def _unit(dim: int, axis: int, s: float) -> tuple[float, ...]:
    v = [0.0] * dim
    v[axis] = float(s)
    return tuple(v)


def basic2d(s: float) -> tuple[LoadCase, ...]:
    """Deussen Fig. 4: two stretches (rollers + one pinned corner) and two shears."""
    return (
        LoadCase("stretch-x", (Constraint("x0", (0,)), Constraint("x0y0", (1,))),
                 (Traction("x1", (s, 0.0)),)),
        LoadCase("stretch-y", (Constraint("y0", (1,)), Constraint("x0y0", (0,))),
                 (Traction("y1", (0.0, s)),)),
        LoadCase("shear-x", (Constraint("y0", (0, 1)),), (Traction("y1", (s, 0.0)),)),
        LoadCase("shear-y", (Constraint("x0", (0, 1)),), (Traction("x1", (0.0, s)),)),
    )


def basic3d(s: float) -> tuple[LoadCase, ...]:
    """Deussen Fig. 7: three stretches and six shears on a box.

    stretch-a: rollers on face a0, the corner (a0, b0, c0) fixed in b and c, the
    corner (a0, b1, c0) fixed in c (b < c are the other two axes): no rigid motion
    is left and the closed form u_a = s(a - a0)/E, u_b = -nu s (b - b0)/E satisfies
    every constraint. shear-ab: face b0 clamped, traction s along a on face b1.
    """
    cases = []
    for a in range(3):
        b, c = [i for i in range(3) if i != a]
        A, B, C = AXES[a], AXES[b], AXES[c]
        corner0 = "".join(sorted([f"{A}0", f"{B}0", f"{C}0"], key=lambda t: AXES.index(t[0])))
        corner1 = "".join(sorted([f"{A}0", f"{B}1", f"{C}0"], key=lambda t: AXES.index(t[0])))
        cases.append(LoadCase(
            f"stretch-{A}",
            (Constraint(f"{A}0", (a,)), Constraint(corner0, (b, c)), Constraint(corner1, (c,))),
            (Traction(f"{A}1", _unit(3, a, s)),)))
    for a, b in ((0, 1), (1, 0), (0, 2), (2, 0), (1, 2), (2, 1)):
        cases.append(LoadCase(
            f"shear-{AXES[a]}{AXES[b]}", (Constraint(f"{AXES[b]}0", (0, 1, 2)),),
            (Traction(f"{AXES[b]}1", _unit(3, a, s)),)))
    return tuple(cases)


LOAD_SETS: dict[str, tuple[int, Callable[[float], tuple[LoadCase, ...]]]] = {
    "basic2d": (2, basic2d),
    "basic3d": (3, basic3d),
}


def stretch_closed_form(load: LoadCase, points, E: float, nu: float, origin):
    """Closed-form displacement (n, dim) of a standard stretch of a homogeneous isotropic
    box (plane stress in 2-D): u_a = s (a - a0)/E, others -nu s (b - b0)/E."""
    import numpy as np
    points = np.asarray(points, float)
    (t,) = load.tractions
    a = int(np.flatnonzero(t.vector)[0])
    s = t.vector[a]
    rel = points - np.asarray(origin, float)
    u = -nu * s * rel / E
    u[:, a] = s * rel[:, a] / E
    return u
