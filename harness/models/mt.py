"""Bourguignon & Cani's element model (MT) on a spring model's own cells (model class "mt").

The model of harness/models/anisotropic.py (the program's force rule: axial springs,
angular couples, volume forces; shared/reference-data/bourguignon2000/README.md) on the
case's cells - the grid's hexahedra, the mesh's tetrahedra - with the same nodes, masses,
loads and constraints as the other classes. Isotropic: every element's three axes lie
along x, y, z (explicit frames; ``rest_angle = "rest"``, the paper's rest angles, 90
degrees here) and share one constant per kind, so the body has three constants
theta = (axial, angular, volume), each a modulus (Pa). An element's own constants are
theta times its size factors, so one theta is one material on a graded mesh too
(element volume V, rest axis lengths L_k, D0 the tet's rest sum of centre distances or
the hex's eight rest radii d_i):

    ks_k      = theta_a V / L_k^2          axis k: (theta_a / 2) eps_k^2 V under a stretch eps_k
    ks_(ij)   = theta_s V / ((L_i+L_j)/2)  angular pair ij: the program's couple -ks (n_i.n_j - c0)
                                           stores (theta_s / 2) gamma_ij^2 V under a shear gamma_ij
    kvs       = 9 theta_v V / D0^2  (tet),  9 theta_v V / sum_i d_i^2  (hex)
                                           a dilation eps about g stores (theta_v / 2) (3 eps)^2 V

Linearised at rest (force-free: the rest lengths, angles and D0 are the rest shape's)
the force is linear in theta: K = sum_j theta_j K_j, K_j the element-by-element complex
step tangent (AnisotropicBody.tangent_stiffness) with only that constant. K is not
symmetric (the angular couples and the volume forces are no energy's gradient; the
angular pair's block is symmetric only when L_i = L_j), so it cannot be written as
C diag(theta) C^T like the volume and P1 terms and the optimisers of harness/optimize
(which assume that form) cannot fit it: an adjoint gradient would need one solve with
K^T per load, -2 lambda^T K_j u per constant. With three constants the sms stage fits
theta by least squares in log theta (harness/stages/bc2000_linear.fit, the B&C suite's
own fit; harness/stages/classes/mt.py). 2-D: B&C 2000 define no 2-D element (their
conclusion leaves surfaces to future work): :func:`unsupported` says so and the stage
writes a skipped row.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np
import scipy.sparse as sp

from harness.errors import ModelError
from harness.models.anisotropic import AnisotropicBody, build_anisotropic
from harness.models.cells import hex_to_tets
from harness.models.sms import SpringNetwork
from harness.models.volume import SpringVolumeNetwork

PARAMS = ("axial", "angular", "volume")  # theta, Pa
NO_2D = (
    "Bourguignon & Cani 2000 define their element model on tetrahedra and hexahedra only "
    "(no 2-D element)"
)


def unsupported(dim: int) -> str | None:
    """Why the class has no model in ``dim`` dimensions (None: it has one)."""
    return None if dim == 3 else NO_2D


def mt_cells(cells) -> np.ndarray:
    """The one cell block (tetrahedra or hexahedra) of a cells mapping; ModelError otherwise."""
    blocks = {k: np.asarray(v, np.int64) for k, v in dict(cells or {}).items() if len(v)}
    if len(blocks) == 1 and next(iter(blocks)) in ("tetra", "hexahedron"):
        return next(iter(blocks.values()))
    raise ModelError(
        f"model class 'mt': cells {sorted(blocks) or 'none'}; B&C's element needs one block of "
        "tetrahedra or hexahedra",
        field="model.classes",
        fix="use placement = 'grid' (hexahedra) or 'mesh' with a tetrahedral mesh",
    )


def size_factors(body: AnisotropicBody) -> np.ndarray:
    """(m, 7): an element's ks1..ks6 and kvs per unit theta (axial, angular, volume)."""
    X = body.points[body.cells]
    T = (
        X[:, [0, 1, 2, 3]][:, None]
        if not body.is_hex
        else body.points[hex_to_tets(body.cells)].reshape(len(X), 6, 4, 3)
    )
    a = T[:, :, 1:] - T[:, :, :1]
    V = (
        np.abs(np.einsum("mtj,mtj->mt", a[:, :, 0], np.cross(a[:, :, 1], a[:, :, 2]))).sum(axis=1)
        / 6.0
    )
    L = body.L0
    pair = np.stack([L[:, 0] + L[:, 1], L[:, 0] + L[:, 2], L[:, 1] + L[:, 2]], axis=1) / 2
    D2 = body.D0**2 if not body.is_hex else np.sum(body.D0**2, axis=1)
    return np.concatenate([V[:, None] / L**2, V[:, None] / pair, (9 * V / D2)[:, None]], axis=1)


