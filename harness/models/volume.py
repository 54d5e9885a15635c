"""A volume term per simplex added to a spring network ("springs + volume").

Each element e (a tetrahedron in 3-D, a triangle in 2-D; nodes in ``elements`` (m, dim+1))
with signed volume (2-D: area) V_e and rest value V0_e > 0 stores

    E_v = (kv_e / 2) (V_e - V0_e)^2 / V0_e  =  (kv_e / 2) (dV_e / V0_e)^2 V0_e,

the energy of a bulk modulus kv_e acting on the element's volumetric strain: central
springs alone are isotropic only at the Cauchy ratio (nu = 1/4 in 3-D, 1/3 in 2-D plane
stress); this term adds bulk stiffness with no shear, so nu up to 0.5 becomes reachable.
Units: kv in Pa (N/m^2) in 3-D; in 2-D N/m (Pa times the unit thickness, the convention of
the 2-D spring constants).

Forces f = -dE/dx = -kv (V - V0) / V0 grad V. The stiffness at x is
kv / V0 (grad V grad V^T + (V - V0) hess V); at rest the second term vanishes, so the
linearised term is rank one per element: K_v = C diag(kv) C^T with the column
c_e = grad V_e / sqrt(V0_e) (dof = dim*node + component, as ``harness.models.springs``). The
columns sit beside the spring incidence B, so statics and every optimiser (which only see
K = B diag(k) B^T) take [B C] and [k, kv] unchanged: the adjoint gradient of G^2 is
2 (c_e . lambda)(c_e . u) per load, SA's rank-one updates apply per element.
V is invariant under translations and rotations (det R = 1), so rigid motions carry
no energy, exactly.

One volume term per element locks: on linear simplices a clamp and a large kv leave too
few displacement fields that keep every element's volume (at nu = 0.45, on coarse tets, a
fit with it is 2-3x worse than the rule under a two-end clamp). ``NodeVolumeTerm`` puts
the term on the nodes instead, the averaged nodal dilatation of Bonet & Burton 1998 ("A
simple average nodal pressure tetrahedral element for incompressible and nearly
incompressible dynamic explicit applications"): node a owns V0_a = sum_{e at a} V0_e /
(dim + 1) and stores

    E_a = (kv_a / 2) (dV_a)^2 / V0_a,      dV_a = sum_{e at a} (V_e - V0_e) / (dim + 1),

a third as many constraints as displacement dofs, so no locking; under a homogeneous
strain dV_a / V0_a = tr(eps) at every node, boundary nodes included, so the term adds
exactly kv to the Lame constant lambda and nothing to mu. Its linearised column is
c_a = sum_{e at a} grad V_e / ((dim + 1) sqrt(V0_a)); forces -kv_a dV_a / V0_a grad dV_a.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np
import scipy.sparse as sp

from harness.errors import ModelError, naming
from harness.models.cells import hex_to_tets
from harness.models.sms import SpringNetwork

# [model] volume (harness/case/sections.py): none; on the elements one kv each ('element')
# or one per body ('shared'); on the nodes one kv each ('node') or one per body ('node-shared')
MODES = ("none", "element", "shared", "node", "node-shared")


def volumes(x: np.ndarray, elements: np.ndarray) -> np.ndarray:
    """Signed volumes (3-D) or areas (2-D) (m,) of the simplices at positions x (n, dim)."""
    e = np.asarray(elements, int)
    a = x[e[:, 1:]] - x[e[:, :1]]  # (m, dim, dim) edge vectors from node 0
    if x.shape[1] == 2:
        return 0.5 * (a[:, 0, 0] * a[:, 1, 1] - a[:, 0, 1] * a[:, 1, 0])
    return np.einsum("ij,ij->i", a[:, 0], np.cross(a[:, 1], a[:, 2])) / 6.0


def volume_gradients(x: np.ndarray, elements: np.ndarray) -> np.ndarray:
    """dV/dx (m, dim+1, dim): the gradient of each element's volume wrt its nodes."""
    e = np.asarray(elements, int)
    a = x[e[:, 1:]] - x[e[:, :1]]
    g = np.zeros((len(e), x.shape[1] + 1, x.shape[1]))
    if x.shape[1] == 2:  # A = (a0 x a1)/2: dA/da0 = (a1_y, -a1_x)/2, dA/da1 = (-a0_y, a0_x)/2
        g[:, 1] = 0.5 * np.stack([a[:, 1, 1], -a[:, 1, 0]], axis=1)
        g[:, 2] = 0.5 * np.stack([-a[:, 0, 1], a[:, 0, 0]], axis=1)
    else:  # V = a0 . (a1 x a2)/6: cyclic cross products
        g[:, 1] = np.cross(a[:, 1], a[:, 2]) / 6.0
        g[:, 2] = np.cross(a[:, 2], a[:, 0]) / 6.0
        g[:, 3] = np.cross(a[:, 0], a[:, 1]) / 6.0
    g[:, 0] = -g[:, 1:].sum(axis=1)
    return g


