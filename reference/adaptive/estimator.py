"""Residual a-posteriori error indicators of linear elasticity on simplex meshes (P1/P2).

For an element T (Verfürth, "A posteriori error estimation techniques", 2013, Sec. 4.4):

    eta_T^2 = ( h_T^2 ||f + div sigma_h||_T^2
              + 1/2 sum_{interior F of T} h_F ||[sigma_h n]||_F^2
              + sum_{Neumann F of T} h_F ||g - sigma_h n||_F^2 ) / c_T

with f the body force (rho g + body_force), g the prescribed traction (traction parts
tested at each quadrature point, so a facet a part's box cuts shows its mismatch, and
sigma_load(x) . n of a stress load, constant or linear, twists included), h the diameter
(h / k for elements of degree k, Melenk & Wohlmuth 2001) and c_T the smallest
eigenvalue of the element's elastic tensor (Mandel form; 2 mu when isotropic), which
puts eta^2 in energy units:
sum eta_T^2 bounds the energy norm a(e, e) of the error up to a constant of the mesh
shape (tests/reference/test_adaptive.py: eta / |e|_a stays in 1..20 and constant under
refinement). A component fixed at every vertex of an element or facet carries no
residual there (the reaction balances it). On affine simplices sigma_h is linear (P2) or constant
(P1) per element, so div sigma_h is constant: it is taken from sigma_h at the vertices.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import skfem

from reference.fem import VOIGT, Discretisation
from reference.problem import load_stress, predicate

CHUNK = 50_000  # facets or elements per evaluation (memory: ~ CHUNK * basis * quadrature)


def body_force(case, load, rho: np.ndarray) -> np.ndarray:
    """Force per volume (ne, dim), constant per element, as reference/problem.py applies it."""
    f = np.zeros((len(rho), case.dim))
    if load.gravity is not None:
        f += rho[:, None] * np.asarray(load.gravity, float)
    if load.body_force is not None:
        f += np.asarray(load.body_force, float)
    return f


def mandel_min(C: np.ndarray) -> np.ndarray:
    """Smallest eigenvalue (ne,) of each Voigt stiffness (engineering shears) in Mandel form."""
    dim = 2 if C.shape[1] == 3 else 3
    s = np.array([1.0 if i == j else np.sqrt(2.0) for i, j in VOIGT[dim]])
    return np.linalg.eigvalsh(C * s[:, None] * s[None, :])[:, 0]


def stress(basis, U: np.ndarray, C: np.ndarray) -> np.ndarray:
    """sigma_h (dim, dim, n, nq) at the basis' quadrature points; U (ns, dim) nodal
    values, C (n, nv, nv) the Voigt stiffness of the element each point lies in."""
    dim = U.shape[1]
    G = np.stack([basis.interpolate(U[:, c]).grad for c in range(dim)])  # dG[c, j] = du_c/dx_j
    eps = np.stack([G[i, i] if i == j else G[i, j] + G[j, i] for i, j in VOIGT[dim]], axis=-1)
    sv = np.einsum("nab,nqb->nqa", C, eps)
    sig = np.empty((dim, dim) + sv.shape[:2])
    for I, (i, j) in enumerate(VOIGT[dim]):
        sig[i, j] = sig[j, i] = sv[..., I]
    return sig


def diameters(p: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """Longest edge of each simplex given by vertex indices nodes (k, n)."""
    k = nodes.shape[0]
    if k == 2:
        return np.linalg.norm(p[:, nodes[0]] - p[:, nodes[1]], axis=0)
    return np.max(
        [
            np.linalg.norm(p[:, nodes[i]] - p[:, nodes[j]], axis=0)
            for i in range(k)
            for j in range(i + 1, k)
        ],
        axis=0,
    )


def _chunks(n: int):
    for s in range(0, n, CHUNK):
        yield np.arange(s, min(s + CHUNK, n))


def _free_mask(fixed_v: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """(n, dim): components not fixed at every vertex of each entity nodes (k, n)."""
    return ~fixed_v[nodes].all(axis=0)


@dataclass(frozen=True)
class Field:
    """One load's discrete solution as the residuals need it: nodal values U (ns, dim),
    body force f (ne, dim), fixed components at the vertices (nv, dim)."""

    load: object
    U: np.ndarray
    f: np.ndarray
    fixed_v: np.ndarray


def element_residual(d: Discretisation, fields, C) -> np.ndarray:
    """h_T^2 ||f + div sigma_h||_T^2 per field and element (nfields, ne)."""
    mesh, dim = d.mesh, d.dim
    R = np.stack([fd.f for fd in fields])
    if d.order == "P2":
        X = np.vstack([np.zeros(dim), np.eye(dim)]).T  # reference vertices = mesh.t order
        for e in _chunks(d.nelems):
            b = skfem.CellBasis(
                mesh,
                d.elem,
                mapping=d.mapping,
                quadrature=(X, np.ones(dim + 1)),
                elements=e,
                dofs=d.dofs,
                disable_doflocs=True,
            )
            dX = d.mapping.invDF(X[:, :1], tind=e)[:, :, :, 0]  # dX_a/dx_j (a, j, ne)
            for i, fd in enumerate(fields):
                sig = stress(b, fd.U, C[e])  # dim, dim, ne, vertex
                R[i, e] += np.einsum("ijea,aje->ei", sig[..., 1:] - sig[..., :1], dX)
    R *= np.stack([_free_mask(fd.fixed_v, mesh.t) for fd in fields])
    vol = np.abs(d.mapping.detDF(np.zeros((dim, 1))))[:, 0] / (2.0 if dim == 2 else 6.0)
    return diameters(mesh.p, mesh.t) ** 2 * vol * (R**2).sum(axis=2)


def _facet_integral(fb, r: np.ndarray) -> np.ndarray:
    """int_F |r|^2 ds per facet, r (dim, nf, nq)."""
    return ((r**2).sum(axis=0) * fb.dx).sum(axis=1)


def jump_residual(d: Discretisation, fields, C) -> np.ndarray:
    """1/2 sum over interior facets of h_F ||[sigma_h n]||^2, per field and element."""
    mesh = d.mesh
    out = np.zeros((len(fields), d.nelems))
    interior = np.flatnonzero(mesh.f2t[1] != -1)
    for part in _chunks(len(interior)):
        facets = interior[part]
        sides = [
            skfem.InteriorFacetBasis(
                mesh,
                d.elem,
                mapping=d.mapping,
                intorder=2,
                facets=facets,
                side=s,
                dofs=d.dofs,
                disable_doflocs=True,
            )
            for s in (0, 1)
        ]
        n = np.asarray(sides[0].normals)  # outward from side 0
        h = diameters(mesh.p, mesh.facets[:, facets])
        for i, fd in enumerate(fields):
            sig = [stress(b, fd.U, C[b.tind]) for b in sides]
            jump = np.einsum("ijfq,jfq->ifq", sig[0] - sig[1], n)
            jump *= _free_mask(fd.fixed_v, mesh.facets[:, facets]).T[:, :, None]
            eta = 0.5 * h * _facet_integral(sides[0], jump)
            for b in sides:
                np.add.at(out[i], b.tind, eta)
    return out


def traction_at(
    case, load, bbox, x: np.ndarray, n: np.ndarray, parts=None, centres=None
) -> np.ndarray:
    """The prescribed traction g (dim, nf, nq) at boundary points x with normals n;
    ``centres`` the area centroid of each twisted traction's facets (by index)."""
    dim = x.shape[0]
    g = np.zeros_like(x)
    for i, t in enumerate(load.tractions):
        inside = predicate(case, t.part, bbox, parts)(x.reshape(dim, -1)).reshape(x.shape[1:])
        tr = np.broadcast_to(np.asarray(t.vector, float)[:, None, None], x.shape)
        if t.twist is not None:
            tr = tr + np.cross(np.asarray(t.twist, float), (x - centres[i][:, None, None]), axis=0)
        g += inside[None] * tr
    if load.stress is not None:
        sig = load_stress(load)
        sig = sig(x) if callable(sig) else sig[:, :, None, None]
        g += np.einsum("ijfq,jfq->ifq", sig, n)
    return g


