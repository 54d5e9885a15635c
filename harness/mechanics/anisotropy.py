"""Undesired anisotropy as numbers: a box pulled by a uniaxial stress along several
directions relative to the mesh.

For a direction d the box faces carry the traction of the uniform stress s d d^T
(t = s d (d . n) on the face with outward normal n, nodal forces by tributary area,
harness.mechanics.statics); three corners hold the six rigid motions (x0y0z0 all, x1y0z0 y and z,
x0y1z0 z), which take no reaction because the load is self-equilibrated. The response's
effective strain eps is the symmetric part of the least-squares affine fit u = a + H x
over all nodes. Per direction:

- ``stiffness`` E_d = s / (d . eps d): Young's modulus along d (an isotropic continuum: E
  for every d; a transversely isotropic one: 1/E_d = c^4/E_L + s^4/E_T + (1/G_LT -
  2 nu_LT/E_L) c^2 s^2 with c, s the cosine and sine of the angle to the fibre);
- ``drift`` |eps d - (d . eps d) d| / (d . eps d): the strain across d that a pull along d
  causes (zero for any isotropic material: a pull along d stretches along d only).

The same loads solved by the FEM reference give the continuum's values, so a model's
spread can be set against the material's own.
"""

from __future__ import annotations

import numpy as np

from harness.case.facet_loads import planar_forces
from harness.case.loadsets import Constraint, LoadCase, Traction
from harness.case.parts import part_predicate
from harness.errors import ModelError

HOLD = (Constraint("x0y0z0", (0, 1, 2)), Constraint("x1y0z0", (1, 2)), Constraint("x0y1z0", (2,)))


def directions_xy(angles_deg) -> np.ndarray:
    """Unit vectors (k, 3) in the x-y plane at the given angles from +x."""
    a = np.deg2rad(np.asarray(angles_deg, float))
    return np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=1)


def pull_load(d, stress: float = 1.0, name: str = "pull") -> LoadCase:
    """The uniaxial stress ``stress`` d d^T on a box as a load case (tractions on the faces
    whose normal is not perpendicular to d, the three-corner hold)."""
    d = np.asarray(d, float) / np.linalg.norm(d)
    tr = []
    for a in range(3):
        if abs(d[a]) > 1e-12:
            for side, sgn in (("0", -1.0), ("1", 1.0)):
                tr.append(
                    Traction("xyz"[a] + side, tuple(float(v) for v in stress * d * d[a] * sgn))
                )
    return LoadCase(name, HOLD, tuple(tr))


def pull_arrays(points, bbox, load: LoadCase) -> tuple[np.ndarray, np.ndarray]:
    """(free (3n,) bool, forces (3n,)) of a pull load on nodes ``points`` (n, 3)."""
    points = np.asarray(points, float)
    f = np.zeros(points.shape)
    for t in load.tractions:
        f += planar_forces(points, part_predicate(t.part, bbox), t.vector)
    fixed = np.zeros(points.shape, bool)
    for c in load.constraints:
        on = part_predicate(c.part, bbox)(points.T)
        if not on.any():
            raise ModelError(
                f"no node on corner {c.part} for the direction pulls",
                fix="the body must be a box meshed to its corners",
            )
        fixed[np.ix_(on, list(c.components))] = True
    return ~fixed.ravel(), f.ravel()


def effective_strain(points, u) -> np.ndarray:
    """Symmetric part (3, 3) of H in the least-squares fit u = a + H x."""
    X = np.column_stack([np.ones(len(points)), np.asarray(points, float)])
    coef, *_ = np.linalg.lstsq(X, np.asarray(u, float), rcond=None)
    H = coef[1:].T  # u_i = a_i + H_ij x_j
    return 0.5 * (H + H.T)


def measures(points, u, d, stress: float = 1.0) -> dict:
    """stiffness E_d and drift of one pull response u (n, 3); see the module doc."""
    d = np.asarray(d, float) / np.linalg.norm(d)
    eps = effective_strain(points, u)
    ed = eps @ d
    along = float(d @ ed)
    return {
        "stiffness": stress / along,
        "drift": float(np.linalg.norm(ed - along * d)) / abs(along),
    }


def spread(values) -> tuple[float, float]:
    """(max/min, coefficient of variation) of positive values."""
    v = np.asarray(values, float)
    return float(v.max() / v.min()), float(v.std() / v.mean())


def transversely_isotropic_modulus(angle_to_fibre, E_L, E_T, nu_LT, G_LT):
    """Closed-form Young's modulus at ``angle_to_fibre`` (radians) of a transversely
    isotropic material (fibre modulus E_L, cross modulus E_T)."""
    c, s = np.cos(angle_to_fibre), np.sin(angle_to_fibre)
    return 1.0 / (c**4 / E_L + s**4 / E_T + (1.0 / G_LT - 2.0 * nu_LT / E_L) * c * c * s * s)


def solve_model(K, points, bbox, loads) -> list[np.ndarray]:
    """Displacements (n, 3) of a linear model (stiffness K, (3n, 3n)) under each pull load."""
    import scipy.sparse.linalg as spla

    K = K.tocsr()
    out = []
    lu, key = None, None
    for load in loads:
        free, f = pull_arrays(points, bbox, load)
        if key is None or not np.array_equal(key, free):
            lu, key = spla.splu(K[free][:, free].tocsc()), free
        u = np.zeros(len(free))
        u[free] = lu.solve(f[free])
        out.append(u.reshape(-1, 3))
    return out
