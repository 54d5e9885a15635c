"""Cauchy-limit report: the elastic constants a periodic spring lattice can reach.

Under a uniform strain eps every spring of a periodic lattice stretches by
L n.eps.n, so the energy per volume gives (Cauchy-Born)

    C_ijkl = (1 / V_cell) sum_springs k L^2 n_i n_j n_k n_l,

each spring of the infinite lattice counted once per cell. C is linear in the spring
constants, C = sum_g k_g C_g over spring groups, and fully symmetric in ijkl: the
Cauchy relations C_1122 = C_1212 (and in 3-D C_1133 = C_1313, C_2233 = C_2323) hold
for every central-force lattice whose nodes are centres of symmetry. An isotropic
target satisfies them only for lambda = mu: nu = 1/3 in 2-D plane stress, 1/4 in 2-D
plane strain and in 3-D. Any other target nu (or an anisotropic target breaking the
relations) is out of reach: the relative misfit of the best non-negative group
constants is the error floor no optimiser can beat in the interior of a large grid under
a uniform strain. It is not a floor for a finite network's G on particular loads: the
boundary layers and the fit to those loads can take G well below it (docs/models.md, "The Cauchy
limit").
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import nnls

from harness.case.elasticity import element_stiffness
from harness.models.stiffness_rules import voigt_dyad
from harness.models.topology import ALIASES


def cell_springs(structure: str, spacing) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """Spring vectors (m, dim) of one periodic cell of a grid structure, their group ids
    and the group names (the same names as ``harness.models.topology.grid_structure``)."""
    h = np.asarray(spacing, float)
    name = ALIASES.get(structure, structure)
    vecs, names, gids = [], [], []

    def add(v, g):
        if g not in names:
            names.append(g)
        vecs.append(np.asarray(v, float) * h)
        gids.append(names.index(g))

    if len(h) == 2:
        add([1, 0], "horizontal")
        add([0, 1], "vertical")
        if name != "edges":
            add([1, 1], "diagonal")
        if name in ("structure1", "edges+diagonals+second"):
            add([-1, 1], "diagonal")
        if name == "edges+diagonals+second":
            add([2, 0], "second-horizontal")
            add([0, 2], "second-vertical")
    else:
        add([1, 0, 0], "edge-x")
        add([0, 1, 0], "edge-y")
        add([0, 0, 1], "edge-z")
        if "face" in name:
            for v, g in (
                ([1, 1, 0], "face-xy"),
                ([-1, 1, 0], "face-xy"),
                ([1, 0, 1], "face-xz"),
                ([-1, 0, 1], "face-xz"),
                ([0, 1, 1], "face-yz"),
                ([0, -1, 1], "face-yz"),
            ):
                add(v, g)
        if "body" in name:
            for v in ([1, 1, 1], [-1, 1, 1], [1, -1, 1], [1, 1, -1]):
                add(v, "body")
    return np.array(vecs), np.array(gids), tuple(names)


def lattice_stiffness(vectors: np.ndarray, k: np.ndarray, cell_volume: float) -> np.ndarray:
    """Voigt C (3x3 in 2-D, 6x6 in 3-D) of a periodic lattice with these cell springs."""
    vectors = np.asarray(vectors, float)
    L = np.linalg.norm(vectors, axis=1)
    a = voigt_dyad(vectors / L[:, None])
    return np.einsum("m,mi,mj->ij", np.asarray(k, float) * L**2, a, a) / cell_volume


def group_stiffness(structure: str, spacing) -> tuple[np.ndarray, tuple[str, ...]]:
    """C_g (groups, v, v): the lattice C per unit spring constant of each group."""
    vecs, gids, names = cell_springs(structure, spacing)
    V = float(np.prod(spacing))
    Cg = np.array(
        [
            lattice_stiffness(vecs[gids == g], np.ones((gids == g).sum()), V)
            for g in range(len(names))
        ]
    )
    return Cg, names


def engineering_constants(C: np.ndarray) -> dict:
    """Young's moduli, Poisson ratios (nu_ij = -S_ij / S_ii) and shear moduli of Voigt C."""
    S = np.linalg.inv(C)
    if C.shape[0] == 3:
        return {
            "E_x": 1 / S[0, 0],
            "E_y": 1 / S[1, 1],
            "nu_xy": -S[0, 1] / S[0, 0],
            "nu_yx": -S[0, 1] / S[1, 1],
            "G_xy": 1 / S[2, 2],
        }
    return {
        "E_x": 1 / S[0, 0],
        "E_y": 1 / S[1, 1],
        "E_z": 1 / S[2, 2],
        "nu_xy": -S[0, 1] / S[0, 0],
        "nu_xz": -S[0, 2] / S[0, 0],
        "nu_yz": -S[1, 2] / S[1, 1],
        "G_yz": 1 / S[3, 3],
        "G_xz": 1 / S[4, 4],
        "G_xy": 1 / S[5, 5],
    }