@dataclass(frozen=True, eq=False)
class MTTerm:
    """B&C's elements on a network's nodes: ``body`` with per-element constants of unit
    theta (its ks, kvs = :func:`size_factors`), ``units`` the linearised K_j of each
    theta_j (3n square), ``kv`` = theta (3,). ``n_elements``/``kv``/``shared`` are the names
    SpringVolumeNetwork reads for its parameters [k, kv] (here three constants)."""

    body: AnisotropicBody
    units: tuple
    kv: np.ndarray
    shared: bool = False
    symmetric: bool = False  # K is not B diag(k) B^T: harness/optimize cannot take it

    @classmethod
    def build(cls, points, cells, theta, seed: int = 0) -> "MTTerm":
        points = np.asarray(points, float)
        cells = np.asarray(cells, np.int64)
        one = build_anisotropic(
            points,
            cells,
            frames=np.eye(3),
            ks=1.0,
            kvs=1.0,
            volume=True,
            rest_angle="rest",
            seed=seed,
        )
        s = size_factors(one)
        body = dataclasses.replace(one, ks=s[:, :6].copy(), kvs=s[:, 6].copy())
        f = body.element_forces(points[cells])  # the rest shape must be force-free
        scale = np.abs(s[:, :3] * body.L0).max(axis=1)
        bad = np.flatnonzero(np.abs(f).max(axis=(1, 2)) > 1e-9 * scale)
        # a hex face that is no rectangle: the program's bilinear weights miss the axis ends
        if len(bad):
            raise ModelError(
                f"model class 'mt': elements {bad[:5].tolist()} are not force-free at rest (B&C's "
                "hexahedron weights its axis ends exactly on rectangular faces only)",
                field="model.classes",
                fix="use a grid of rectangular hexahedra or a tetrahedral mesh",
            )
        zero6, zero = np.zeros_like(body.ks), np.zeros_like(body.kvs)
        units = []
        for j, cols in enumerate(([0, 1, 2], [3, 4, 5], [])):
            ks = zero6.copy()
            ks[:, cols] = body.ks[:, cols]
            units.append(
                dataclasses.replace(
                    body, ks=ks, kvs=body.kvs if j == 2 else zero
                ).tangent_stiffness()
            )
        theta = np.broadcast_to(np.asarray(theta, float), (len(PARAMS),)).copy()
        return cls(body, tuple(u.tocsr() for u in units), theta)

    @property
    def n_elements(self) -> int:
        """Parameters (three: axial, angular, volume)."""
        return len(self.kv)

    def stiffness_matrix(self, points=None, kv=None) -> sp.csc_matrix:
        """sum_j theta_j K_j (3n square, not symmetric) at the rest positions."""
        t = self.kv if kv is None else np.asarray(kv, float)
        return sum(float(tj) * K for tj, K in zip(t, self.units)).tocsc()

    def model(self, kv=None) -> AnisotropicBody:
        """The nonlinear B&C model with theta's element constants (for simulations)."""
        t = self.kv if kv is None else np.asarray(kv, float)
        ks = self.body.ks * np.repeat(t[:2], 3)[None, :]
        return dataclasses.replace(self.body, ks=ks, kvs=self.body.kvs * t[2])


def start_theta(material) -> np.ndarray:
    """A start for theta (not a calibration): an isotropic tensor's C11 = lambda + 2 mu,
    C12 = lambda, C44 = mu read as axial 2 mu, angular mu and a volume term lambda (at
    least 5 % of the bulk modulus, so the start is positive at nu = 0)."""
    E, nu = float(material.E), float(material.nu)
    mu, lam = E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))
    return np.array([2 * mu, mu, max(lam, 0.05 * E / (3 * (1 - 2 * nu)))])


def with_mt(net: SpringNetwork, material, theta=None) -> SpringVolumeNetwork:
    """``net``'s nodes, masses and classes with B&C's elements on its cells and no spring
    stiffness (the springs stay as its connectivity), theta by default :func:`start_theta`."""
    why = unsupported(net.dim)
    if why:
        raise ModelError(why, field="model.classes", fix="list 'mt' only in 3-D cases")
    term = MTTerm.build(
        net.points,
        mt_cells(net.cells),
        start_theta(material) if theta is None else theta,
        seed=int(net.info.get("seed", 0)),
    )
    fields = {f.name: getattr(net, f.name) for f in dataclasses.fields(SpringNetwork)}
    fields["k"] = np.zeros(net.n_springs)
    fields["info"] = MappingProxyType({**net.info, "stiffness": "mt"})
    return SpringVolumeNetwork(**fields, volume=term)
