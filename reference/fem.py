"""Assembly of linear elasticity on one mesh: stiffness with a per-element Voigt matrix,
consistent mass, body forces, tractions, constraints and the rigid-body modes.

Everything is built on the *scalar* Lagrange basis; the displacement has ``dim``
components per scalar dof, interleaved: global dof = dim * scalar_dof + component
(the same order as scikit-fem's ElementVector). The stiffness is the bilinear form
a(u, v) = sum_e int_e eps(v)^T C_e eps(u) dx with engineering-shear Voigt strains
(harness.case.elasticity order), evaluated for all elements of a chunk with one matmul
instead of scikit-fem's per-basis-pair Python form (the same integral, see the test).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import skfem

from harness.errors import ModelError
from reference.mesh import SIMPLEX, element

VOIGT = {2: [(0, 0), (1, 1), (0, 1)], 3: [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)]}
CHUNK_ENTRIES = 4_000_000  # local matrix entries per assembly chunk (memory bound)


def quadrature_orders(cell: str, order: str) -> tuple[int, int]:
    """(stiffness, mass/load) integration orders, exact for affine cells and constant
    material: P-k simplices need 2(k-1) and 2k; Q-k tensor cells 2k for both."""
    k = 1 if order == "P1" else 2
    return (2 * (k - 1) if SIMPLEX[cell] else 2 * k), 2 * k


@dataclass
class Discretisation:
    """One mesh with its scalar element; ``ns`` scalar dofs, ``ndof = dim * ns``."""

    mesh: skfem.Mesh
    cell: str
    order: str

    def __post_init__(self):
        self.elem = element(self.cell, self.order)
        self.dim = self.mesh.p.shape[0]
        self.q_stiff, self.q_mass = quadrature_orders(self.cell, self.order)
        self.mapping = mapping(self.mesh)
        self.basis = skfem.CellBasis(
            self.mesh, self.elem, mapping=self.mapping, intorder=self.q_mass
        )
        self.dofs = self.basis.dofs
        self.ns = self.basis.N
        self.ndof = self.dim * self.ns
        self.doflocs = self.basis.doflocs  # (dim, ns)

    @property
    def nelems(self) -> int:
        return self.mesh.t.shape[1]

    def centroids(self) -> np.ndarray:
        return self.mesh.p[:, self.mesh.t].mean(axis=1).T

    def vector_dofs(self, element_dofs: np.ndarray) -> np.ndarray:
        """(nbf, ne) scalar dofs -> (ne, nbf * dim) interleaved vector dofs."""
        return (self.dim * element_dofs.T[:, :, None] + np.arange(self.dim)).reshape(
            element_dofs.shape[1], -1
        )

    def _chunks(self, nloc: int):
        step = max(1, CHUNK_ENTRIES // (nloc * nloc))
        for start in range(0, self.nelems, step):
            yield np.arange(start, min(start + step, self.nelems))

    def _cell_basis(self, elems, intorder):
        return skfem.CellBasis(
            self.mesh,
            self.elem,
            mapping=self.mapping,
            intorder=intorder,
            elements=elems,
            dofs=self.dofs,
        )

    def stiffness(self, C: np.ndarray) -> sp.csr_matrix:
        """K for per-element Voigt stiffness C (ne, nv, nv)."""
        nbf, dim = len(self.basis.basis), self.dim
        nl = nbf * dim
        boxes = self._box_cells()
        if boxes is not None:
            return self._box_stiffness(C, boxes)
        K = sp.csr_matrix((self.ndof, self.ndof))
        for elems in self._chunks(nl):
            b = self._cell_basis(elems, self.q_stiff)
            grad = np.stack([b.basis[a][0].grad for a in range(nbf)])  # nbf, dim, ne, nq
            B = strain_matrix(grad)  # ne, nq, nv, nl
            ne, nq, nv, _ = B.shape
            CB = C[elems][:, None] @ B
            Bw = B * b.dx[:, :, None, None]
            Ke = Bw.reshape(ne, nq * nv, nl).transpose(0, 2, 1) @ CB.reshape(ne, nq * nv, nl)
            K = K + _scatter(Ke, self.vector_dofs(b.element_dofs), self.ndof)
        return K

    def _box_cells(self) -> np.ndarray | None:
        """Cell sizes (ne, dim) if every cell is an axis-aligned box whose vertices come
        in the same order as cell 0's (a tensor mesh's quads or hexes), else None."""
        if SIMPLEX[self.cell]:
            return None
        p = self.mesh.p[:, self.mesh.t]  # dim, nv, ne
        lo, hi = p.min(axis=1), p.max(axis=1)
        h = (hi - lo).T
        if not np.all(h > 0):
            return None
        tol = 1e-12 * h.T[:, None, :]
        upper = np.abs(p - hi[:, None, :]) <= tol
        if not np.all(upper | (np.abs(p - lo[:, None, :]) <= tol)) or not np.all(
            upper == upper[:, :, :1]
        ):
            return None
        return h

    def _box_stiffness(self, C: np.ndarray, h: np.ndarray) -> sp.csr_matrix:
        """K on box cells: the gradient products G_pq[i, j] = int d_p phi_i d_q phi_j of
        cell 0 scale to any other box as vol / (h_p h_q) (the same quadrature, so the same
        matrix as the general loop to rounding, ~30x fewer flops), and
        Ke[(i, a), (j, b)] = sum_pq Ct[a, p, b, q] G_pq[i, j] with Ct = S^T C S, S the
        Voigt selector (eps_v = S[v, a, p] d_p u_a)."""
        nbf, dim = len(self.basis.basis), self.dim
        nl = nbf * dim
        b = self._cell_basis(np.array([0]), self.q_stiff)
        grad = np.stack([np.asarray(b.basis[a][0].grad)[:, 0] for a in range(nbf)])  # nbf, dim, nq
        G0 = np.einsum("ipk,jqk,k->pqij", grad, grad, b.dx[0])
        S = np.zeros((len(VOIGT[dim]), dim, dim))
        for v, (i, j) in enumerate(VOIGT[dim]):
            S[v, i, j] += 1.0
            if i != j:
                S[v, j, i] += 1.0
        vol = np.prod(h, axis=1)
        scale = (
            (vol / vol[0])[:, None, None]
            * (h[0][:, None] * h[0][None, :])
            / (h[:, :, None] * h[:, None, :])
        )
        K = sp.csr_matrix((self.ndof, self.ndof))
        for elems in self._chunks(nl):
            Ct = np.einsum("vap,evw,wbq->eabpq", S, C[elems], S) * scale[elems][:, None, None]
            Ke = (Ct.reshape(-1, dim * dim) @ G0.reshape(dim * dim, nbf * nbf)).reshape(
                len(elems), dim, dim, nbf, nbf
            )
            Ke = Ke.transpose(0, 3, 1, 4, 2).reshape(len(elems), nl, nl)
            K = K + _scatter(Ke, self.vector_dofs(self.dofs.element_dofs[:, elems]), self.ndof)
        return K

    def scalar_mass(self, rho: np.ndarray) -> sp.csr_matrix:
        """int rho phi_a phi_b with a constant density rho per element (ne,)."""
        nbf = len(self.basis.basis)
        Ms = sp.csr_matrix((self.ns, self.ns))
        for elems in self._chunks(nbf * self.dim):
            b = self._cell_basis(elems, self.q_mass)
            phi = np.stack([np.asarray(b.basis[a][0]) for a in range(nbf)], axis=1)  # ne, nbf, nq
            w = b.dx * rho[elems][:, None]
            Me = (phi * w[:, None, :]) @ phi.transpose(0, 2, 1)
            Ms = Ms + _scatter(Me, b.element_dofs.T, self.ns)
        return Ms

    def mass(self, rho: np.ndarray) -> sp.csr_matrix:
        """Consistent mass, rho per element; interleaved like K."""
        return sp.kron(self.scalar_mass(rho), sp.identity(self.dim), format="csr")

    def body_load(self, f, intorder: int | None = None) -> np.ndarray:
        """Load vector of a force per volume: ``f`` (ne, dim) constant per element, or a
        callable x (dim, ne, nq) -> (dim, ne, nq)."""
        b = (
            self.basis
            if intorder is None
            else skfem.CellBasis(
                self.mesh, self.elem, mapping=self.mapping, intorder=intorder, dofs=self.dofs
            )
        )
        if callable(f):
            fq = np.asarray(f(np.asarray(b.global_coordinates())))  # dim, ne, nq
        else:
            fq = np.broadcast_to(np.asarray(f, float).T[:, :, None], (self.dim,) + b.dx.shape)
        F = np.zeros((self.ns, self.dim))
        for a in range(len(b.basis)):
            val = np.einsum("ceq,eq,eq->ec", fq, np.asarray(b.basis[a][0]), b.dx)
            for c in range(self.dim):
                F[:, c] += np.bincount(b.element_dofs[a], val[:, c], minlength=self.ns)
        return F.ravel()

    def part_facets(self, predicate) -> np.ndarray:
        """Boundary facets all of whose vertices and whose centroid satisfy ``predicate``
        (the centroid keeps a facet that only spans between a part's edges out)."""
        bf = self.mesh.boundary_facets()
        nodes = self.mesh.facets[:, bf]  # nvf, nf
        ok = predicate(self.mesh.p[:, nodes.ravel()]).reshape(nodes.shape).all(axis=0)
        ok[ok] = predicate(self.mesh.p[:, nodes[:, ok]].mean(axis=1))
        return bf[ok]

    def traction_load(self, facets: np.ndarray, vector) -> np.ndarray:
        """Load vector of a constant traction ``vector`` on ``facets``."""
        fb = skfem.FacetBasis(
            self.mesh,
            self.elem,
            mapping=self.mapping,
            facets=facets,
            intorder=self.q_mass,
            dofs=self.dofs,
        )
        w = skfem.asm(skfem.LinearForm(lambda v, _: v), fb)  # int phi_a ds, (ns,)
        return (w[:, None] * np.asarray(vector, float)[None, :]).ravel()

    def twist_load(self, facets: np.ndarray, w) -> np.ndarray:
        """Load vector of the traction w x (x - c) on ``facets`` (3-D), c their area
        centroid: a torque without resultant (harness.case.loadsets.Traction)."""
        fb = skfem.FacetBasis(
            self.mesh,
            self.elem,
            mapping=self.mapping,
            facets=facets,
            intorder=self.q_mass,
            dofs=self.dofs,
        )
        xq, dx = np.asarray(fb.global_coordinates()), fb.dx
        c = np.einsum("dfq,fq->d", xq, dx) / dx.sum()
        w = np.asarray(w, float)
        out = np.zeros((self.ns, self.dim))
        for comp in range(3):  # (w x r)_comp = w_a r_b - w_b r_a
            a, b = (comp + 1) % 3, (comp + 2) % 3
            out[:, comp] = skfem.asm(
                skfem.LinearForm(
                    lambda v, p: v * (w[a] * (p.x[b] - c[b]) - w[b] * (p.x[a] - c[a]))
                ),
                fb,
            )
        return out.ravel()

    def stress_load(self, sigma) -> np.ndarray:
        """Load vector of the traction sigma . n on the whole boundary (n the outward
        normal of each facet): a constant stress (dim, dim), or a function of the points
        x (dim, nf, nq) -> (dim, dim, nf, nq); q_mass integrates a linear one against the
        basis exactly."""
        fb = skfem.FacetBasis(
            self.mesh,
            self.elem,
            mapping=self.mapping,
            facets=self.mesh.boundary_facets(),
            intorder=self.q_mass,
            dofs=self.dofs,
        )
        n = np.asarray(fb.normals)
        if callable(sigma):
            sq = np.asarray(sigma(np.asarray(fb.global_coordinates())))
        else:
            sq = np.asarray(sigma, float)[:, :, None, None]
        t = np.einsum("ijfq,jfq->ifq", sq, n) * fb.dx  # traction times the facet weights
        out = np.zeros((self.ns, self.dim))
        for a in range(len(fb.basis)):
            val = np.einsum("ifq,fq->fi", t, np.asarray(fb.basis[a][0]))
            for c in range(self.dim):
                out[:, c] += np.bincount(fb.element_dofs[a], val[:, c], minlength=self.ns)
        return out.ravel()

    def part_dofs(self, predicate, components) -> np.ndarray:
        """Vector dofs of the components at every dof location inside the part.

        For Lagrange elements a dof is the value at its location, so this fixes exactly
        the points of the part: a face gets its vertex, edge and face dofs, an edge its
        vertex and mid-edge dofs, a corner only its vertex."""
        nodes = np.flatnonzero(predicate(self.doflocs))
        return (self.dim * nodes[:, None] + np.asarray(components, int)[None, :]).ravel()

    def rigid_modes(self) -> np.ndarray:
        """(ndof, 3 | 6) translations and rotations about the centroid, unit-scaled."""
        x = self.doflocs - self.doflocs.mean(axis=1, keepdims=True)
        x = x / max(np.abs(x).max(), 1e-300)
        ns, dim = self.ns, self.dim
        modes = []
        for c in range(dim):
            m = np.zeros((ns, dim))
            m[:, c] = 1
            modes.append(m)
        for i, j in [(0, 1)] if dim == 2 else [(0, 1), (1, 2), (0, 2)]:
            m = np.zeros((ns, dim))
            m[:, i], m[:, j] = -x[j], x[i]
            modes.append(m)
        return np.stack([m.ravel() for m in modes], axis=1)

    def check_rigid(self, fixed: np.ndarray, load_name: str):
        """ModelError unless the constraints remove every rigid motion: no combination of
        rigid modes may vanish on all fixed dofs."""
        R = self.rigid_modes()[fixed]
        nr = 3 if self.dim == 2 else 6
        s = np.linalg.svd(R, compute_uv=False) if len(R) else np.zeros(0)
        if len(s) < nr or s[-1] < 1e-8 * max(s[0], 1e-300):
            free = nr - int(np.sum(s > 1e-8 * (s[0] if len(s) else 1)))
            raise ModelError(
                f"load case '{load_name}': the constraints leave {free} rigid motion(s) free",
                fix="constrain more parts or components",
            )


class _Isoparametric(skfem.MappingIsoparametric):
    """scikit-fem's quad/hex mapping with a Newton tolerance that the rounding of the
    coordinates allows: its absolute 1e-12 on the reference coordinates (summed over a
    facet's quadrature points) cannot be met in the thin cells of a graded mesh far from
    the origin. The iteration converges quadratically, so 1e-9 there is exact to
    rounding in the positions of the quadrature points."""

    def invF(self, x, tind=None, newton_max_iters=50, newton_tol=1e-12):
        return super().invF(
            x, tind=tind, newton_max_iters=newton_max_iters, newton_tol=max(newton_tol, 1e-9)
        )


def mapping(mesh: skfem.Mesh):
    """The mesh's own mapping (affine for simplices), with _Isoparametric for quads/hexes."""
    if mesh.affine:
        return mesh._mapping()
    return _Isoparametric(mesh, mesh.elem(), mesh.bndelem)


def strain_matrix(grad: np.ndarray) -> np.ndarray:
    """Voigt strain-displacement matrices: grad (nbf, dim, ne, nq) of the scalar basis
    -> B (ne, nq, nv, nbf * dim) with engineering shears, interleaved local dofs."""
    nbf, dim, ne, nq = grad.shape
    pairs = VOIGT[dim]
    g = grad.transpose(2, 3, 0, 1)
    B = np.zeros((ne, nq, len(pairs), nbf, dim))
    for I, (i, j) in enumerate(pairs):
        B[:, :, I, :, i] += g[..., j]
        if i != j:
            B[:, :, I, :, j] += g[..., i]
    return B.reshape(ne, nq, len(pairs), nbf * dim)


def _scatter(Ke: np.ndarray, gdofs: np.ndarray, n: int) -> sp.csr_matrix:
    nl = gdofs.shape[1]
    rows = np.repeat(gdofs, nl, axis=1).ravel()
    cols = np.tile(gdofs, (1, nl)).ravel()
    return sp.coo_matrix((Ke.ravel(), (rows, cols)), shape=(n, n)).tocsr()
