"""Mirror symmetry of a box problem: solve a half (quarter, eighth) and unfold.

A box of a mirror-invariant material whose constraints are invariant under the mirror
M_m about its mid-plane x_m = c_m, loaded by forces that are symmetric (S f(M x) = f(x))
or antisymmetric (S f(M x) = -f(x)) under it, S flipping component m, has a solution of
the same parity. The lower half with u_m = 0 (symmetric) or the other components = 0
(antisymmetric) on the mid-plane is the same problem with half the unknowns; a direct
solve of a quarter of a 3-D box costs ~1/16 of the whole. The shears of ``basic3d``
reduce to quarters (antisymmetric in the load's direction, symmetric in the third axis).

Parity is decided from the load's definition (parts, vectors), never from a solve: a
part is compared with its mirror image (a face/edge/corner name with the side flipped,
a user's box reflected), forces by their vectors; the material by its Voigt stiffness at
seeded points and their mirror images. Anything else (regions, a part that is not a
box part) keeps the whole box.
"""

from __future__ import annotations

import numpy as np

from harness.case.elasticity import element_stiffness
from harness.case.parts import parse_face_name
from reference.fem import VOIGT
from reference.lattice import Lattice
from reference.mirror import Mirror

PLACES = 12  # decimals to which a user part's corners are compared
SAMPLES = 64  # seeded points at which the material's mirror image is checked


def _part_key(name: str, case, lo, hi):
    parts = case.body.parts or {}
    if name in parts:
        plo, phi = (np.asarray(b, float) for b in parts[name])
        return ("box", tuple(np.round(plo, PLACES)), tuple(np.round(phi, PLACES)))
    faces = parse_face_name(name, case.dim)
    return None if faces is None else ("faces", frozenset(faces))


def _mirror_key(key, m: int, lo, hi):
    if key[0] == "faces":
        return ("faces", frozenset((a, 1 - s if a == m else s) for a, s in key[1]))
    plo, phi = np.array(key[1]), np.array(key[2])
    plo[m], phi[m] = lo[m] + hi[m] - key[2][m], lo[m] + hi[m] - key[1][m]
    return ("box", tuple(np.round(plo, PLACES)), tuple(np.round(phi, PLACES)))


def _flip(vector, m: int) -> np.ndarray:
    v = np.array(vector, float)
    v[m] = -v[m]
    return v


def material_is_symmetric(case, m: int) -> bool:
    """The Voigt stiffness at seeded points and at their mirror images agree, the shear
    rows and columns that mix axis m with another flipped (regions: never)."""
    if case.material.regions:
        return False
    lo, hi = case.body.bbox()
    x = lo + (hi - lo) * np.random.default_rng(0).random((SAMPLES, case.dim))
    xm = x.copy()
    xm[:, m] = lo[m] + hi[m] - x[:, m]
    T = np.array([-1.0 if (i == m) != (j == m) else 1.0 for i, j in VOIGT[case.dim]])
    C, Cm = element_stiffness(case.material, x), element_stiffness(case.material, xm)
    return bool(
        np.allclose(Cm, T[:, None] * C * T[None, :], rtol=1e-12, atol=1e-12 * np.abs(C).max())
    )


def _parity(case, load, m: int, lo, hi) -> int:
    """+1 or -1 if the load has that parity under M_m (constraints invariant), else 0."""
    if load.stress is not None:
        return 0
    cons = set()
    for c in load.constraints:
        key = _part_key(c.part, case, lo, hi)
        if key is None:
            return 0
        cons.add((key, tuple(sorted(c.components))))
    if {(_mirror_key(k, m, lo, hi), comp) for k, comp in cons} != cons:
        return 0
    forces = {}
    for t in load.tractions:
        key = _part_key(t.part, case, lo, hi)
        if key is None or t.twist is not None:  # a twist: solved whole
            return 0
        forces[key] = forces.get(key, 0.0) + np.asarray(t.vector, float)
    for p in (1, -1):
        ok = all(
            np.array_equal(p * _flip(v, m), forces.get(_mirror_key(k, m, lo, hi), 0.0 * v))
            for k, v in forces.items()
        )
        for g in (load.gravity, load.body_force):
            ok = ok and (g is None or np.array_equal(p * _flip(g, m), np.asarray(g, float)))
        if ok:
            return p
    return 0


def mirror_of(case, load) -> Mirror:
    """The mid-planes at which ``load`` on the case's box may be cut (none for a body
    that is not a box, an asymmetric material, constraints or forces)."""
    if case.body.shape not in ("box", "rectangle"):
        return Mirror()
    lo, hi = case.body.bbox()
    axes, parities = [], []
    for m in range(case.dim):
        p = _parity(case, load, m, lo, hi)
        if p and material_is_symmetric(case, m):
            axes.append(m)
            parities.append(p)
    return Mirror(tuple(axes), tuple(parities))


def lower_half(axes: list, mirror: Mirror) -> list:
    """The node coordinates of the kept part: the lower half (mid-plane included) of
    each cut axis, which must be symmetric with its midpoint a node."""
    out = []
    for a, x in enumerate(axes):
        if a in mirror.axes:
            if len(x) % 2 == 0 or not np.allclose(
                x, x[0] + x[-1] - x[::-1], rtol=0, atol=1e-12 * np.ptp(x)
            ):
                raise ValueError("a cut axis needs symmetric nodes with a node at its midpoint")
            x = x[: len(x) // 2 + 1]
        out.append(x)
    return out


def unfold(full: Lattice, half: Lattice, u: np.ndarray, mirror: Mirror) -> np.ndarray:
    """The kept part's dof vector (ns_half * dim,) -> the whole box's (ns_full * dim,):
    u(M x) = p S u(x) for every cut, on grids whose lower halves coincide."""
    dim = len(full.shape)
    idx = list(np.unravel_index(full.index, full.shape))
    sign = np.ones((len(full.index), dim))
    for m, p in zip(mirror.axes, mirror.parities):
        n = full.shape[m]
        if half.shape[m] != n // 2 + 1 or not np.allclose(half.axes[m], full.axes[m][: n // 2 + 1]):
            raise ValueError("the kept grid is not the lower half of the whole grid")
        upper = idx[m] > n // 2
        idx[m] = np.where(upper, n - 1 - idx[m], idx[m])
        sign[upper] *= p
        sign[upper, m] *= -1
    position = np.empty(len(half.index), np.int64)
    position[half.index] = np.arange(len(half.index))
    kept = position[np.ravel_multi_index(tuple(idx), half.shape)]
    return (sign * u.reshape(-1, dim)[kept]).ravel()
