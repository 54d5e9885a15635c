"""The ``learned`` stiffness rule: van Gelder's constants times a fitted correction.

    k_e = k_vG,e * exp(sum_j c_j phi_j(e, nu)),   k_vG,e = sum_{T ∋ e} E_dir |T| / |e|^2

(harness/models/stiffness_rules.py ``vangelder``). The features phi_j are cheap, vectorised
and free of the mesh's units and orientation (so k scales as E L in 3-D, as E in 2-D, like
van Gelder's), and ``c`` has one short vector per dimension, fitted by ``springbench rules
fit`` (harness/optimize/rule_fit.py) on a corpus of meshes against exact answers and shipped
in learned_rule.json beside this module. All c = 0 is van Gelder's rule.

Features of spring e (``FEATURES[dim]``, in this order), t = nu - NU0:

- ``1``, ``nu`` (t), ``nu^2`` (t^2): the scale and its dependence on Poisson's ratio
  (a spring network has no independent bulk stiffness, so the best scale moves with nu);
- ``log_length``: log(|e| / Lbar_e), Lbar_e the mean over e's two end nodes of the mean
  length of the springs at each: how long the spring is for its neighbourhood;
- ``boundary``: 1 on an edge of the body's surface (an edge of a boundary facet), else 0;
- ``log_cells`` (3-D): log(n_e / n_reg), n_e the number of cells sharing e, n_reg =
  2 pi / arccos(1/3) = 5.1 (regular tetrahedra round an edge); in 2-D n_e is 2 - boundary;
- ``dihedral``: the mean over those cells of cos(theta) - cos(theta_reg): theta the
  dihedral angle at e (3-D, regular 1/3) or the angle opposite e (2-D, regular 1/2);
- ``log_quality``: log of the mean over those cells of their quality (d! |T| / L_rms^d
  normalised, 1 for a regular simplex: harness/models/topology.py ``simplex_quality``),
  floored at 1e-3.

Quads and hexahedra (and meshes mixing them with simplices) keep only the scale: the
geometric features are 0 there, so the rule is van Gelder's times the fitted
exp(c_1 + c_nu t + c_nu2 t^2). ``nu`` is the [material] table's (for fibres and regions
van Gelder's E_dir still follows the local material).
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

import numpy as np

from harness.errors import ModelError
from harness.models.topology import element_pairs, simplex_quality

NU0 = 0.3  # the centre of the nu features (t = nu - NU0)
SCALE = ("1", "nu", "nu^2")
FEATURES = {
    3: SCALE + ("log_length", "boundary", "log_cells", "dihedral", "log_quality"),
    2: SCALE + ("log_length", "boundary", "dihedral", "log_quality"),
}
COEFFICIENTS = Path(__file__).with_name("learned_rule.json")
SIMPLEX = {2: "triangle", 3: "tetra"}
N_REG = 2 * np.pi / np.arccos(1 / 3)  # regular tetrahedra sharing one edge
COS_REG = {3: 1 / 3, 2: 0.5}  # dihedral of a regular tetrahedron, angle of an equilateral triangle
QUALITY_FLOOR = 1e-3


def _edge_keys(springs: np.ndarray, n: int):
    """Sorted keys of the springs' node pairs and the order that sorts them."""
    key = np.minimum(springs[:, 0], springs[:, 1]).astype(np.int64) * n + np.maximum(
        springs[:, 0], springs[:, 1]
    )
    order = np.argsort(key)
    return key[order], order


def _lookup(keys, order, n, a, b) -> np.ndarray:
    """Spring ids of node pairs (a, b), -1 where none."""
    k = np.minimum(a, b).astype(np.int64) * n + np.maximum(a, b)
    pos = np.clip(np.searchsorted(keys, k), 0, len(keys) - 1)
    return np.where(keys[pos] == k, order[pos], -1)


def _boundary_facets(c: np.ndarray) -> np.ndarray:
    """Facets (m, dim) of simplices c (cells, dim + 1) that belong to exactly one cell."""
    d1 = c.shape[1]
    faces = np.sort(np.concatenate([np.delete(c, i, axis=1) for i in range(d1)]), axis=1)
    uniq, cnt = np.unique(faces, axis=0, return_counts=True)
    return uniq[cnt == 1]


def _cos_at(p: np.ndarray, i: int, j: int, others) -> np.ndarray:
    """Per cell (p: (m, dim+1, dim) vertices), cos of the dihedral angle at edge ij (3-D,
    others = the two other vertices) or of the angle opposite ij (2-D, others = one)."""
    if len(others) == 1:
        a, b = p[:, i] - p[:, others[0]], p[:, j] - p[:, others[0]]
    else:
        e = p[:, j] - p[:, i]
        e = e / np.linalg.norm(e, axis=1, keepdims=True)
        a, b = p[:, others[0]] - p[:, i], p[:, others[1]] - p[:, i]
        a = a - np.einsum("md,md->m", a, e)[:, None] * e
        b = b - np.einsum("md,md->m", b, e)[:, None] * e
    return np.einsum("md,md->m", a, b) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))