def scaled_gradient_forces(x: np.ndarray, elements: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(n, dim): sum over the elements of s_e grad V_e, gathered on their nodes."""
    g = volume_gradients(x, elements) * s[:, None, None]
    out = np.zeros(x.shape)
    for c in range(x.shape[1]):
        out[:, c] = np.bincount(elements.ravel(), g[:, :, c].ravel(), len(x))
    return out


def gradient_columns(points: np.ndarray, elements: np.ndarray) -> sp.csc_matrix:
    """(n*dim, m): column e = grad V_e at ``points`` (dof = dim*node + component)."""
    n, dim = points.shape
    g = volume_gradients(np.asarray(points, float), elements)
    rows = elements[:, :, None] * dim + np.arange(dim)
    cols = np.repeat(np.arange(len(elements)), (dim + 1) * dim)
    return sp.csc_matrix((g.ravel(), (rows.ravel(), cols)), shape=(n * dim, len(elements)))


def oriented(points: np.ndarray, elements: np.ndarray) -> np.ndarray:
    """The elements with two nodes swapped where the rest volume is negative (V0 > 0);
    a degenerate element (V0 = 0) is a ModelError naming it."""
    e = np.array(elements, dtype=np.int64, copy=True)
    V = volumes(np.asarray(points, float), e)
    scale = float(np.ptp(points, axis=0).max()) ** points.shape[1]
    flat = np.flatnonzero(np.abs(V) <= 1e-12 * scale)
    if len(flat):
        raise ModelError(
            f"elements {flat[:5].tolist()} have zero rest volume",
            field="model.volume",
            fix="remove degenerate cells from the mesh",
        )
    neg = V < 0
    e[neg, 0], e[neg, 1] = e[neg, 1], e[neg, 0].copy()
    return e


@dataclass(frozen=True, eq=False)
class VolumeTerm:
    """elements (m, dim+1) node ids with positive rest volume V0 (m,) (2-D: area) and
    kv (m,) volume constants; ``shared``: fitted as one constant per body."""

    elements: np.ndarray
    V0: np.ndarray
    kv: np.ndarray
    shared: bool = False

    @classmethod
    def build(cls, points, elements, kv, shared: bool = False) -> "VolumeTerm":
        points = np.asarray(points, float)
        e = oriented(points, elements)
        kv = np.broadcast_to(np.asarray(kv, float), (len(e),)).copy()
        return cls(e, volumes(points, e), kv, bool(shared))

    @property
    def n_elements(self) -> int:
        return len(self.elements)

    def energy(self, x: np.ndarray) -> float:
        dV = volumes(x, self.elements) - self.V0
        return float(0.5 * np.sum(self.kv * dV * dV / self.V0))

    def forces(self, x: np.ndarray) -> np.ndarray:
        """f = -dE/dx (n, dim) at positions x (n, dim)."""
        return scaled_gradient_forces(
            x, self.elements, -self.kv * (volumes(x, self.elements) - self.V0) / self.V0
        )

    def columns(self, points: np.ndarray) -> sp.csc_matrix:
        """C (n*dim, m): column e = grad V_e / sqrt(V0_e) at the rest positions ``points``."""
        return (gradient_columns(points, self.elements) @ sp.diags(1.0 / np.sqrt(self.V0))).tocsc()

    def stiffness_matrix(self, points: np.ndarray, kv=None) -> sp.csc_matrix:
        """Linearised K_v = sum_e kv_e / V0_e grad V_e grad V_e^T at rest (n*dim square)."""
        C = self.columns(points)
        return (C @ sp.diags(self.kv if kv is None else np.asarray(kv, float)) @ C.T).tocsc()


@dataclass(frozen=True, eq=False)
class NodeVolumeTerm:
    """One volume term per node (module doc): elements (m, dim+1) with rest volumes V0
    (m,); ``nodes`` (p,) the nodes that own volume, their rest volumes Vn (p,) and
    constants kv (p,) (named as VolumeTerm's, so SpringVolumeNetwork fits them);
    ``shared``: fitted as one constant per body."""

    elements: np.ndarray
    V0: np.ndarray
    nodes: np.ndarray
    Vn: np.ndarray
    kv: np.ndarray
    shared: bool = False

    @classmethod
    def build(cls, points, elements, kv, shared: bool = False) -> "NodeVolumeTerm":
        points = np.asarray(points, float)
        e = oriented(points, elements)
        V0 = volumes(points, e)
        owned = np.bincount(e.ravel(), np.repeat(V0 / e.shape[1], e.shape[1]), len(points))
        nodes = np.flatnonzero(owned > 0)
        kv = np.broadcast_to(np.asarray(kv, float), (len(nodes),)).copy()
        return cls(e, V0, nodes, owned[nodes], kv, bool(shared))

    @property
    def n_elements(self) -> int:
        """Parameters (one per node that owns volume), as SpringVolumeNetwork counts them."""
        return len(self.nodes)

    def _shares(self, n: int) -> sp.csr_matrix:
        """A (m, p): A[e, a] = 1 / (dim + 1) for the nodes a of element e, so dV_n = A^T dV_e."""
        where = np.full(n, -1)
        where[self.nodes] = np.arange(len(self.nodes))
        m, k = self.elements.shape
        return sp.csr_matrix(
            (np.full(m * k, 1.0 / k), (np.repeat(np.arange(m), k), where[self.elements.ravel()])),
            shape=(m, len(self.nodes)),
        )

    def node_changes(self, x: np.ndarray) -> np.ndarray:
        """dV_a (p,): each node's share of its elements' volume change at positions x."""
        return self._shares(len(x)).T @ (volumes(x, self.elements) - self.V0)

    def energy(self, x: np.ndarray) -> float:
        dV = self.node_changes(x)
        return float(0.5 * np.sum(self.kv * dV * dV / self.Vn))

    def forces(self, x: np.ndarray) -> np.ndarray:
        """f = -dE/dx (n, dim): each element's nodes get its volume gradient times the mean
        of its nodes' -kv dV / V0."""
        s = self._shares(len(x)) @ (-self.kv * self.node_changes(x) / self.Vn)
        return scaled_gradient_forces(x, self.elements, s)

    def columns(self, points: np.ndarray) -> sp.csc_matrix:
        """C (n*dim, p): column a = sum_{e at a} grad V_e / ((dim + 1) sqrt(V0_a)) at rest."""
        points = np.asarray(points, float)
        return (
            gradient_columns(points, self.elements)
            @ self._shares(len(points))
            @ sp.diags(1.0 / np.sqrt(self.Vn))
        ).tocsc()

    def stiffness_matrix(self, points: np.ndarray, kv=None) -> sp.csc_matrix:
        """Linearised K_v = sum_a kv_a c_a c_a^T at rest (n*dim square)."""
        C = self.columns(points)
        return (C @ sp.diags(self.kv if kv is None else np.asarray(kv, float)) @ C.T).tocsc()


@dataclass(frozen=True, eq=False)
class SpringVolumeNetwork(SpringNetwork):
    """A SpringNetwork plus a VolumeTerm; its parameters are [k (springs), kv (elements)]."""

    volume: VolumeTerm | None = None

    def params(self) -> np.ndarray:
        return np.concatenate([self.k, self.volume.kv])

    def with_k(self, k, **info) -> "SpringVolumeNetwork":
        """Other constants: k (springs only) or [k, kv] (springs then elements)."""
        k = np.asarray(k, float)
        vol = self.volume
        if k.shape == (self.n_springs + vol.n_elements,):
            vol = dataclasses.replace(vol, kv=k[self.n_springs :].copy())
            k = k[: self.n_springs]
        net = super().with_k(k, **info)
        return dataclasses.replace(net, volume=vol)

    def stiffness_matrix(self):
        return (super().stiffness_matrix() + self.volume.stiffness_matrix(self.points)).tocsc()

    def param_groups(self, grouped: bool) -> np.ndarray | None:
        """Parameter groups of the fit over [k, kv]: springs one each (or their groups if
        ``grouped``), elements one each or, if shared, one for all. None: all free."""
        if not grouped and not self.volume.shared:
            return None
        g = np.asarray(self.groups, int) if grouped else np.arange(self.n_springs)
        top = int(g.max(initial=-1)) + 1
        m = self.volume.n_elements
        return np.concatenate([g, np.full(m, top) if self.volume.shared else top + np.arange(m)])


def simplices(cells, dim: int) -> np.ndarray:
    """The tetrahedra (3-D) or triangles (2-D) of a cells mapping; quads and hexahedra are
    split (2 triangles, 6 tetrahedra: hex_to_tets). Other cells are a ModelError."""
    out = []
    for ctype, c in dict(cells or {}).items():
        c = np.asarray(c, int)
        if ctype == ("tetra" if dim == 3 else "triangle"):
            out.append(c)
        elif ctype == "hexahedron" and dim == 3:
            out.append(hex_to_tets(c))
        elif ctype == "quad" and dim == 2:
            out.append(np.concatenate([c[:, [0, 1, 2]], c[:, [0, 2, 3]]]))
        else:
            raise ModelError(
                f"volume term: cells of type '{ctype}' in a {dim}-D model",
                field="model.volume",
                fix="use triangle/quad (2-D) or tetra/hexahedron (3-D) cells",
            )
    if not out:
        raise ModelError(
            "volume term: the model has no cells",
            field="model.volume",
            fix="use a placement with cells (grid, mesh, random, lloyd), or volume = 'none'",
        )
    return np.concatenate(out)


def bulk_modulus(material, dim: int) -> float:
    """The material's bulk modulus (3-D: E / (3 (1 - 2 nu)); 2-D: the area modulus of
    plane stress E / (2 (1 - nu)) or plane strain E / (2 (1 + nu) (1 - 2 nu)))."""
    E, nu = float(material.E), float(material.nu)
    if dim == 3:
        return E / (3 * (1 - 2 * nu))
    if getattr(material, "plane", "stress") == "strain":
        return E / (2 * (1 + nu) * (1 - 2 * nu))
    return E / (2 * (1 - nu))


def initial_kv(material, dim: int) -> float:
    """A start for kv (not a calibration): the bulk modulus the material has beyond that of
    the same E at the Cauchy ratio (springs' own), at least 5 % of the material's."""
    cauchy = 0.25 if dim == 3 or getattr(material, "plane", "stress") == "strain" else 1.0 / 3.0
    K = bulk_modulus(material, dim)
    Kc = bulk_modulus(dataclasses.replace(material, nu=cauchy), dim)
    return max(K - Kc, 0.05 * K)


def with_volume(net: SpringNetwork, mode: str, kv, elements=None) -> SpringNetwork:
    """``net`` with a volume term on its cells (or ``elements``): mode 'element' (one kv
    per element), 'shared' (one per body), 'node' (one per node: NodeVolumeTerm) or
    'node-shared'; 'none' returns net unchanged."""
    if mode not in MODES:
        raise ModelError(
            f"volume = '{mode}' is not one of {', '.join(MODES)}",
            field="model.volume",
            fix="volume = 'element' (one kv per element), 'shared' (one per body), 'node' (one per "
            "node) or 'node-shared'",
        )
    if mode == "none":
        return net
    el = simplices(net.cells, net.dim) if elements is None else np.asarray(elements, int)
    term = NodeVolumeTerm if mode.startswith("node") else VolumeTerm
    vol = term.build(net.points, el, kv, shared=mode in ("shared", "node-shared"))
    fields = {f.name: getattr(net, f.name) for f in dataclasses.fields(SpringNetwork)}
    fields["info"] = MappingProxyType({**net.info, "volume": mode})
    return SpringVolumeNetwork(**fields, volume=vol)


def case_volume(net: SpringNetwork, case, spec: dict) -> SpringNetwork:
    """The [model] table's volume term (``volume``, ``kv``) on a built network; errors name
    the case file."""
    if spec.get("volume", "none") == "none":
        return net
    kv = spec.get("kv") or initial_kv(case.material, case.dim)
    with naming(case):
        return with_volume(net, spec["volume"], kv)


def save(path, net) -> None:
    """The volume term of ``net`` as .npz (elements, V0, kv, shared, on: 'element' or
    'node') beside its VTU."""
    v = net.volume
    on = "node" if isinstance(v, NodeVolumeTerm) else "element"
    np.savez(
        path, elements=v.elements, V0=v.V0, kv=v.kv, shared=np.array(v.shared), on=np.array(on)
    )


def load(path, net: SpringNetwork) -> SpringNetwork:
    """``net`` (read from a VTU) with the volume term saved by ``save``."""
    d = np.load(path)
    el = np.asarray(d["elements"], int)
    if "on" in d and str(d["on"]) == "node":
        vol = dataclasses.replace(
            NodeVolumeTerm.build(net.points, el, 1.0, bool(d["shared"])),
            kv=np.asarray(d["kv"], float),
        )
    else:
        vol = VolumeTerm(el, volumes(net.points, el), np.asarray(d["kv"], float), bool(d["shared"]))
    fields = {f.name: getattr(net, f.name) for f in dataclasses.fields(SpringNetwork)}
    return SpringVolumeNetwork(**fields, volume=vol)


def effective_bulk_modulus(points, elements, u, p: float) -> float:
    """p / (dV / V): the bulk modulus a body shows under a hydrostatic traction p n on its
    whole surface (u (n, dim) its response; 2-D: the area modulus), with dV the linearised
    change of the elements' total volume, sum_e grad V_e . u."""
    e = oriented(points, elements)
    dV = float(
        np.einsum(
            "eid,eid->", volume_gradients(np.asarray(points, float), e), np.asarray(u, float)[e]
        )
    )
    return p / (dV / float(volumes(np.asarray(points, float), e).sum()))