def twist_centres(d: Discretisation, case, load, bbox, parts=None) -> dict:
    """{traction index: area centroid of its facets} of the load's twisted tractions, as
    reference/fem.py's twist_load takes it."""
    out = {}
    for i, t in enumerate(load.tractions):
        if t.twist is not None:
            fb = skfem.FacetBasis(
                d.mesh,
                d.elem,
                mapping=d.mapping,
                intorder=2,
                dofs=d.dofs,
                facets=d.part_facets(predicate(case, t.part, bbox, parts)),
                disable_doflocs=True,
            )
            out[i] = (
                np.einsum("dfq,fq->d", np.asarray(fb.global_coordinates()), fb.dx) / fb.dx.sum()
            )
    return out


def neumann_residual(d: Discretisation, case, fields, bbox, C, parts=None) -> np.ndarray:
    """sum over boundary facets of h_F ||g - sigma_h n||^2, per field and element."""
    mesh = d.mesh
    out = np.zeros((len(fields), d.nelems))
    boundary = mesh.boundary_facets()
    centres = [twist_centres(d, case, fd.load, bbox, parts) for fd in fields]
    for part in _chunks(len(boundary)):
        facets = boundary[part]
        fb = skfem.FacetBasis(
            mesh,
            d.elem,
            mapping=d.mapping,
            intorder=2,
            facets=facets,
            dofs=d.dofs,
            disable_doflocs=True,
        )
        n = np.asarray(fb.normals)
        x = np.asarray(fb.global_coordinates())
        h = diameters(mesh.p, mesh.facets[:, facets])
        for i, fd in enumerate(fields):
            g = traction_at(case, fd.load, bbox, x, n, parts, centres[i])
            r = g - np.einsum("ijfq,jfq->ifq", stress(fb, fd.U, C[fb.tind]), n)
            r *= _free_mask(fd.fixed_v, mesh.facets[:, facets]).T[:, :, None]
            np.add.at(out[i], fb.tind, h * _facet_integral(fb, r))
    return out


