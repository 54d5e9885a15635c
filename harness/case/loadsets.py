"""Load cases: constraints and tractions on named parts, body forces.

The standard sets ``basic2d`` (Deussen 1995 Fig. 4) and ``basic3d`` (Fig. 7) are
defined here once (docs/design.md, "Load sets for boxes"), and every consumer (the
FEM reference, the spring networks, the anisotropic model) applies these objects.
The sets are registered by name in ``harness.registry.LOAD_SETS``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

AXES = "xyz"


@dataclass(frozen=True)
class Constraint:
    """Displacement components ``components`` (0=x, 1=y, 2=z) are zero on ``part``."""

    part: str
    components: tuple[int, ...]


@dataclass(frozen=True)
class Traction:
    """A constant traction ``vector`` (force per area in 3-D, per length in 2-D with unit
    thickness) on the boundary ``part``. With ``twist`` w (3-D; stress per length) it is
    t(x) = vector + w x (x - c), c the area centroid of the part's facets: w x (x - c)
    has no resultant, only the torque int (x - c) x (w x (x - c)) dA (torsion)."""

    part: str
    vector: tuple[float, ...]
    twist: tuple[float, ...] | None = None


@dataclass(frozen=True)
class Frame:
    """A body's centroid and size L (its largest bounding-box extent): the scaled
    coordinates xi = (x - centroid) / L of the linear stress states, |xi| <~ 1."""

    centroid: tuple[float, ...]
    size: float

    def xi(self, x) -> np.ndarray:
        """Scaled coordinates of points x (..., dim)."""
        return (np.asarray(x, float) - np.asarray(self.centroid, float)) / self.size


@dataclass(frozen=True)
class LoadCase:
    """One static load case. ``gravity`` is an acceleration (force = density * g);
    ``body_force`` a force per volume; both may be None. ``stress`` (Voigt, VOIGT
    order) is a stress state whose traction sigma . n acts on the whole boundary (the
    ``homogeneous`` sets on bodies that are not boxes, the ``linear`` sets on any): constant, or
    with
    ``stress_gradient`` G (dim rows of Voigt entries, G[k] = d sigma / d xi_k in the
    coordinates of ``frame``) the linear field sigma(x) = stress + sum_k xi_k G[k]
    (:func:`stress_field`); ``stress`` is then its value at the frame's centroid.
    ``family`` groups the states of a set (:func:`family`); None for user loads."""

    name: str
    constraints: tuple[Constraint, ...]
    tractions: tuple[Traction, ...] = ()
    gravity: tuple[float, ...] | None = None
    body_force: tuple[float, ...] | None = None
    stress: tuple[float, ...] | None = None
    stress_gradient: tuple[tuple[float, ...], ...] | None = None
    frame: Frame | None = None
    family: str | None = None

    def __post_init__(self):
        if self.stress_gradient is not None and (self.stress is None or self.frame is None):
            raise ValueError(
                f"load '{self.name}': a stress gradient needs its constant part and its frame"
            )

    @property
    def parts(self) -> set[str]:
        return {c.part for c in self.constraints} | {t.part for t in self.tractions}


def family(load: LoadCase) -> str | None:
    """The family of a standard set's load case ('constant', 'bending', 'torsion',
    'shear-gradient', 'gravity'; harness/case/linear_states.py), None for the others:
    the groups a calibration leaves out one at a time."""
    return load.family


def _unit(dim: int, axis: int, s: float) -> tuple[float, ...]:
    v = [0.0] * dim
    v[axis] = float(s)
    return tuple(v)


def basic2d(s: float, anchors=None, frame=None) -> tuple[LoadCase, ...]:
    """Deussen Fig. 4: two stretches (rollers + one pinned corner) and two shears."""
    return (
        LoadCase(
            "stretch-x",
            (Constraint("x0", (0,)), Constraint("x0y0", (1,))),
            (Traction("x1", (s, 0.0)),),
        ),
        LoadCase(
            "stretch-y",
            (Constraint("y0", (1,)), Constraint("x0y0", (0,))),
            (Traction("y1", (0.0, s)),),
        ),
        LoadCase("shear-x", (Constraint("y0", (0, 1)),), (Traction("y1", (s, 0.0)),)),
        LoadCase("shear-y", (Constraint("x0", (0, 1)),), (Traction("x1", (0.0, s)),)),
    )


def basic3d(s: float, anchors=None, frame=None) -> tuple[LoadCase, ...]:
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
        cases.append(
            LoadCase(
                f"stretch-{A}",
                (Constraint(f"{A}0", (a,)), Constraint(corner0, (b, c)), Constraint(corner1, (c,))),
                (Traction(f"{A}1", _unit(3, a, s)),),
            )
        )
    for a, b in ((0, 1), (1, 0), (0, 2), (2, 0), (1, 2), (2, 1)):
        cases.append(
            LoadCase(
                f"shear-{AXES[a]}{AXES[b]}",
                (Constraint(f"{AXES[b]}0", (0, 1, 2)),),
                (Traction(f"{AXES[b]}1", _unit(3, a, s)),),
            )
        )
    return tuple(cases)


VOIGT = {2: ((0, 0), (1, 1), (0, 1)), 3: ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))}
ANCHORS = ("anchor-a", "anchor-b", "anchor-c")  # part names of the minimal constraints


def stress_tensor(voigt) -> "np.ndarray":
    """Voigt stress (VOIGT order) -> symmetric (dim, dim) tensor; (..., nv) -> (..., dim, dim)."""
    voigt = np.asarray(voigt, float)
    dim = 2 if voigt.shape[-1] == 3 else 3
    sig = np.zeros(voigt.shape[:-1] + (dim, dim))
    for I, (i, j) in enumerate(VOIGT[dim]):
        sig[..., i, j] = sig[..., j, i] = voigt[..., I]
    return sig


def stress_field(load: LoadCase, x) -> "np.ndarray":
    """The load's stress (..., dim, dim) at points x (..., dim): ``load.stress``, plus
    sum_k xi_k G[k] with its gradient (LoadCase)."""
    x = np.asarray(x, float)
    voigt = np.broadcast_to(np.asarray(load.stress, float), x.shape[:-1] + (len(load.stress),))
    if load.stress_gradient is not None:
        voigt = voigt + load.frame.xi(x) @ np.asarray(load.stress_gradient, float)
    return stress_tensor(voigt)


def anchor_points(points) -> np.ndarray:
    """Three (2-D: two) well-separated points of a body's boundary vertices (m, dim) for
    the minimal constraints: A farthest from the centroid, B farthest from A, C farthest
    off the line AB. Near-ties (symmetric bodies have many) go to the lexicographically
    smallest point, so rounding the coordinates cannot change the choice."""
    p = np.asarray(points, float)
    tol = 1e-9 * float(np.ptp(p, axis=0).max())
    # lexicographic on rounded coordinates
    key = np.round(p / max(tol, 1e-300) / 1e3) if tol > 0 else p

    def pick(score):
        cand = np.flatnonzero(score >= score.max() - tol * 1e3)
        return p[cand[np.lexsort(key[cand].T[::-1])[0]]]

    a = pick(np.linalg.norm(p - p.mean(0), axis=1))
    b = pick(np.linalg.norm(p - a, axis=1))
    if p.shape[1] == 2:
        return np.array([a, b])
    d = (b - a) / np.linalg.norm(b - a)
    r = (p - a) - np.outer((p - a) @ d, d)
    return np.array([a, b, pick(np.linalg.norm(r, axis=1))])


def minimal_constraints(anchors, names=ANCHORS) -> tuple[Constraint, ...]:
    """3-2-1 (2-D: 2-1) constraints at the anchor points that remove exactly the rigid
    motions: A all components; B the components across AB's main direction; C the
    component along the normal of the plane ABC (its largest entry)."""
    p = np.asarray(anchors, float)
    dim = p.shape[1]
    main = int(np.argmax(np.abs(p[1] - p[0])))
    cons = [
        Constraint(names[0], tuple(range(dim))),
        Constraint(names[1], tuple(c for c in range(dim) if c != main)),
    ]
    if dim == 3:
        n = np.cross(p[1] - p[0], p[2] - p[0])
        cons.append(Constraint(names[2], (int(np.argmax(np.abs(n))),)))
    return tuple(cons)


def homogeneous(dim: int, s: float, anchors=None) -> tuple[LoadCase, ...]:
    """The homogeneous stress states (docs/design.md, "Load sets for any shape"), one unit
    Voigt component times s each (sxx, syy, [szz, syz, sxz,] sxy). A box gets them as face
    tractions sigma . n and the corner constraints of the stretches; any other body
    (``anchors``: its anchor points) as ``stress`` on the whole boundary with minimal
    constraints at the anchors."""
    out = []
    for I, (i, j) in enumerate(VOIGT[dim]):
        voigt = np.zeros(len(VOIGT[dim]))
        voigt[I] = s
        name = f"s{AXES[i]}{AXES[j]}"
        if anchors is not None:
            out.append(
                LoadCase(name, minimal_constraints(anchors), stress=tuple(voigt), family="constant")
            )
            continue
        sig = stress_tensor(voigt)
        tracs = []
        for a in range(dim):
            for side, sign in ((0, -1.0), (1, 1.0)):
                t = sign * sig[:, a]
                if np.any(t):
                    tracs.append(Traction(f"{AXES[a]}{side}", tuple(float(v) for v in t)))
        corners = [(0,) * dim, (1,) + (0,) * (dim - 1), (0, 1) + (0,) * (dim - 2)]
        names = ["".join(f"{AXES[a]}{c[a]}" for a in range(dim)) for c in corners]
        out.append(
            LoadCase(
                name,
                minimal_constraints(np.array(corners[:dim], float), names),
                tuple(tracs),
                family="constant",
            )
        )
    return tuple(out)


def homogeneous2d(s: float, anchors=None, frame=None) -> tuple[LoadCase, ...]:
    return homogeneous(2, s, anchors)


def homogeneous3d(s: float, anchors=None, frame=None) -> tuple[LoadCase, ...]:
    return homogeneous(3, s, anchors)


def _box_stress(load: LoadCase, dim: int):
    """The Voigt stress of a box's homogeneous load from its x1/y1/z1 face tractions."""
    sig = np.zeros((dim, dim))
    for t in load.tractions:
        a, side = AXES.index(t.part[0]), int(t.part[1])
        if side == 1:
            sig[:, a] = t.vector
    return tuple(sig[i, j] for i, j in VOIGT[dim])


def stretch_closed_form(load: LoadCase, points, E: float, nu: float, origin):
    """Closed-form displacement (n, dim) of a standard stretch of a homogeneous isotropic
    box (plane stress in 2-D): u_a = s (a - a0)/E, others -nu s (b - b0)/E."""
    points = np.asarray(points, float)
    (t,) = load.tractions
    a = int(np.flatnonzero(t.vector)[0])
    s = t.vector[a]
    rel = points - np.asarray(origin, float)
    u = -nu * s * rel / E
    u[:, a] = s * rel[:, a] / E
    return u
