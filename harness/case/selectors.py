"""Regions a user picks by a spelling: a clamp or load region (``calibrate --clamp`` /
``--load-region``, ``pack``, ``[body.parts] name = { facets = "..." }``, an engines case's
``[model] clamp``) is a mesh group's name or one of

- ``nodes:FILE``: node ids, 0-based in the order the mesh file lists its nodes, one a line
  or comma-separated (a first line of words is a CSV header; ``#`` starts a comment);
- ``box:XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX`` (2-D ``box:XMIN,YMIN,XMAX,YMAX``);
- ``sphere:X,Y,Z,R`` (2-D the circle ``sphere:X,Y,R``);

each the boundary facets all of whose nodes it holds (a node within RTOL of the body's
diagonal outside a box or a sphere is inside). The kinds are the node tests of
``harness.registry.REGION_SELECTORS``. Like a group (harness.io.mesh_groups) the region is a
set of the user's mesh's facets whose predicate holds the points on them, so the FEM on every
refinement, the spring networks on its nodes and every exported force see the same facets.
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from harness.case.regions import vector
from harness.io.end_faces import FACET_TYPE
from harness.io.mesh_groups import cell_simplices, on_simplices
from harness.io.meshfile import boundary_facets, mesh_surface
from harness.registry import REGION_SELECTORS

NUMBERED = ("box", "sphere")  # the kinds spelled by numbers
RTOL = 1e-8  # as harness.case.parts.RTOL: within this x the body's diagonal is inside


@dataclass(frozen=True)
class Selector:
    """A parsed spelling: its ``kind``, the box's corners (lo then hi) or the sphere's
    centre and radius (``numbers``), or the node file and its sorted ``ids``."""

    kind: str
    numbers: tuple[float, ...] = ()
    file: str | None = None
    ids: tuple[int, ...] = ()

    @property
    def text(self) -> str:
        """The spelling that parses back to this selector (numbers exact)."""
        if self.kind == "nodes":
            return f"nodes:{self.file}"
        return f"{self.kind}:" + ",".join(repr(float(x)) for x in self.numbers)

    def scaled(self, factor: float) -> Selector:
        """The selector with its lengths times ``factor`` (a mesh in mm read as m)."""
        return replace(self, numbers=tuple(float(x) * factor for x in self.numbers))

    def describe(self) -> str:
        """Where it selects, lengths in m: 'the facets in the box (0, 0, 0)..(1, 1, 1) m'."""
        v, n = vector, self.numbers
        if self.kind == "box":
            h = len(n) // 2
            return f"the facets in the box {v(n[:h])}..{v(n[h:])} m"
        if self.kind == "sphere":
            shape = "circle" if len(n) == 3 else "sphere"
            return f"the facets in the {shape} about {v(n[:-1])} m of radius {n[-1]:.3g} m"
        return f"the facets of the {len(self.ids)} nodes of {Path(self.file).name}"


def forms(kind: str) -> str:
    """The right spelling of ``kind`` (registry ``about``), for messages."""
    return REGION_SELECTORS.about[kind]


SPELLINGS = "a mesh group's name; " + "; ".join(forms(k) for k in REGION_SELECTORS)


def kind_of(text) -> str | None:
    """The selector kind ``text`` spells ('box' of 'box:...'), None for a group's name."""
    kind, sep, _ = str(text).partition(":")
    return kind if sep and kind in REGION_SELECTORS else None


def parse(text: str, bad, dim: int | None = None, base: Path | None = None) -> Selector | None:
    """The Selector ``text`` spells (None: a group's name). ``bad(message, fix)`` raises the
    caller's one-line error; ``dim`` None accepts a 2-D or 3-D count; a relative node file
    is found from ``base`` (default: the working folder)."""
    kind = kind_of(text)
    if kind is None:
        return None
    arg = str(text).partition(":")[2]
    fail = lambda why: bad(f"'{text}' {why}", forms(kind))  # noqa: E731
    if kind == "nodes":
        path = Path(arg).expanduser()
        path = path if path.is_absolute() else Path(base or ".") / path
        return Selector("nodes", file=str(path.resolve()), ids=read_ids(path, fail))
    numbers, why = read_numbers(kind, arg, dim)
    if why:
        fail(why)
    return Selector(kind, numbers)


