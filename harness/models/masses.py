"""Masses of the nodes (Deussen 1995, Section 4) and the body's exact mass moments.

"moments": the masses reproduce every mass moment p_jkl = int x^j y^k z^l rho dV with
j+k+l <= 2 (6 in 2-D, 10 in 3-D): A m = p with least Euclidean norm, m = A^T x where
A A^T x = p (eq. 6-7). Coordinates are centred and scaled first; this changes neither
the solution set nor the min-norm solution, only the conditioning of A A^T.
"moments-nonneg": m >= 0 matching the moments as well as possible (scipy lsq_linear
with a tiny min-norm regularisation); equal to "moments" when those are already >= 0.
"voronoi": density times the size of each node's Voronoi region clipped to the body
(exact in 2-D, sampled in 3-D), scaled to the exact total mass. "uniform": total / n.
"lumped" (mesh bodies, nodes = the mesh's vertices): each simplex (quads and hexahedra
split into triangles / tetrahedra) gives rho V / (dim + 1) to each of its vertices, rho
at its centroid: never negative, the total mass exact, the first moments exact for
affine cells; the second moments are not matched (the residual says how far).
Every rule reports the relative moment residual and the number of negative masses.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import lsq_linear

from harness.case.elasticity import densities
from harness.case.moments import (  # noqa: F401
    _quadrature,
    _simplices,
    box_moments,
    mesh_moments,
    monomials,
    polygon_moments,
)
from harness.case.reader import Region
from harness.errors import ModelError
from harness.geometry.bodies import BodyGeom, clip_box
from harness.geometry.bodies import polygon as make_polygon
from harness.geometry.placement import voronoi_cells_2d, voronoi_cells_sampled
from harness.models.cells import hex_to_tets

RULES = ("moments", "moments-nonneg", "voronoi", "uniform", "lumped")


def density_function(material, dim: int):
    """rho(points) for a ``harness.case.reader.Material`` (regions may override the density)."""
    return lambda x: densities(material, x)


def body_moments(body: BodyGeom, material=None) -> np.ndarray:
    """Exact mass moments of the body; density regions (axis-aligned boxes) are exact
    for polygons and boxes when they do not overlap."""
    rho0 = float(material.density) if material is not None else 1.0
    regions = [
        r for r in (material.regions if material is not None else ()) if r.density is not None
    ]
    if body.kind == "mesh":
        return mesh_moments(
            body.mesh_points,
            body.mesh_cells,
            density_function(material, body.dim) if material is not None else None,
        )

    def moments(lo=None, hi=None):
        if body.kind == "polygon":
            v = body.vertices if lo is None else clip_box(body.vertices, lo, hi)
            return polygon_moments(v) if len(v) >= 3 else np.zeros(6)
        if lo is None:
            return box_moments(body.lo, body.hi)
        a, b = np.maximum(lo, body.lo), np.minimum(hi, body.hi)
        return box_moments(a, b) if np.all(b > a) else np.zeros(10)

    p = rho0 * moments()
    for r in regions:
        p = p + (r.density - rho0) * moments(np.asarray(r.lo, float), np.asarray(r.hi, float))
    return p


def _normaliser(body: BodyGeom):
    c = (body.lo + body.hi) / 2
    s = float(np.max(body.hi - body.lo)) / 2
    return c, s


def _scaled_body(body: BodyGeom, c, s) -> BodyGeom:
    if body.kind == "polygon":
        return make_polygon((body.vertices - c) / s)
    if body.kind == "box":
        from harness.geometry.bodies import box

        return box((body.lo - c) / s, (body.hi - c) / s)
    from harness.geometry.bodies import mesh_body

    return mesh_body((body.mesh_points - c) / s, body.mesh_cells)


class _ScaledMaterial:
    def __init__(self, material, c, s):
        self.density = material.density if material is not None else 1.0
        self.regions = tuple(
            Region(
                tuple((np.asarray(r.lo) - c) / s),
                tuple((np.asarray(r.hi) - c) / s),
                r.E,
                r.nu,
                r.density,
            )
            for r in (material.regions if material is not None else ())
        )


def min_norm_masses(A: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Least-norm solution of A m = p via A A^T x = p, m = A^T x (eq. 7)."""
    AAt = A @ A.T
    try:
        x = np.linalg.solve(AAt, p)
    except np.linalg.LinAlgError:
        raise ModelError(
            "the points lie on a quadric, so A A^T is singular (eq. 7)",
            field="model.masses",
            fix="use more points or masses = 'voronoi'",
        )
    if np.linalg.cond(AAt) > 1e14:
        raise ModelError(
            "the points (nearly) lie on a quadric, so A A^T is singular (eq. 7)",
            field="model.masses",
            fix="use more points or masses = 'voronoi'",
        )
    return A.T @ x


