"""Named boundary parts of a body, as point predicates shared by the FEM and every model.

Built-in names are intersections of bounding-box faces: ``x0`` is the face x = xmin,
``x1`` the face x = xmax (likewise y, z); ``x0y0`` is their intersection (a corner in
2-D, an edge in 3-D), ``x0y0z0`` a corner in 3-D. User parts are axis-aligned boxes
declared in ``[body.parts]``, groups of the body's mesh file (harness.io.mesh_groups), its
end faces along an axis (harness.io.end_faces) or the facets a node file, a box or a sphere
selects (harness.case.selectors).
A predicate takes coordinates shaped (dim, n), as scikit-fem does, and returns a
boolean mask.
"""

from __future__ import annotations

import re
from typing import Callable, Mapping

import numpy as np

from harness.case.selectors import SelectorPart, selector_predicate
from harness.io.end_faces import EndPart, end_predicate
from harness.io.mesh_groups import GroupPart, group_predicate

FACE = re.compile(r"([xyz])([01])")
AXES = "xyz"


def parse_face_name(name: str, dim: int) -> list[tuple[int, int]] | None:
    """``"x0y1"`` -> [(0, 0), (1, 1)]; None if ``name`` is not a face combination."""
    tokens = FACE.findall(name)
    if not tokens or "".join(a + s for a, s in tokens) != name:
        return None
    out = [(AXES.index(a), int(s)) for a, s in tokens]
    axes = [a for a, _ in out]
    if len(set(axes)) != len(axes) or max(axes) >= dim:
        return None
    return out


RTOL = 1e-8  # a point is on a face or in a part within RTOL times the body's diagonal


def geometric_tol(bbox, rtol: float = RTOL) -> float:
    """The absolute distance within which a point counts as on a face or in a part."""
    lo, hi = (np.asarray(b, float) for b in bbox)
    return rtol * float(np.linalg.norm(hi - lo))


def part_predicate(
    name: str,
    bbox: tuple[np.ndarray, np.ndarray],
    user_parts: Mapping[str, tuple] | None = None,
    rtol: float = RTOL,
) -> Callable[[np.ndarray], np.ndarray]:
    """Predicate for the named part; raises KeyError for an unknown name."""
    lo, hi = (np.asarray(b, float) for b in bbox)
    tol = geometric_tol(bbox, rtol)
    if user_parts and isinstance(user_parts.get(name), GroupPart):
        return group_predicate(user_parts[name], tol)
    if user_parts and isinstance(user_parts.get(name), EndPart):
        return end_predicate(user_parts[name], tol)
    if user_parts and isinstance(user_parts.get(name), SelectorPart):
        return selector_predicate(user_parts[name], tol)
    if user_parts and name in user_parts:
        plo, phi = (np.asarray(b, float) for b in user_parts[name])

        def in_box(x):
            x = np.asarray(x, float)
            return np.all((x >= plo[:, None] - tol) & (x <= phi[:, None] + tol), axis=0)

        return in_box
    faces = parse_face_name(name, len(lo))
    if faces is None:
        raise KeyError(name)

    def on_faces(x):
        x = np.asarray(x, float)
        mask = np.ones(x.shape[1], bool)
        for axis, side in faces:
            mask &= np.abs(x[axis] - (hi if side else lo)[axis]) <= tol
        return mask

    return on_faces


def part_exists(name: str, dim: int, user_parts: Mapping | None = None) -> bool:
    return bool(user_parts and name in user_parts) or parse_face_name(name, dim) is not None


def classify_nodes(
    points: np.ndarray, bbox, boundary: np.ndarray | None = None, rtol: float = RTOL
) -> np.ndarray:
    """Node classes for the G weights: 0 inner, 1 border, 2 corner (docs/design.md, "The G
    criteria").

    ``points`` is (n, dim). A corner is a vertex of the bounding box; a border node
    is any other node on the boundary: on a bounding-box face, or flagged in
    ``boundary`` (for bodies that are not boxes).
    """
    points = np.asarray(points, float)
    lo, hi = (np.asarray(b, float) for b in bbox)
    tol = geometric_tol(bbox, rtol)
    on = (np.abs(points - lo) <= tol) | (np.abs(points - hi) <= tol)
    n_on = on.sum(axis=1)
    cls = np.zeros(len(points), int)
    cls[n_on >= 1] = 1
    if boundary is not None:
        cls[np.asarray(boundary, bool)] = np.maximum(cls[np.asarray(boundary, bool)], 1)
    cls[n_on == points.shape[1]] = 2
    return cls