def read_numbers(kind: str, arg: str, dim: int | None) -> tuple[tuple, str | None]:
    """(the numbers of a box's or a sphere's ``arg``, what is wrong with them or None)."""
    words = [w.strip() for w in arg.split(",")]
    if not all(re.fullmatch(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?", w) for w in words):
        return (), "is not a list of numbers"
    numbers = tuple(float(w) for w in words)
    counts = {"box": (4, 6), "sphere": (3, 4)}[kind]
    want = counts if dim is None else (counts[dim - 2],)
    h = len(numbers) // 2
    if len(numbers) not in want:
        space = f"{dim}-D" if dim else "2-D or 3-D"
        return (), f"has {len(numbers)} numbers, a {space} {kind} {' or '.join(map(str, want))}"
    if kind == "box" and any(lo > hi for lo, hi in zip(numbers[:h], numbers[h:])):
        return (), "has a minimum above its maximum (the first corner is the minimum)"
    if kind == "sphere" and not numbers[-1] > 0:
        return (), "has a radius that is not positive"
    return numbers, None


def spelling_problem(text) -> str | None:
    """What is wrong with a box's or a sphere's spelling before the mesh is read (a case
    file's check), or None (a group's name, a node file: checked on the mesh)."""
    kind = kind_of(text)
    why = read_numbers(kind, str(text).partition(":")[2], None)[1] if kind in NUMBERED else None
    return f"'{text}' {why} ({forms(kind)})" if why else None


def read_ids(path: Path, fail) -> tuple[int, ...]:
    """The sorted distinct node ids of a node file (module doc); ``fail(why)`` raises."""
    if not path.is_file():
        fail("names no such file")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        fail("is not a text file of node ids")
    lines = [ln.split("#")[0].strip() for ln in text.splitlines()]
    rows = [(i + 1, re.split(r"[,;\s]+", ln)) for i, ln in enumerate(lines) if ln]
    if rows and not any(re.fullmatch(r"[-+.\d]\S*", w) for w in rows[0][1]):
        rows = rows[1:]  # a CSV header: words only
    ids = []
    for line, words in rows:
        for w in filter(None, words):
            if not re.fullmatch(r"\d+", w):
                fail(f"line {line}: '{w}' is not a node id")
            ids.append(int(w))
    if not ids:
        fail("holds no node ids")
    return tuple(sorted(set(ids)))


def check_nodes(sel: Selector, n: int, bad) -> None:
    """``bad(message, fix)`` when a node file names an id the mesh of ``n`` nodes lacks."""
    if sel.kind == "nodes" and sel.ids[-1] >= n:
        bad(
            f"'{sel.text}': node id {sel.ids[-1]} is not a node of the mesh ({n} nodes)",
            f"{forms('nodes')}: 0..{n - 1}, in the file's order (gmsh tags from 1: tag - 1)",
        )


def box(sel: Selector, points: np.ndarray, tol: float) -> np.ndarray:
    """Mask of the nodes inside the box (within ``tol``)."""
    h = len(sel.numbers) // 2
    lo, hi = np.array(sel.numbers[:h]), np.array(sel.numbers[h:])
    return np.all((points >= lo - tol) & (points <= hi + tol), axis=1)


def sphere(sel: Selector, points: np.ndarray, tol: float) -> np.ndarray:
    """Mask of the nodes inside the sphere (circle in 2-D; within ``tol``)."""
    centre, r = np.array(sel.numbers[:-1]), sel.numbers[-1]
    return np.linalg.norm(points - centre, axis=1) <= r + tol


def nodes(sel: Selector, points: np.ndarray, tol: float) -> np.ndarray:
    """Mask of the nodes the file names (ids checked by :func:`check_nodes`)."""
    mask = np.zeros(len(points), bool)
    mask[list(sel.ids)] = True
    return mask


def facet_masks(sel: Selector, points: np.ndarray, facets) -> list[np.ndarray]:
    """One mask per facet array of ``facets``: the facets all of whose nodes the selector
    holds (harness.io.meshfile.boundary_facets of the mesh whose ``points`` these are)."""
    points = np.asarray(points, float)
    tol = RTOL * float(np.linalg.norm(np.ptp(points, axis=0)))
    inside = REGION_SELECTORS.load(sel.kind)(sel, points, tol)
    return [inside[np.asarray(f, int)].all(axis=1) for f in facets]


def require_facets(sel, masks, points: np.ndarray, bad, given: str = "", unit: str = "m") -> None:
    """``bad(message, fix)`` when the selector (spelled ``given`` by the user) holds no
    boundary facet (``points`` in ``unit``)."""
    if any(m.any() for m in masks):
        return
    lo, hi = np.min(points, axis=0), np.max(points, axis=0)
    bad(
        f"'{given or sel.text}' holds no boundary facet (all of a facet's nodes must be inside)",
        f"the body spans {vector(lo)}..{vector(hi)} {unit}; {forms(sel.kind)}",
    )


@dataclass(frozen=True)
class SelectorPart:
    """A ``[body.parts]`` entry ``{ facets = "box:..." }``: the selector on the body's file."""

    selector: Selector
    file: Path
    format: str | None = None


@functools.lru_cache(maxsize=8)
def _geometry(file: str, fmt: str | None, stamp: tuple, sel: Selector) -> dict:
    """{k: (m, k, dim) simplices} of the selected facets of the file (cached per version)."""
    points, facets, _ = mesh_surface(file, fmt)
    by_k: dict[int, list] = {}
    for fac, m in zip(facets, facet_masks(sel, points, facets)):
        for s in cell_simplices(FACET_TYPE[fac.shape[1]], fac[m], points):
            by_k.setdefault(s.shape[1], []).append(s)
    return {k: np.concatenate(v) for k, v in by_k.items()}


def selector_predicate(part: SelectorPart, tol: float):
    """Predicate (coordinates (dim, n) -> mask) of the points on the part's facets."""

    st = Path(part.file).stat()
    geometry = _geometry(str(part.file), part.format, (st.st_mtime_ns, st.st_size), part.selector)

    def on_facets(x):
        x = np.asarray(x, float).T
        mask = np.zeros(len(x), bool)
        for simplices in geometry.values():
            mask |= on_simplices(x, simplices, tol)
        return mask

    return on_facets


def case_part(value, mesh, body, base: Path, fail):
    """The part of ``[body.parts] name = { facets = value }`` on the read ``mesh`` of a mesh
    ``body``: a SelectorPart, or the name of a group of the mesh (str); ``fail(message,
    fix)`` raises the case's error naming the key."""
    if not isinstance(value, str) or not value:
        fail("expected a group's name or a selector", SPELLINGS)
    sel = parse(value, fail, mesh.dim, base)
    if sel is None:
        return value
    check_nodes(sel, len(mesh.points), fail)

    masks = facet_masks(sel, mesh.points, boundary_facets(mesh.cells))
    require_facets(sel, masks, mesh.points, fail, value)
    return SelectorPart(sel, body.file, body.format)
