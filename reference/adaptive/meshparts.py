"""A mesh body's box parts resolved on the user's mesh, for the refined levels of its
reference.

A ``[body.parts]`` box that cuts through the user's elements (calibrate's clamp and tip
slabs do) would otherwise select different regions on every refinement: new vertices
inside the box are clamped and new boundary facets inside it loaded, so the clamped
region grows towards the box and the load's resultant changes from level to level
(measured: a tip traction's resultant 3.04 N on an 875-tet cylinder, 3.21 N after
adaptive refinement, 4.7 N in the limit). Here a point belongs to a box part when the
entity of the user's mesh it lies on (vertex, edge, face or cell: the vertices with a
positive barycentric coordinate) has all its vertices in the box: the clamped region
and the loaded facets of every level are those of the user's mesh, which the spring
models on its nodes see too. Parts that are faces of the bounding box or mesh groups
select refinement-invariant sets already and are left as they are.
"""

from __future__ import annotations

import numpy as np

from harness.case.parts import part_predicate
from reference.locate import Locator

BARY = 1e-9  # a barycentric coordinate below this is zero (the point lies on a face)


class UserMeshParts:
    """``parts(name, bbox)`` -> point predicate (x (dim, n) -> (n,) bool), the
    replacement of harness.case.parts.part_predicate that reference/problem.py accepts."""

    def __init__(self, case, mesh):
        self.case = case
        self.mesh = mesh
        self._locator = None

    def __call__(self, name: str, bbox):
        base = part_predicate(name, bbox, self.case.body.parts)
        if not isinstance((self.case.body.parts or {}).get(name), tuple):
            return base
        flag = base(self.mesh.p)

        def on_user_entities(x):
            x = np.asarray(x, float)
            inside = base(x)  # the entities of a box lie in the box
            idx = np.flatnonzero(inside)
            if len(idx):
                inside[idx] = self._closure(flag, x[:, idx])
            return inside

        return on_user_entities

    def _closure(self, flag: np.ndarray, x: np.ndarray) -> np.ndarray:
        if self._locator is None:
            self._locator = Locator(self.mesh)
        elem, X = self._locator.locate(x.T)
        lam = np.vstack([1.0 - X.sum(axis=0), X])
        return np.all(flag[self.mesh.t[:, elem]] | (lam < BARY), axis=0)
