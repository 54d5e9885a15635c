"""The adjustable-Poisson correction of Kot & Nagahashi 2015 added to a spring network
("springs+kn").

Kot & Nagahashi ("Second degree of freedom of elastic objects - adjustable Poisson's ratio
for mass spring models", GRAPP 2015) keep the springs and let the force a spring brings to
a node be dispersed uniformly to all the springs connected with that node, scaled by their
length; the redistribution is isotropic and frees nu from the Cauchy value (their Fig. 8:
a block compressed at nu = -1, 0, 0.25, 0.47). Only the abstract, the introduction and the
conclusion of the paper were readable here, which state that rule in words but not its
equations, so this module implements the closest energy-consistent form of it (force =
-gradient of an energy, hence a symmetric stiffness, and the adjoint gradient of the fit
applies unchanged). With the springs' strains and a node's mean spring strain

    eps_e = (l_e - L_e) / L_e,       s_a = (1 / N_a) sum_{e at a} eps_e

(N_a the springs at node a, L_e rest lengths), each node a adds

    E_a = (kn_a / 2) V_a d^2 s_a^2                      (d = 2 or 3, V_a the node's volume)

whose force is exactly the rule above: the node's scalar kn_a V_a d^2 s_a is shared
equally by its N_a springs, each carrying the tension T_e = sum_{a = ends of e}
kn_a V_a d^2 s_a / (N_a L_e) along itself (f_j = -T_e u_e, f_i = +T_e u_e, u_e = (x_j -
x_i) / l_e). The term depends on lengths only, so rigid motions carry no energy, exactly.
V_a: the node's lumped share of the model's cells (each simplex's volume / (d + 1);
quads and hexahedra split as in harness/models/volume.py), so kn is a modulus: Pa in 3-D,
N/m in 2-D (Pa times the unit thickness).

Where it is exact. For a homogeneous strain eps, eps_e = u_e . eps u_e (linearised); at a
node whose star has mean(u u^T) = I / d (every star of the cubic lattices edges+face,
edges+face+body and of the 2-D square lattice with both diagonals, away from the
boundary) s_a = tr(eps) / d, so E_a / V_a = kn (tr eps)^2 / 2: the term adds kn to the
Lame constant lambda and nothing to mu. A cubic lattice of spacing h with springs k1
(edges) and k2 (face diagonals) has C11 = (k1 + 2 k2) / h, C12 = C44 = k2 / h; with
k1 = k2 = k it is isotropic at nu = 1/4 and the term gives

    lambda = k / h + kn,  mu = k / h,  nu = (k / h + kn) / (4 k / h + 2 kn),

nu from 1/4 (kn = 0) to 1/2 (kn -> inf), and down to -1 for kn -> -5 k / (3 h) (bulk
modulus 0), the paper's range. 2-D, the square lattice with edges 2k and both diagonals k
(per unit thickness): lambda = k + kn, mu = k, plane-stress nu = (k + kn) / (3 k + kn),
1/3 at kn = 0. The tests check both against the model's own energy (tests/models/test_kn.py).
Approximations: on boundary nodes and irregular stars mean(u u^T) != I / d, so s_a mixes
in deviatoric strain; the energy is quadratic in the spring strains (not in volume).
Linearised at rest (statics, modes) the term is rank one per node: K = C diag(kn) C^T
with the column c_a = d sqrt(V_a) / N_a sum_{e at a} b_e / L_e (b_e the springs'
incidence columns, harness.models.springs), beside B like the volume term's columns.
The optimisers fit positive constants (factors of a positive start), so a fitted kn >= 0
and the fitted range is nu >= the springs' own; the module itself takes any sign.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np
import scipy.sparse as sp

from harness.errors import ModelError, naming
from harness.models.sms import SpringNetwork
from harness.models.springs import incidence
from harness.models.volume import SpringVolumeNetwork, initial_kv, oriented, simplices, volumes

MODES = ("none", "node", "shared")  # [model] kn: none, one constant per node, one per body


def node_volumes(points: np.ndarray, elements: np.ndarray) -> np.ndarray:
    """Each node's lumped volume (n,) (2-D: area): every simplex gives V / (dim + 1) to each
    of its nodes."""
    points = np.asarray(points, float)
    e = oriented(points, elements)
    share = np.repeat(volumes(points, e) / e.shape[1], e.shape[1])
    return np.bincount(e.ravel(), share, len(points))


@dataclass(frozen=True, eq=False)
class KNTerm:
    """springs (s, 2) with rest lengths L0 (s,); ``nodes`` (m,) the nodes carrying a term
    (at least one spring, positive volume), their spring counts N (m,), volumes V (m,)
    and constants kv (m,) (named as VolumeTerm's, so SpringVolumeNetwork fits them);
    ``shared``: fitted as one constant per body."""

    springs: np.ndarray
    L0: np.ndarray
    nodes: np.ndarray
    N: np.ndarray
    V: np.ndarray
    kv: np.ndarray
    shared: bool = False

    @classmethod
    def build(cls, points, springs, node_volume, kn, shared: bool = False) -> "KNTerm":
        """The term of the springs ``springs`` at rest ``points``, node volumes ``node_volume``
        (n,) and constants ``kn`` (one number or one per carrying node)."""
        points = np.asarray(points, float)
        springs = np.asarray(springs, dtype=np.int64)
        n = len(points)
        L0 = np.linalg.norm(points[springs[:, 1]] - points[springs[:, 0]], axis=1)
        deg = np.bincount(springs.ravel(), minlength=n)
        V = np.asarray(node_volume, float)
        nodes = np.flatnonzero((deg > 0) & (V > 0))
        kn = np.broadcast_to(np.asarray(kn, float), (len(nodes),)).copy()
        return cls(springs, L0, nodes, deg[nodes].astype(float), V[nodes], kn, bool(shared))

    @property
    def n_elements(self) -> int:
        """Parameters (one per carrying node), as SpringVolumeNetwork counts them."""
        return len(self.nodes)

    def _weights(self, n: int) -> sp.csr_matrix:
        """W (s, m): W[e, a] = 1 / (N_a L_e) for the ends a of spring e, so s = W^T eps-sum."""
        pos = np.full(n, -1)
        pos[self.nodes] = np.arange(self.n_elements)
        rows, cols, vals = [], [], []
        for end in (0, 1):
            a = pos[self.springs[:, end]]
            ok = a >= 0
            rows.append(np.flatnonzero(ok))
            cols.append(a[ok])
            vals.append(1.0 / (self.N[a[ok]] * self.L0[ok]))
        return sp.csr_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
            shape=(len(self.springs), self.n_elements),
        )

    def mean_strains(self, x: np.ndarray) -> np.ndarray:
        """s_a (m,): the mean spring strain at each carrying node at positions x (n, dim)."""
        l = np.linalg.norm(x[self.springs[:, 1]] - x[self.springs[:, 0]], axis=1)
        return self._weights(len(x)).T @ (l - self.L0)

    def energy(self, x: np.ndarray) -> float:
        s = self.mean_strains(x)
        return float(0.5 * np.sum(self.kv * self.V * x.shape[1] ** 2 * s * s))

    def forces(self, x: np.ndarray) -> np.ndarray:
        """f = -dE/dx (n, dim): each spring's tension T_e from the scalars of its end nodes."""
        dim = x.shape[1]
        d = x[self.springs[:, 1]] - x[self.springs[:, 0]]
        l = np.linalg.norm(d, axis=1)
        W = self._weights(len(x))
        s = W.T @ (l - self.L0)
        T = W @ (self.kv * self.V * dim**2 * s)
        g = T[:, None] * d / l[:, None]  # dE/dx_j for spring (i, j); -that at i
        out = np.zeros(x.shape)
        for c in range(dim):
            out[:, c] = np.bincount(self.springs[:, 0], g[:, c], len(x)) - np.bincount(
                self.springs[:, 1], g[:, c], len(x)
            )
        return out

    def columns(self, points: np.ndarray) -> sp.csc_matrix:
        """C (n*dim, m): column a = d sqrt(V_a) / N_a sum_{e at a} b_e / L_e at rest."""
        points = np.asarray(points, float)
        dim = points.shape[1]
        W = self._weights(len(points)) @ sp.diags(dim * np.sqrt(self.V))
        return (incidence(points, self.springs) @ W).tocsc()

    def stiffness_matrix(self, points: np.ndarray, kv=None) -> sp.csc_matrix:
        """Linearised K = sum_a kn_a c_a c_a^T at rest (n*dim square)."""
        C = self.columns(points)
        return (C @ sp.diags(self.kv if kv is None else np.asarray(kv, float)) @ C.T).tocsc()


def with_kn(net: SpringNetwork, mode: str, kn, elements=None) -> SpringNetwork:
    """``net`` with the Kot-Nagahashi term on its springs, node volumes from its cells (or
    ``elements``, simplices): mode 'node' (one kn per node) or 'shared' (one per body);
    'none' returns net unchanged."""
    if mode not in MODES:
        raise ModelError(
            f"kn = '{mode}' is not one of {', '.join(MODES)}",
            field="model.kn",
            fix="kn = 'shared' (one constant per body) or 'node' (one per node)",
        )
    if mode == "none":
        return net
    if getattr(net, "volume", None) is not None:
        raise ModelError(
            "kn and volume both set: a model holds one extra term",
            field="model.kn",
            fix="set volume = 'none' or kn = 'none'",
        )
    if elements is None:
        try:
            elements = simplices(net.cells, net.dim)
        except ModelError as exc:
            raise ModelError(
                exc.message.replace("volume term", "kn term"), field="model.kn", fix=exc.fix
            ) from None
    term = KNTerm.build(
        net.points, net.springs, node_volumes(net.points, elements), kn, shared=(mode == "shared")
    )
    fields = {f.name: getattr(net, f.name) for f in dataclasses.fields(SpringNetwork)}
    fields["info"] = MappingProxyType({**net.info, "kn": mode})
    return SpringVolumeNetwork(**fields, volume=term)


def case_kn(net: SpringNetwork, case, spec: dict) -> SpringNetwork:
    """The [model] table's kn term on a built network, started at the material's bulk
    modulus beyond its Cauchy-ratio value (harness.models.volume.initial_kv: the term adds
    kn to the bulk modulus of a regular lattice); errors name the case file."""
    if spec.get("kn", "none") == "none":
        return net
    with naming(case):
        return with_kn(net, spec["kn"], initial_kv(case.material, case.dim))


def save(path, net) -> None:
    """The term of ``net`` as .npz (springs, nodes, V, kv, shared) beside its VTU."""
    t = net.volume
    np.savez(path, springs=t.springs, nodes=t.nodes, V=t.V, kv=t.kv, shared=np.array(t.shared))


def load(path, net: SpringNetwork) -> SpringNetwork:
    """``net`` (read from a VTU) with the term saved by ``save``."""
    d = np.load(path)
    V = np.zeros(net.n_nodes)
    V[d["nodes"]] = d["V"]
    term = KNTerm.build(
        net.points, np.asarray(d["springs"], int), V, np.asarray(d["kv"], float), bool(d["shared"])
    )
    fields = {f.name: getattr(net, f.name) for f in dataclasses.fields(SpringNetwork)}
    return SpringVolumeNetwork(**fields, volume=term)