@dataclass(frozen=True, eq=False)
class MassResult:
    """masses (n,); residual = |A m - p| / |p| (centred, scaled coordinates); n_negative."""

    masses: np.ndarray
    rule: str
    residual: float
    n_negative: int


def compute_masses(
    rule: str, points: np.ndarray, body: BodyGeom, material=None, seed: int = 0
) -> MassResult:
    """Masses by the named rule (see the module docstring)."""
    points = np.asarray(points, float)
    c, s = _normaliser(body)
    sb = _scaled_body(body, c, s)
    sm = _ScaledMaterial(material, c, s)
    z = (points - c) / s
    A = monomials(z)
    p = body_moments(sb, sm)
    scale = s**body.dim
    if rule == "moments":
        m = min_norm_masses(A, p)
    elif rule == "moments-nonneg":
        m = min_norm_masses(A, p)
        if m.min() < 0:
            eps = 1e-6 * np.linalg.norm(A, 2)
            lhs = np.vstack([A, eps * np.eye(len(z))])
            rhs = np.concatenate([p, np.zeros(len(z))])
            m = lsq_linear(lhs, rhs, bounds=(0, np.inf), lsmr_tol="auto", tol=1e-14).x
    elif rule == "voronoi":
        if sb.kind == "polygon":
            sizes, cents = voronoi_cells_2d(z, sb)
        elif sb.kind == "box":
            sizes, cents = voronoi_cells_sampled(z, sb, 4000 * len(z), np.random.default_rng(seed))
        else:
            raise ModelError(
                "Voronoi masses need a rectangle, polygon or box",
                field="model.masses",
                fix="use masses = 'moments' for mesh bodies",
            )
        rho = density_function(sm, body.dim)(cents)
        m = sizes * rho
        m *= p[0] / m.sum()
    elif rule == "uniform":
        m = np.full(len(z), p[0] / len(z))
    elif rule == "lumped":
        if (
            sb.kind != "mesh"
            or sb.mesh_points.shape != z.shape
            or not np.allclose(sb.mesh_points, z, atol=1e-12)
        ):
            raise ModelError(
                "lumped masses need the nodes to be the mesh's own vertices",
                field="model.masses",
                fix="use placement = 'mesh', or masses = 'moments-nonneg'",
            )
        simp, vol = _simplices(z, sb.mesh_cells)
        rho = density_function(sm, body.dim)(z[simp].mean(axis=1))
        m = np.zeros(len(z))
        np.add.at(m, simp.ravel(), np.repeat(rho * vol / simp.shape[1], simp.shape[1]))
    else:
        raise ModelError(
            f"unknown mass rule '{rule}'", field="model.masses", fix=f"one of {', '.join(RULES)}"
        )
    res = float(np.linalg.norm(A @ m - p) / np.linalg.norm(p))
    return MassResult(m * scale, rule, res, int(np.sum(m < 0)))


def lumped_masses(points, cells, density: float) -> np.ndarray:
    """Node masses (n,) of a constant density: each element's volume times ``density``
    shared equally by its vertices (for a constant body force this is the consistent
    P1 / Q1 load of a tetrahedron / parallelepiped, i.e. the FEM's linear load)."""
    cells = np.asarray(cells)
    per_cell = np.abs(sub_tet_volumes(points, cells)).sum(axis=1)
    m = np.zeros(len(points))
    np.add.at(m, cells.ravel(), np.repeat(density * per_cell / cells.shape[1], cells.shape[1]))
    return m


def sub_tet_volumes(points, cells) -> np.ndarray:
    """Signed volumes (m, k) of each element's tetrahedra (k = 1 for a tet, the hex split
    of harness.models.cells.hex_to_tets for a hex)."""
    tets = cells if cells.shape[1] == 4 else hex_to_tets(cells)
    X = np.asarray(points, float)[tets]
    v = np.einsum("ij,ij->i", np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]), X[:, 3] - X[:, 0]) / 6
    return v.reshape(len(cells), -1)