def indicators(
    d: Discretisation,
    case,
    loads,
    U: dict,
    C: np.ndarray,
    rho: np.ndarray,
    bbox,
    fixed: dict,
    parts=None,
) -> dict:
    """{load name: eta_T^2 (ne,)} of the loads' displacement dofs U[name] (ndof,) with
    fixed vector dofs fixed[name]; C (ne, nv, nv) and rho (ne,) per element; ``parts``
    as reference/problem.py takes it."""
    if d.mesh.t.shape[0] != d.dim + 1:
        raise ValueError("residual indicators need a simplex mesh")
    nv = d.mesh.p.shape[1]
    fields = []
    for load in loads:
        fx = np.zeros(d.ndof, bool)
        fx[fixed[load.name]] = True
        fields.append(
            Field(
                load,
                U[load.name].reshape(d.ns, d.dim),
                body_force(case, load, rho),
                fx.reshape(d.ns, d.dim)[:nv],
            )
        )
    k = 1.0 if d.order == "P1" else 2.0
    eta2 = (
        element_residual(d, fields, C) / k**2
        + (jump_residual(d, fields, C) + neumann_residual(d, case, fields, bbox, C, parts)) / k
    )
    eta2 /= mandel_min(C)
    return {load.name: eta2[i] for i, load in enumerate(loads)}


def doerfler(eta2: np.ndarray, theta: float, least: float = 0.0) -> np.ndarray:
    """Dörfler's bulk criterion: the fewest elements whose indicators sum to theta of the
    total (ties taken together), and at least the ``least`` share of all elements with
    the largest indicators; as indices."""
    order = np.argsort(-eta2, kind="stable")
    cum = np.cumsum(eta2[order])
    if cum[-1] <= 0:
        return np.zeros(0, np.int64)
    k = max(int(np.searchsorted(cum, theta * cum[-1])) + 1, int(np.ceil(least * len(eta2))))
    cut = eta2[order[min(k, len(order)) - 1]]
    return np.flatnonzero(eta2 >= cut)