def cauchy_nu(dim: int, plane: str = "stress") -> float:
    """The only Poisson ratio an isotropic central-force lattice can have."""
    return 1 / 3 if dim == 2 and plane == "stress" else 1 / 4


def fit_groups(Cg: np.ndarray, C_target: np.ndarray) -> tuple[np.ndarray, float]:
    """Group constants k >= 0 minimising ||sum k_g C_g - C_target||_F; relative misfit."""
    A = Cg.reshape(len(Cg), -1).T
    b = C_target.ravel()
    scale = np.abs(A).max(axis=0)
    scale[scale == 0] = 1
    k, _ = nnls(A / scale, b)
    k = k / scale
    return k, float(np.linalg.norm(A @ k - b) / np.linalg.norm(b))


def cauchy_report(
    structure: str, spacing, C_target: np.ndarray, plane: str = "stress", tol: float = 1e-6
) -> dict:
    """How close the grid structure can get to C_target: best group constants, the
    relative misfit (the error floor), the lattice's engineering constants at the best
    fit, and ``reachable`` (misfit <= tol)."""
    Cg, names = group_stiffness(structure, spacing)
    k, misfit = fit_groups(Cg, np.asarray(C_target, float))
    C = np.einsum("g,gij->ij", k, Cg)
    dim = len(spacing)
    out = {
        "structure": structure,
        "group_names": names,
        "k_groups": k,
        "misfit": misfit,
        "reachable": misfit <= tol,
        "cauchy_nu": cauchy_nu(dim, plane),
    }
    try:
        out["fit"] = engineering_constants(C)
    except np.linalg.LinAlgError:
        out["fit"] = {}
    out["target"] = engineering_constants(np.asarray(C_target, float))
    return out


def boundary_share(
    points: np.ndarray, springs: np.ndarray, lo, hi, rtol: float = 1e-9
) -> np.ndarray:
    """Fraction (e,) of the cells around a spring of the infinite lattice that lie in the
    box: 1/2 per axis along which the spring has no extent and lies on a box face. With
    k = k_group * share a finite grid is exactly the cell-wise assembly of the periodic
    cell, so a uniform strain with tributary loads is an exact equilibrium."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    tol = rtol * float(np.linalg.norm(hi - lo))
    a, b = points[springs[:, 0]], points[springs[:, 1]]
    flat = np.abs(b - a) <= tol
    on = (np.abs(a - lo) <= tol) | (np.abs(a - hi) <= tol)
    return 0.5 ** np.sum(flat & on, axis=1)


def case_report(case, spec) -> dict | None:
    """The Cauchy report of a case's grid model against the material at the body centre
    (None for non-grid placements)."""
    if spec.get("placement") != "grid":
        return None
    lo, hi = case.body.bbox()
    grid = np.asarray(spec["grid"])
    spacing = (np.asarray(hi) - np.asarray(lo)) / (grid - 1)
    C_t = element_stiffness(case.material, ((np.asarray(lo) + np.asarray(hi)) / 2)[None])[0]
    structure = spec.get("structure") or ("structure1" if case.dim == 2 else "edges+face+body")
    return cauchy_report(structure, spacing, C_t, case.material.plane)
