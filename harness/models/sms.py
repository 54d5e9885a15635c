"""Spring/mass systems (Deussen, Kobbelt & Tuecke 1995): the network and its builders.

``build_network(case, spec, seed)`` follows the paper's three steps: place the points
(grid / random / Lloyd / a mesh's nodes), compute the masses, connect them (grid
structure / Delaunay / mesh edges) and give the springs initial constants by a named
rule. ``spec`` is the case's ``[model]`` table (kind = "sms", keys in MODEL_SPEC).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Mapping

import numpy as np

from harness.case.parts import classify_nodes
from harness.case.schema import check
from harness.case.sections import SMS as MODEL_SPEC  # the [model] keys of kind = "sms"
from harness.errors import ModelError, SpringbenchError
from harness.io.meshfile import read_mesh
from harness.models import topology
from harness.models.springs import incidence, stiffness_matrix
from harness.models.stiffness_rules import spring_constants


@dataclass(frozen=True, eq=False)
class SpringNetwork:
    """points (n, dim) rest positions; springs (e, 2) node pairs; k (e,) linear spring
    constants; masses (n,); classes (n,) G weight classes 0 inner / 1 border / 2 corner;
    groups (e,) group id per spring with ``group_names``; cells: the cells the springs
    came from (for stiffness rules); info: how it was built (rules, seed, residuals)."""

    points: np.ndarray
    springs: np.ndarray
    k: np.ndarray
    masses: np.ndarray
    classes: np.ndarray
    groups: np.ndarray
    group_names: tuple[str, ...] = ("all",)
    cells: Mapping[str, np.ndarray] = field(default_factory=dict)
    info: Mapping[str, object] = field(default_factory=dict)

    @property
    def dim(self) -> int:
        return self.points.shape[1]

    @property
    def n_nodes(self) -> int:
        return len(self.points)

    @property
    def n_springs(self) -> int:
        return len(self.springs)

    @property
    def rest_lengths(self) -> np.ndarray:
        return np.linalg.norm(
            self.points[self.springs[:, 1]] - self.points[self.springs[:, 0]], axis=1
        )

    def with_k(self, k, **info) -> "SpringNetwork":
        """The same network with other spring constants."""
        k = np.asarray(k, float)
        if k.shape != self.k.shape:
            raise ValueError(f"expected {self.k.shape} spring constants, got {k.shape}")
        return dataclasses.replace(self, k=k, info=MappingProxyType({**self.info, **info}))

    def incidence(self):
        return incidence(self.points, self.springs)

    def stiffness_matrix(self):
        return stiffness_matrix(self.incidence(), self.k)


def make_network(
    points,
    springs,
    k=None,
    masses=None,
    classes=None,
    groups=None,
    group_names=None,
    cells=None,
    info=None,
    bbox=None,
) -> SpringNetwork:
    """A network from plain arrays; missing classes come from the bounding box
    (``harness.case.parts.classify_nodes``), missing masses are 1, groups one per network."""
    points = np.asarray(points, float)
    springs = np.asarray(springs, int).reshape(-1, 2)
    n, e = len(points), len(springs)
    if e and (springs.min() < 0 or springs.max() >= n):
        raise ModelError(f"spring node index out of range 0..{n - 1}", field="springs")
    if np.any(springs[:, 0] == springs[:, 1]):
        raise ModelError("a spring connects a node to itself", field="springs")
    L = np.linalg.norm(points[springs[:, 1]] - points[springs[:, 0]], axis=1)
    if np.any(L <= 0):
        raise ModelError(
            f"springs {np.flatnonzero(L <= 0)[:5].tolist()} have zero rest length",
            field="springs",
            fix="merge coincident nodes",
        )
    if classes is None:
        classes = classify_nodes(points, bbox or (points.min(0), points.max(0)))
    return SpringNetwork(
        points,
        springs,
        np.ones(e) if k is None else np.asarray(k, float),
        np.ones(n) if masses is None else np.asarray(masses, float),
        np.asarray(classes, int),
        np.zeros(e, int) if groups is None else np.asarray(groups, int),
        tuple(group_names or ("all",)),
        MappingProxyType(dict(cells or {})),
        MappingProxyType(dict(info or {})),
    )


def _spec(spec) -> dict:
    spec = {
        k: list(v) if isinstance(v, tuple) else v
        for k, v in dict(spec or {}).items()
        if k != "kind" and v is not None
    }
    return check(spec, MODEL_SPEC, "<model>", "model.")


def node_classes(points: np.ndarray, body) -> np.ndarray:
    """0 inner, 1 border, 2 corner: corners are the body's vertices (rectangle/box/polygon)."""
    if body.kind == "mesh":
        return classify_nodes(points, body.bbox(), boundary=_mesh_boundary_nodes(body, len(points)))
    cls = np.where(body.on_boundary(points), 1, 0)
    c = body.corners
    corner = np.any(np.all(np.abs(points[:, None, :] - c[None]) <= body.tol, axis=2), axis=1)
    cls[corner] = 2
    return cls


def _mesh_boundary_nodes(body, n) -> np.ndarray:
    """Nodes on faces (3-D) / edges (2-D) that belong to exactly one cell."""
    faces = {
        "triangle": [(0, 1), (1, 2), (2, 0)],
        "quad": [(0, 1), (1, 2), (2, 3), (3, 0)],
        "tetra": [(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)],
        "hexahedron": [
            (0, 1, 2, 3),
            (4, 5, 6, 7),
            (0, 1, 5, 4),
            (1, 2, 6, 5),
            (2, 3, 7, 6),
            (3, 0, 4, 7),
        ],
    }
    allf = []
    for ctype, c in body.mesh_cells.items():
        for f in faces[ctype]:
            allf.append(np.sort(c[:, list(f)], axis=1))
    width = max(a.shape[1] for a in allf)
    allf = np.concatenate(
        [np.pad(a, ((0, 0), (0, width - a.shape[1])), constant_values=-1) for a in allf]
    )
    uniq, cnt = np.unique(allf, axis=0, return_counts=True)
    out = np.zeros(n, bool)
    b = uniq[cnt == 1].ravel()
    out[b[b >= 0]] = True
    return out