def geometry(points, springs, cells) -> np.ndarray:
    """The geometric features (e, len(FEATURES[dim]) - 3), in FEATURES order after the
    scale; zeros unless the cells are all simplices of the points' dimension."""
    points, springs = np.asarray(points, float), np.asarray(springs, int)
    n, dim = points.shape
    e = len(springs)
    names = FEATURES[dim][len(SCALE) :]
    out = np.zeros((e, len(names)))
    ctype = SIMPLEX[dim]
    if set(cells) != {ctype} or e == 0:
        return out
    c = np.asarray(cells[ctype], int)
    L = np.linalg.norm(points[springs[:, 1]] - points[springs[:, 0]], axis=1)
    deg = np.bincount(springs.ravel(), minlength=n)
    node_mean = np.bincount(springs.ravel(), np.repeat(L, 2), minlength=n) / np.maximum(deg, 1)
    col = dict(zip(names, range(len(names))))
    out[:, col["log_length"]] = np.log(
        L / (0.5 * (node_mean[springs[:, 0]] + node_mean[springs[:, 1]]))
    )
    keys, order = _edge_keys(springs, n)
    facets = _boundary_facets(c)
    on = np.zeros(e, bool)
    for i in range(dim):
        for j in range(i + 1, dim):
            s = _lookup(keys, order, n, facets[:, i], facets[:, j])
            on[s[s >= 0]] = True
    out[:, col["boundary"]] = on
    count, cos_sum, q_sum = np.zeros(e), np.zeros(e), np.zeros(e)
    q = simplex_quality(points, c)
    p = points[c]
    for i, j in element_pairs(ctype):
        s = _lookup(keys, order, n, c[:, i], c[:, j])
        ok = s >= 0
        others = [v for v in range(dim + 1) if v not in (i, j)]
        np.add.at(count, s[ok], 1.0)
        np.add.at(cos_sum, s[ok], _cos_at(p[ok], i, j, others))
        np.add.at(q_sum, s[ok], q[ok])
    has = count > 0
    cnt = np.maximum(count, 1)
    if "log_cells" in col:
        out[has, col["log_cells"]] = np.log(count[has] / N_REG)
    out[has, col["dihedral"]] = cos_sum[has] / cnt[has] - COS_REG[dim]
    out[has, col["log_quality"]] = np.log(np.maximum(q_sum[has] / cnt[has], QUALITY_FLOOR))
    return out


def design(geom: np.ndarray, nu: float, dim: int) -> np.ndarray:
    """The full feature matrix (e, len(FEATURES[dim])): the scale columns for ``nu``, then
    the geometric features ``geom`` (from :func:`geometry`)."""
    t = float(nu) - NU0
    return np.hstack([np.tile([1.0, t, t * t], (len(geom), 1)), geom])


def correction(X: np.ndarray, c) -> np.ndarray:
    """exp(X c) (e,): the factor on van Gelder's constants (exponent clipped to +-30)."""
    return np.exp(np.clip(X @ np.asarray(c, float), -30.0, 30.0))


@functools.lru_cache(maxsize=4)
def _read(path: str, stamp: float) -> dict:
    return json.loads(Path(path).read_text())


def coefficients(dim: int, path: Path | None = None) -> np.ndarray:
    """The fitted c of ``dim`` from the coefficient file (default: the shipped
    learned_rule.json), checked against this module's feature names."""
    path = Path(path or COEFFICIENTS)
    try:
        data = _read(str(path), path.stat().st_mtime)
    except (OSError, ValueError) as exc:
        raise ModelError(
            f"cannot read the learned rule's coefficients {path} ({exc})",
            field="model.stiffness",
            fix="reinstall springbench, or refit them with 'springbench rules fit'",
        ) from None
    entry = data.get("dims", {}).get(str(dim))
    if entry is None:
        raise ModelError(
            f"the learned rule has no {dim}-D coefficients in {path}",
            field="model.stiffness",
            fix=f"fit them on {dim}-D meshes with 'springbench rules fit', or use 'vangelder'",
        )
    if tuple(entry.get("features", ())) != FEATURES[dim]:
        raise ModelError(
            f"the learned rule's {dim}-D features in {path} are not this version's "
            f"({', '.join(FEATURES[dim])})",
            field="model.stiffness",
            fix="refit them with 'springbench rules fit'",
        )
    return np.asarray(entry["coefficients"], float)


def learned(points, springs, cells, material, base, coef=None) -> np.ndarray:
    """k (e,) by the learned rule (module docstring): ``base`` is van Gelder's k of the same
    springs; ``coef`` overrides the shipped c."""
    points = np.asarray(points, float)
    dim = points.shape[1]
    if not cells:
        raise ModelError(
            "the learned rule needs cells (a triangulation, a grid or a mesh)",
            field="model.stiffness",
        )
    c = coefficients(dim) if coef is None else np.asarray(coef, float)
    X = design(geometry(points, springs, cells), material.nu, dim)
    return np.asarray(base, float) * correction(X, c)
