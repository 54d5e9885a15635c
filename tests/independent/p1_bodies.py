"""Small tetrahedral bodies with their loads and their linear P1 answers, for the engine
adapters' tests (tests/engines/): scikit-fem's own mesh, elasticity and load forms and a
direct solve; nothing goes through reference/ or harness/.

A body is clamped on its face x = 0 (every component of those nodes held) and carries
two loads: ``sag`` (gravity along -z, the body force rho g) and ``tip`` (a traction along
-y on the face x = L). Each is scaled so the P1 answer's largest strain is ``PEAK``: small
enough that an engine's nonlinear material is its linearisation to about that."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse.linalg as spla
import skfem
from skfem.models.elasticity import lame_parameters, linear_elasticity

PEAK = 1e-3  # the largest strain of every load's P1 answer


@dataclass(frozen=True)
class Body:
    """Nodes (n, 3) m, tetrahedra (m, 4), clamped nodes, and per load its nodal forces
    (n, 3) N and its P1 answer (n, 3) m."""

    name: str
    points: np.ndarray
    tets: np.ndarray
    clamped: np.ndarray
    forces: dict
    answers: dict


def beam_mesh(length=0.2, side=0.04, n=(6, 2, 2)) -> skfem.MeshTet:
    """A box beam along x."""
    return skfem.MeshTet.init_tensor(
        np.linspace(0, length, n[0] + 1),
        np.linspace(0, side, n[1] + 1),
        np.linspace(0, side, n[2] + 1),
    )


def taper_mesh(length=0.15, side=0.05, n=(5, 2, 2)) -> skfem.MeshTet:
    """A beam whose section shrinks to half its side at x = length and turns by 0.4 rad
    about x on the way: no face but the clamp is a coordinate plane."""
    m = beam_mesh(length, side, n)
    x, y, z = m.p
    s = 1.0 - 0.5 * x / length
    a = 0.4 * x / length
    yc, zc = (y - side / 2) * s, (z - side / 2) * s
    p = np.array([x, np.cos(a) * yc - np.sin(a) * zc, np.sin(a) * yc + np.cos(a) * zc])
    return skfem.MeshTet(p, m.t)


def p1_stiffness(mesh: skfem.MeshTet, E: float, nu: float):
    """K (csr, node-major dofs: 3 node + component) of linear P1 elasticity."""
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementTetP1()))
    return skfem.asm(linear_elasticity(*lame_parameters(E, nu)), basis).tocsr(), basis


def peak_strain(points: np.ndarray, tets: np.ndarray, u: np.ndarray) -> float:
    """The largest |eps| (Frobenius) over the tetrahedra of the P1 field u (n, 3)."""
    X = points[tets[:, 1:]] - points[tets[:, :1]]  # m, 3, 3: edges as rows
    U = u[tets[:, 1:]] - u[tets[:, :1]]
    grad = np.linalg.solve(X, U).transpose(0, 2, 1)  # du_i / dx_j
    eps = 0.5 * (grad + grad.transpose(0, 2, 1))
    return float(np.sqrt(np.sum(eps * eps, axis=(1, 2))).max())


def _loads(mesh, basis, density):
    """{name: nodal force (n, 3)} of unit gravity along -z and a unit traction along -y."""
    fb = skfem.FacetBasis(
        mesh,
        basis.elem,
        facets=mesh.facets_satisfying(lambda x: x[0] > mesh.p[0].max() - 1e-12),
    )
    sag = skfem.asm(skfem.LinearForm(lambda v, w: -density * v[2]), basis)
    tip = skfem.asm(skfem.LinearForm(lambda v, w: -v[1]), fb)
    return {"sag": sag, "tip": tip}


def body(name: str, mesh: skfem.MeshTet, E: float, nu: float, density: float) -> Body:
    """The body of the module docstring on ``mesh``, its loads scaled to PEAK."""
    K, basis = p1_stiffness(mesh, E, nu)
    points, tets = mesh.p.T.copy(), mesh.t.T.copy()
    clamped = np.flatnonzero(points[:, 0] < 1e-12)
    free = np.ones(points.shape, bool)
    free[clamped] = False
    dofs = np.flatnonzero(free.ravel())
    forces, answers = {}, {}
    for load, f in _loads(mesh, basis, density).items():
        u = np.zeros(f.size)
        u[dofs] = spla.spsolve(K[dofs][:, dofs].tocsc(), f[dofs])
        scale = PEAK / peak_strain(points, tets, u.reshape(-1, 3))
        forces[load] = scale * f.reshape(-1, 3)
        answers[load] = scale * u.reshape(-1, 3)
    return Body(name, points, tets, clamped, forces, answers)