def place_points(case, spec: dict, seed: int, body=None):
    """Points for the model, the Lloyd history (or the cells of a [model] mesh, or None)
    and the body geometry."""
    from harness.geometry import body_geometry, grid_points, lloyd, random_points

    body = body or body_geometry(case)
    p = spec["placement"]
    if p == "grid":
        grid = spec["grid"]
        if not (
            isinstance(grid, (list, tuple))
            and len(grid) == case.dim
            and all(isinstance(g, int) for g in grid)
        ):
            raise ModelError(
                f"grid must list {case.dim} integers (nodes per axis)",
                field="model.grid",
                fix="e.g. grid = [5, 5]",
            )
        if not body.is_box:
            raise ModelError(
                "grid placement needs a rectangle or a box",
                field="model.placement",
                fix="use placement = 'random' or 'lloyd' for polygons",
            )
        return grid_points(body.lo, body.hi, grid), None, body
    if p in ("random", "lloyd"):
        if spec["n_points"] is None:
            raise ModelError(
                f"placement = '{p}' needs n_points",
                field="model.n_points",
                fix="e.g. n_points = 30",
            )
        pts = random_points(body, spec["n_points"], seed, spec["n_boundary"])
        if p == "lloyd" and spec["lloyd_iterations"] > 0:
            res = lloyd(body, pts, spec["lloyd_iterations"], seed=seed)
            return res.points, res, body
        return pts, None, body
    if spec.get("mesh"):
        path = (case.path.parent if case.path is not None else Path(".")) / spec["mesh"]
        m = read_mesh(path, spec.get("mesh_format"))
        if m.dim != case.dim:
            raise ModelError(
                f"the mesh is {m.dim}-D but dim = {case.dim}", file=str(path), field="model.mesh"
            )
        return m.points, _MeshCells(m.cells), body
    if body.kind != "mesh":
        raise ModelError(
            "placement = 'mesh' needs body.shape = 'mesh' or a model.mesh file",
            field="model.placement",
            fix="add mesh = 'file.vtu' to [model]",
        )
    return body.mesh_points, None, body


class _MeshCells:
    """Cells of a [model] mesh handed from placement to topology."""

    def __init__(self, cells):
        self.cells = cells


def connect(case, spec: dict, points: np.ndarray, body, extra=None):
    p = spec["placement"]
    if p == "grid":
        return topology.grid_structure(
            spec["grid"],
            spec["structure"] or ("structure1" if case.dim == 2 else "edges+face+body"),
        )
    if spec["structure"] not in (None, "delaunay", "mesh"):
        raise ModelError(
            f"structure '{spec['structure']}' is for grids",
            field="model.structure",
            fix="leave it out (Delaunay / mesh edges are used)",
        )
    if p == "mesh":
        cells = extra.cells if isinstance(extra, _MeshCells) else body.mesh_cells
        return topology.mesh_edges(cells, len(points))
    return topology.delaunay(points, body, spec["min_quality"])


def build_network(case, spec=None, seed: int = 0, stiffness: str | None = None) -> SpringNetwork:
    """The SMS a case's [model] table describes, with constants by ``stiffness`` (default:
    the first rule listed). ``seed`` is added to the table's seed. Errors name the case file."""
    try:
        return _build(case, spec, seed, stiffness)
    except SpringbenchError as exc:
        if exc.file is None or exc.file == "<model>":
            exc.file = str(case.path) if case.path is not None else exc.file
            exc.args = (str(exc),)
        raise


def _build(case, spec, seed, stiffness) -> SpringNetwork:
    from harness.models.masses import compute_masses

    spec = _spec(spec if spec is not None else case.section("model"))
    s = int(spec["seed"]) + int(seed)
    points, hist, body = place_points(case, spec, s)
    top = connect(case, spec, points, body, hist)
    if isinstance(hist, _MeshCells):
        hist = None
    used = np.unique(top.springs)
    if len(used) < len(points):
        lonely = np.setdiff1d(np.arange(len(points)), used)
        raise ModelError(
            f"nodes {lonely[:8].tolist()} have no spring",
            field="model",
            fix="lower model.min_quality or use another placement",
        )
    mres = compute_masses(spec["masses"], points, body, case.material, seed=s)
    rule = stiffness or spec["stiffness"][0]
    k = spring_constants(rule, points, top.springs, top.cells, case.material)
    info = {
        "placement": spec["placement"],
        "structure": spec["structure"],
        "seed": s,
        "stiffness": rule,
        "masses": spec["masses"],
        "mass_residual": mres.residual,
        "negative_masses": mres.n_negative,
    }
    if hist is not None:
        info["lloyd_std_distance"] = hist.std_distance
        info["lloyd_std_size"] = hist.std_size
    return SpringNetwork(
        points,
        top.springs,
        k,
        mres.masses,
        node_classes(points, body),
        top.groups,
        top.group_names,
        top.cells,
        MappingProxyType(info),
    )


def model_spec(case) -> dict:
    """The validated [model] table of a case (defaults filled in)."""
    return _spec(case.section("model"))
