"""The adaptive reference's estimate (reference/adaptive/adapt.py): Richardson's over the
levels, with the number of dofs N in place of the mesh size (h = N^(-1/dim)), taken over
*wide* steps: the finest level k, the last level i with at most 1/WIDE^2 of its dofs
(else the first level) and the level j between them nearest their middle in log dofs
(without one, j is the first level and there is no i). With r = h_j / h_k and the order
p of the largest changes of the three (fitted exactly to the two changes, between 1 and
the degree k: HIGHEST; 1, the most conservative, with two levels), the error of u_k at a
point is

    F * max(|u_k - u_j| / (r^p - 1),  |u_j - u_i| / ((h_i^p - h_j^p) / h_k^p))

(the second term: the previous step carried forward, for points where the last change
happens to vanish), F Roache's factor of safety: 1.25 when three levels give the order,
3 with two. Consecutive adaptive levels add only 25-40 % dofs (r ~ 1.1 in 3-D), so
1 / (r^p - 1) would amplify their erratic pointwise changes ~10x (on the B&C tetra cube_333
shears: 0.12-0.15 of max |u| where the true error, against an independent graded Q2
solve, is 0.012-0.014), so the estimate is taken over wide steps: there it is 1.3-2.7x the true
error at the worst point and above it at every vertex (tests/reference/test_adaptive.py checks a
cube body the same way). On nested meshes a coarser level's field lies in the finest
level's space, so both changes are kept as dof vectors of the finest mesh and the
estimate is exact to evaluate at any point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reference.fem import Discretisation
from reference.graded.extrapolate import ORDER_RANGE, SAFETY
from reference.locate import Locator

WIDE = 4.0  # the estimate's levels are about this factor apart in dofs (when they span WIDE^2)
SAFETY_THREE = 1.25  # Roache's factor of safety when three levels give the observed order
EXACT = 1e-9  # a change below this share of the largest displacement is rounding
FIT = 4  # changes the order is fitted to at most
HIGHEST = {"P1": 1.0, "P2": 2.0}  # the observed order at most the degree k: point values
# converge at k + 1 only where the solution is smooth, and a clamped or partly loaded face
# has singular edges (B&C tetra cube_333, against the independent solve: 1.0-1.3 for the
# shears, 2.3-2.7 for the sag between the wide levels, whose largest changes fitted 3 and
# then under-estimated the error at 5 of 57 vertices by up to 25 %)


@dataclass(frozen=True)
class Changes:
    """The two wide changes between levels of each load (module docstring), as dof
    vectors (ndof,) of the finest mesh (``d1`` = u_k - u_j, ``d2`` = u_j - u_i, zero
    without a level i), and their weights ``coef`` (a1, a2), SAFETY included: the
    per-point estimate is max(a1 |d1(x)|, a2 |d2(x)|) (a plain |d1(x)| for a field
    represented exactly). ``uniform`` {load: bound}: the estimate is that bound at every
    point instead (coarse levels: their pointwise changes do not follow the finest
    mesh's error, only their largest does)."""

    d1: dict
    d2: dict
    coef: dict
    uniform: dict | None = None

    def at(self, locator: Locator, basis, points, load: str) -> np.ndarray:
        if self.uniform is not None and load in self.uniform:
            return np.full(len(points), self.uniform[load])
        a1, a2 = self.coef[load]
        dim = points.shape[1]
        v = locator.evaluate(
            basis,
            np.column_stack([self.d1[load].reshape(-1, dim), self.d2[load].reshape(-1, dim)]),
            points,
        )
        e1, e2 = np.linalg.norm(v[:, :dim], axis=1), np.linalg.norm(v[:, dim:], axis=1)
        return np.maximum(a1 * e1, a2 * e2)

    def to_arrays(self, names) -> dict:
        out = {
            "d1": np.stack([self.d1[n] for n in names]),
            "d2": np.stack([self.d2[n] for n in names]),
            "coef": np.array([self.coef[n] for n in names], float),
        }
        if self.uniform is not None:
            out["uniform"] = np.array([self.uniform[n] for n in names], float)
        return out

    @classmethod
    def from_arrays(cls, names, arrays) -> "Changes | None":
        if "coef" not in arrays:
            return None
        uniform = (
            {n: float(arrays["uniform"][i]) for i, n in enumerate(names)}
            if "uniform" in arrays
            else None
        )
        return cls(
            {n: arrays["d1"][i] for i, n in enumerate(names)},
            {n: arrays["d2"][i] for i, n in enumerate(names)},
            {n: tuple(arrays["coef"][i]) for i, n in enumerate(names)},
            uniform,
        )


def n_dofs(mesh, order: str) -> int:
    """Vector dofs of a P1/P2 simplex mesh (P2: vertices and edge midpoints)."""
    dim = mesh.p.shape[0]
    ns = mesh.p.shape[1] + (
        0 if order == "P1" else (mesh.facets.shape[1] if dim == 2 else mesh.edges.shape[1])
    )
    return dim * ns


def fitted_order(changes, dofs, dim: int, highest: float = ORDER_RANGE[1]) -> float:
    """The order p (in h = N^(-1/dim)) of the largest changes between levels,
    c_j ~ K (h_(j-1)^p - h_j^p), fitted in log by least squares over the last FIT
    changes (dofs: the N of those levels and the one before), at most ``highest``;
    ORDER_RANGE's lowest, the most conservative, from a single change."""
    c = np.asarray(changes[-FIT:], float)
    if len(c) < 2:
        return ORDER_RANGE[0]
    h = np.asarray(dofs[-len(c) - 1 :], float) ** (-1.0 / dim)
    p = np.linspace(ORDER_RANGE[0], highest, 401)
    res = np.log(c)[:, None] - np.log(h[:-1, None] ** p - h[1:, None] ** p)
    res -= res.mean(axis=0)
    return float(p[np.argmin((res**2).sum(axis=0))])


def coefficients(p: float, dofs, dim: int) -> tuple:
    """(a1, a2): the last and the previous change scaled to the finest level's error,
    h_k^p / (h_(k-1)^p - h_k^p) and h_k^p / (h_(k-2)^p - h_(k-1)^p) (0 with two levels)."""
    h = np.asarray(dofs[-3:], float) ** (-p / dim)  # h^p
    a1 = h[-1] / (h[-2] - h[-1])
    return a1, (h[-1] / (h[-3] - h[-2]) if len(h) == 3 else 0.0)


def _interpolate(coarse: Discretisation, fields: np.ndarray, fine: Discretisation) -> np.ndarray:
    """Coarse fields (ns_c, m) at the fine mesh's dof locations (ns_f, m): exact, the
    meshes being nested and the element the same."""
    return Locator(coarse.mesh).evaluate(coarse.basis, fields, fine.doflocs.T)


def wide_levels(dofs, k: int):
    """(i, j) of the wide steps below level k: i the last level with dofs <= dofs[k] /
    WIDE^2 (else the first), j the level between them nearest their middle in log dofs;
    (None, i) when no level lies between."""
    below = [l for l in range(k) if dofs[l] * WIDE**2 <= dofs[k]]
    i = below[-1] if below else 0
    if k - i < 2:
        return None, i
    mid = 0.5 * (np.log(dofs[i]) + np.log(dofs[k]))
    return i, min(range(i + 1, k), key=lambda l: abs(np.log(dofs[l]) - mid))


def prune(kept):
    """Drop the levels no later estimate can use (level i only moves up)."""
    dofs = [n for n, _ in kept]
    below = [l for l in range(len(dofs) - 1) if dofs[l] * WIDE**2 <= dofs[-1]]
    return kept[below[-1] :] if below else kept


def carry(kept, d: Discretisation, fine: Discretisation, names):
    """The kept levels' fields of the loads ``names`` (on d's mesh) at the finer mesh's
    dofs (nested: exact)."""
    dim = d.dim
    cols = np.column_stack([U[n].reshape(-1, dim) for _, U in kept for n in names])
    vals = _interpolate(d, cols, fine)
    out, c = [], 0
    for ndof, _ in kept:
        out.append(
            (
                ndof,
                {
                    n: vals[:, (c + a) * dim : (c + a + 1) * dim].ravel()
                    for a, n in enumerate(names)
                },
            )
        )
        c += len(names)
    return out


def wide_changes(
    kept, ndof: int, U: dict, names, dim: int, highest: float, probe, est: dict
) -> Changes:
    """The Changes of the finest level U over the wide steps (module docstring); fills
    ``est`` ({load: largest estimate at the user's vertices / max |u| there}). A load the
    kept levels do not hold is in closed form on every level: its changes are zero."""
    dofs = [n for n, _ in kept] + [ndof]
    levels = [f for _, f in kept] + [U]
    i, j = wide_levels(dofs, len(dofs) - 1)
    zero = np.zeros(ndof)
    zero.flags.writeable = False  # shared by every load without a change

    def change(n, a, b):
        return zero if b is None or n not in levels[b] else levels[a][n] - levels[b][n]

    d1 = {n: change(n, -1, j) for n in names}
    d2 = {n: change(n, j, i) for n in names}
    used = [dofs[l] for l in ([i] if i is not None else []) + [j, len(dofs) - 1]]
    coef = {}
    for n in names:
        scale = max(float(probe(U[n]).max()), 1e-300)
        e1, e2 = probe(d1[n]), probe(d2[n])
        if e1.max() <= EXACT * scale:
            coef[n] = (1.0, 0.0)
        else:
            p = (
                fitted_order([e2.max(), e1.max()], used, dim, highest)
                if i is not None
                else ORDER_RANGE[0]
            )
            safety = SAFETY_THREE if i is not None else SAFETY
            coef[n] = tuple(safety * a for a in coefficients(p, used, dim))
        est[n] = float(np.maximum(coef[n][0] * e1, coef[n][1] * e2).max() / scale)
    return Changes(d1, d2, coef)
