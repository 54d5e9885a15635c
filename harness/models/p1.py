"""Linear P1 finite elements on a spring model's own nodes (model class "p1").

The upper bound a cheap model on these nodes can hope for: the same nodes, masses, loads
and constraints as the spring network, but the stiffness of linear (P1) simplices with
the case's elastic tensor D (``harness.case.elasticity.element_stiffness``; 2-D plane
stress or strain, unit thickness), no free constants. Per element e (volume, 2-D area V_e,
strain-displacement matrix B_e of the constant shape-function gradients, Voigt order of
``harness.case.elasticity``, engineering shear)

    K_e = V_e B_e^T D_e B_e = (sqrt(V_e) B_e^T L_e) (sqrt(V_e) B_e^T L_e)^T,  D_e = L_e L_e^T,

so the term is ``nv`` (6 in 3-D, 3 in 2-D) columns per element beside the springs'
incidence, like the volume term's (harness/models/volume.py): statics, natural frequencies
and the stable step take it unchanged. ``kv`` holds one scale per column (all 1: the
P1 stiffness itself); ``n_elements`` counts columns, as SpringVolumeNetwork expects.
Quads and hexahedra are split into simplices (``harness.models.volume.simplices``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np
import scipy.sparse as sp

from harness.case.elasticity import element_stiffness
from harness.models.sms import SpringNetwork
from harness.models.volume import SpringVolumeNetwork, oriented, simplices, volumes


def shape_gradients(x: np.ndarray, elements: np.ndarray) -> np.ndarray:
    """grad N (m, dim+1, dim) of the linear shape functions of each simplex."""
    e = np.asarray(elements, int)
    A = np.transpose(x[e[:, 1:]] - x[e[:, :1]], (0, 2, 1))  # columns: edges from node 0
    g = np.zeros((len(e), x.shape[1] + 1, x.shape[1]))
    g[:, 1:] = np.linalg.inv(A)  # row j of A^-1 = grad N_{j+1}
    g[:, 0] = -g[:, 1:].sum(axis=1)
    return g


def strain_matrices(x: np.ndarray, elements: np.ndarray) -> np.ndarray:
    """B (m, nv, (dim+1)*dim): Voigt strains (3-D xx, yy, zz, yz, xz, xy; 2-D xx, yy,
    xy; engineering shear) from the element's nodal displacements (node-major)."""
    g = shape_gradients(x, elements)
    m, nn, dim = g.shape
    pairs = (
        [(0, 0), (1, 1), (0, 1)] if dim == 2 else [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)]
    )
    B = np.zeros((m, len(pairs), nn, dim))
    for r, (i, j) in enumerate(pairs):  # eps_ij = (du_i/dx_j + du_j/dx_i) (/2 on the diagonal)
        B[:, r, :, i] += g[:, :, j]
        if i != j:
            B[:, r, :, j] += g[:, :, i]
    return B.reshape(m, len(pairs), nn * dim)


@dataclass(frozen=True, eq=False)
class P1Term:
    """elements (m, dim+1) with rest volumes V0 (m,), Cholesky factors L (m, nv, nv) of
    their elastic tensors, kv (m*nv,) one scale per column (1: P1 itself)."""

    elements: np.ndarray
    V0: np.ndarray
    L: np.ndarray
    kv: np.ndarray
    shared: bool = True

    @classmethod
    def build(cls, points, elements, D) -> "P1Term":
        points = np.asarray(points, float)
        e = oriented(points, elements)
        L = np.linalg.cholesky(np.asarray(D, float))
        return cls(e, volumes(points, e), L, np.ones(len(e) * L.shape[1]))

    @property
    def n_elements(self) -> int:
        """Columns (parameters), nv per element."""
        return len(self.kv)

    def columns(self, points: np.ndarray) -> sp.csc_matrix:
        """C (n*dim, m*nv): sqrt(V_e) B_e^T L_e, element by element."""
        n, dim = points.shape
        B = strain_matrices(np.asarray(points, float), self.elements)
        # (m, nn*dim, nv)
        c = np.einsum("mvk,mvw->mkw", B, self.L) * np.sqrt(self.V0)[:, None, None]
        m, nd, nv = c.shape
        rows = (self.elements[:, :, None] * dim + np.arange(dim)).reshape(m, nd)
        rows = np.repeat(rows[:, :, None], nv, axis=2)
        cols = np.broadcast_to((np.arange(m) * nv)[:, None, None] + np.arange(nv), c.shape)
        return sp.csc_matrix((c.ravel(), (rows.ravel(), cols.ravel())), shape=(n * dim, m * nv))

    def stiffness_matrix(self, points: np.ndarray, kv=None) -> sp.csc_matrix:
        """sum_e V_e B_e^T D_e B_e (kv = 1), n*dim square."""
        C = self.columns(points)
        return (C @ sp.diags(self.kv if kv is None else np.asarray(kv, float)) @ C.T).tocsc()


def with_p1(net: SpringNetwork, material) -> SpringVolumeNetwork:
    """``net``'s nodes, masses and classes with P1 stiffness on its cells (simplices; quads
    and hexahedra split) and no spring stiffness (the springs stay as its connectivity)."""
    el = simplices(net.cells, net.dim)
    D = element_stiffness(material, net.points[el].mean(axis=1))
    term = P1Term.build(net.points, el, D)
    fields = {f.name: getattr(net, f.name) for f in dataclasses.fields(SpringNetwork)}
    fields["k"] = np.zeros(net.n_springs)
    fields["info"] = MappingProxyType({**net.info, "stiffness": "p1"})
    return SpringVolumeNetwork(**fields, volume=term)
