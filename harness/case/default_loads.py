"""Held-out structural loads for any mesh (what ``calibrate`` scores a fit on without
fitting it): the body is clamped at the low end of its longest axis and loaded across
it, the way a bar, a beam or an organ held at one end is.

- ``sag``: a uniform body force (gravity's form, rho g) along the body's thinnest other
  axis (``across``), the clamp holding;
- ``tip``: a traction along ``across`` on the high end's face;
- ``tip2`` (3-D): a traction along the third axis on the same face;
- ``torsion`` (3-D): the twist t = w e_axis x (x - c) on the same face (c its area
  centroid: a torque, no resultant);
- ``bridge``: the sag's body force with both ends clamped;
- training states (fitted, never held out): ``train-tip``, ``train-tip2`` and
  ``train-torsion``, the tip loads and the twist with the ends swapped (the high end
  clamped, the low end loaded); and per other axis b with faces at its ends (``sides``)
  ``train-<b>-<c>``: the low end face along b clamped, the high one sheared along c (each
  axis but b; tau = 2 G eps), so the clamps a fit is validated on are not all at one
  place. The side faces are end faces along b in a band of SIDE_BAND of the extent.

The ends are end faces (harness.io.end_faces): the boundary facets within a band of 5 %
of the length at each end of the axis whose outward normals point along it (cos >= 0.5;
a pointed end, which has no such face: cos >= 0), the band widened (x 1.5 at a time)
until the clamp holds three non-collinear nodes (two in 2-D) and the tip a facet. Either may
instead be a named group of the mesh (``calibrate
--clamp`` / ``--load-region``). The FEM and the springs are clamped and loaded on the same
facets (harness.case.facet_loads).

Magnitudes (:meth:`EndLoads.magnitudes`) give a peak strain of about ``peak_strain``
(default 1e-3) by beam theory on the body's own section: bending strain M c / (E I) at the
clamp (tip: M = P L, sag: w L^2 / 2, bridge: w L^2 / 12) and the shear strain of the twist
w r / (2 G), so the linear answer is the physical one.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

from harness.case.moments import EXPONENTS, mesh_moments
from harness.errors import SpringbenchError
from harness.io.end_faces import BAND, COS, end_facets, outward_normals
from harness.io.meshfile import boundary_facets

PEAK_STRAIN = 1e-3
SIDE_BAND = (
    0.25  # of the side faces, a fraction of the body's extent across (a curved side: a wide cap)
)


@dataclass(frozen=True)
class Section:
    """What beam theory needs of the body along its axis: length L, mean section area
    A = V / L, second moments I (dim,) of the section about the centroidal axis
    (I[b] = int (x_b - xbar_b)^2 dV / L), extreme-fibre distances c (dim,), the tip face's
    area and its radius about the axis through its area centroid (its farthest node)."""

    L: float
    A: float
    I: tuple[float, ...]
    c: tuple[float, ...]
    tip_area: float
    tip_radius: float


@dataclass(frozen=True)
class EndLoads:
    axis: int  # the longest axis: clamp at its low end, tip at its high end
    across: int  # the sag's and tip's direction (the thinnest other axis)
    clamp: str | None  # a mesh group's name, or None: the low end face
    tip: str | None  # a mesh group's name, or None: the high end face
    band: float  # of the end faces, a fraction of the length
    section: Section
    dim: int = 3
    clamp_info: str = ""  # where the clamp is: centroid, normal, node count
    cos: float = COS  # of the end faces: outward normals n . e >= cos
    sides: tuple = ()  # (axis b, band, cos) of the side clamps' end faces

    @property
    def names(self) -> tuple[str, ...]:
        return (
            ("sag", "tip", "tip2", "torsion", "bridge")
            if self.dim == 3
            else ("sag", "tip", "bridge")
        )

    @property
    def training(self) -> tuple[str, ...]:
        """Clamped training states (the family 'clamped'): the tip loads and the twist with
        the ends swapped (the high end held, the low end loaded), so a fit sees how a clamp
        behaves without seeing a held-out load."""
        ends = ("train-tip", "train-tip2", "train-torsion") if self.dim == 3 else ("train-tip",)
        return ends + tuple(name for name, *_ in self._side_states())

    def _side_states(self):
        """(name, side axis b, traction axis c) of the side states."""
        return [
            (f"train-{'xyz'[b]}-{'xyz'[c]}", b, c)
            for b, *_ in self.sides
            for c in range(self.dim)
            if c != b
        ]

    @property
    def second(self) -> int:
        """tip2's direction: the axis neither ``axis`` nor ``across``."""
        return 3 - self.axis - self.across

    @property
    def radius(self) -> float:
        return self.section.tip_radius

    def describe(self) -> str:
        a, b = "xyz"[self.axis], "xyz"[self.across]
        where = lambda p, end: f"group '{p}'" if isinstance(p, str) else f"the {a}{end} end face"  # noqa: E731
        extra = (
            f", 'tip2' (along -{'xyz'[self.second]}), 'torsion' (a twist about {a})"
            if self.dim == 3
            else ""
        )
        band = (
            ""
            if isinstance(self.clamp, str) and isinstance(self.tip, str)
            else f" (facets within {self.band:.3g} of the length of each end, "
            f"normals n . e_{a} >= {self.cos:g})"
        )
        return (
            f"held-out loads: 'sag' (body force along -{b}), 'tip' (traction along -{b}){extra} on "
            f"{where(self.tip, '1')}, 'bridge' (the sag with both ends clamped); "
            f"{where(self.clamp, '0')} "
            f"clamped{band}{self.clamp_info}"
        )

    def magnitudes(
        self, E: float, nu: float, density: float, peak_strain: float = PEAK_STRAIN
    ) -> dict:
        """{load: magnitude} for a peak strain of about ``peak_strain`` (module doc): the
        tip tractions in Pa, the body force's acceleration in m/s^2, the twist w in Pa/m."""
        s, eps, b, t = self.section, float(peak_strain), self.across, self.second
        bend = lambda i: eps * E * s.I[i] / s.c[i]  # noqa: E731  the moment M at the peak strain
        out = {
            "sag": 2 * bend(b) / (density * s.A * s.L**2),
            "tip": bend(b) / (s.tip_area * s.L),
            "bridge": 12 * bend(b) / (density * s.A * s.L**2),
        }
        if self.dim == 3:
            out["tip2"] = bend(t) / (s.tip_area * s.L)
            out["torsion"] = 2 * eps * E / (2 * (1 + nu)) / s.tip_radius
        out["side"] = 2 * eps * E / (2 * (1 + nu))  # a shear traction tau = 2 G eps: eps_bc ~ eps
        return out

    def toml(self, magnitudes: dict) -> tuple[str, str]:
        """([body.parts] lines, [[loads.case]] tables) of the loads with these magnitudes."""
        dim, m = self.dim, magnitudes

        def vec(axis, value):
            v = [0.0] * dim
            v[axis] = float(value)
            return v

        part = lambda p, side: (
            f"{{ group = {json.dumps(p)} }}"
            if isinstance(p, str)
            # noqa: E731
            else f'{{ end = "{"xyz"[self.axis]}{side}", band = {float(self.band)!r}, '
            f"cos = {float(self.cos)!r} }}"
        )
        hold = lambda name: f'[[loads.case.constraint]]\npart = "{name}"\ncomponents = "all"\n'  # noqa: E731
        load = lambda name: f'[[loads.case]]\nname = "{name}"\n'  # noqa: E731
        trac = lambda **kv: (
            '[[loads.case.traction]]\npart = "tip"\n'
            + "".join(  # noqa: E731
                f"{k} = {v}\n" for k, v in kv.items()
            )
        )
        cases = (
            load("sag")
            + f"gravity = {vec(self.across, -m['sag'])}\n"
            + hold("clamp")
            + load("tip")
            + hold("clamp")
            + trac(vector=vec(self.across, -m["tip"]))
        )
        if dim == 3:
            cases += load("tip2") + hold("clamp") + trac(vector=vec(self.second, -m["tip2"]))
            cases += load("torsion") + hold("clamp") + trac(twist=vec(self.axis, m["torsion"]))
        cases += (
            load("bridge")
            + f"gravity = {vec(self.across, -m['bridge'])}\n"
            + hold("clamp")
            + hold("tip")
        )
        back = lambda **kv: trac(**kv).replace('part = "tip"', 'part = "clamp"')  # noqa: E731
        cases += load("train-tip") + hold("tip") + back(vector=vec(self.across, m["tip"]))
        if dim == 3:
            cases += load("train-tip2") + hold("tip") + back(vector=vec(self.second, m["tip2"]))
            cases += load("train-torsion") + hold("tip") + back(twist=vec(self.axis, -m["torsion"]))
        parts = f"clamp = {part(self.clamp, 0)}\ntip = {part(self.tip, 1)}\n"
        for b, band, cos in self.sides:
            for side in (0, 1):
                parts += (
                    f'side-{"xyz"[b]}{side} = {{ end = "{"xyz"[b]}{side}", band = {float(band)!r}, '
                    f"cos = {float(cos)!r} }}\n"
                )
        for name, b, c in self._side_states():
            cases += (
                load(name)
                + hold(f"side-{'xyz'[b]}0")
                + trac(vector=vec(c, m["side"])).replace(
                    'part = "tip"', f'part = "side-{"xyz"[b]}1"'
                )
            )
        return parts, cases


def end_loads(
    points: np.ndarray, cells, clamp: str | None = None, tip: str | None = None, groups=None
) -> EndLoads:
    """The end loads of a mesh (points (n, dim), meshio-style cells): its end faces along
    the longest axis, or the mesh groups named ``clamp`` / ``tip`` (``groups``:
    harness.io.meshfile.Mesh.groups), and the side states' faces (the end faces of the
    other axes that hold, module doc)."""
    points = np.asarray(points, float)
    dim = points.shape[1]
    lo, hi = points.min(axis=0), points.max(axis=0)
    size = hi - lo
    axis = int(np.argmax(size))
    across = min((a for a in range(dim) if a != axis), key=lambda a: size[a])
    facets, inside = boundary_facets(cells, points)

    def group_facets(name):
        g = groups[name]
        held = np.zeros(len(points), bool)
        held[
            np.unique(np.concatenate([c.ravel() for c in g.cells.values()] + [g.nodes]).astype(int))
        ] = True
        return [f[held[f].all(axis=1)] for f in facets]

    def holds(fac):
        nodes = np.unique(np.concatenate([f.ravel() for f in fac]))
        c = points[nodes] - points[nodes].mean(axis=0) if len(nodes) else np.zeros((0, dim))
        return len(nodes) >= dim and np.linalg.matrix_rank(c, tol=1e-9 * size.max()) >= dim - 1

    if clamp is not None and not holds(group_facets(clamp)):
        raise SpringbenchError(
            f"group '{clamp}' cannot clamp the body (a face with {dim} nodes not on one line "
            f"needed)",
            field="--clamp",
            fix="name a face group of the mesh",
        )
    for band, cos in _bands(BAND):
        cf = (
            group_facets(clamp)
            if clamp is not None
            else end_facets(points, facets, inside, axis, 0, band, cos)
        )
        tf = (
            group_facets(tip)
            if tip is not None
            else end_facets(points, facets, inside, axis, 1, band, cos)
        )
        if holds(cf) and any(len(f) for f in tf):
            return EndLoads(
                axis,
                across,
                clamp,
                tip,
                band,
                _section(points, cells, axis, tf),
                dim,
                _where(points, facets, inside, cf),
                cos,
                _sides(points, facets, inside, axis, holds),
            )
    raise SpringbenchError(
        "no end of the mesh's longest axis can be clamped (no face there whose normals point "
        "along the axis)",
        field="mesh",
        fix="name a face group with --clamp, or --heldout none",
    )


def _bands(start: float):
    """(band, cos) to try, narrowest first: the band from ``start`` x 1.5 at a time up to
    half the extent, each with the faces' cos and then 0 (a pointed end has no face: then
    the facets that face that way at all)."""
    band = start
    while band <= 0.5:
        yield band, COS
        yield band, 0.0
        band *= 1.5


def _sides(points, facets, inside, axis: int, holds) -> tuple:
    """((b, band, cos), ...) per axis b but ``axis``: the first :func:`_bands` from
    SIDE_BAND in which b's low end face holds and its high one has a facet (none: no entry)."""

    def first(b):
        for band, cos in _bands(SIDE_BAND):
            lo, hi = (end_facets(points, facets, inside, b, side, band, cos) for side in (0, 1))
            if holds(lo) and any(len(f) for f in hi):
                return b, band, cos
        return None

    return tuple(
        f for f in (first(b) for b in range(points.shape[1]) if b != axis) if f is not None
    )


def _where(points, facets, inside, fac) -> str:
    """': centroid (..), normal (..), N nodes' of the clamp's facets."""
    area, centre, normal = 0.0, 0.0, 0.0
    for f, cell in zip(facets, inside):
        keep = _rows(f, fac)
        if not keep.any():
            continue
        a = _areas(points, f[keep])
        c, n = outward_normals(points, f[keep], cell[keep])
        area, centre, normal = area + a.sum(), centre + a @ c, normal + a @ n
    nodes = len(np.unique(np.concatenate([f.ravel() for f in fac])))
    fmt = lambda v: ", ".join(f"{x:.3g}" for x in v)  # noqa: E731
    n = normal / max(np.linalg.norm(normal), 1e-300)
    return f": centroid ({fmt(centre / area)}), normal ({fmt(n)}), {nodes} nodes"


def _rows(f: np.ndarray, chosen: list[np.ndarray]) -> np.ndarray:
    """Mask of the rows of f that are among the chosen facets of the same size."""
    same = [c for c in chosen if c.shape[1] == f.shape[1] and len(c)]
    if not same:
        return np.zeros(len(f), bool)
    key = lambda a: [tuple(r) for r in np.sort(a, axis=1)]  # noqa: E731
    want = set(key(np.concatenate(same)))
    return np.array([r in want for r in key(f)], bool)


def _areas(points: np.ndarray, fac: np.ndarray) -> np.ndarray:
    """Sizes (m,) of facets (m, k): lengths in 2-D, polygon areas in 3-D."""
    x = points[fac]
    if x.shape[2] == 2:
        return np.linalg.norm(x[:, 1] - x[:, 0], axis=1)
    a = np.zeros((len(x), 3))
    for i in range(1, x.shape[1] - 1):
        a += np.cross(x[:, i] - x[:, 0], x[:, i + 1] - x[:, 0]) / 2
    return np.linalg.norm(a, axis=1)


def _section(points, cells, axis: int, tip_facets) -> Section:
    """The body's Section along ``axis`` (its exact volume moments, harness.case.moments;
    the tip face from ``tip_facets``)."""
    dim = points.shape[1]
    m = mesh_moments(points, cells)  # int x^e dV for the exponents e of EXPONENTS
    V, mean = m[0], m[1 : 1 + dim] / m[0]
    square = [
        m[EXPONENTS[dim].index(tuple(2 * int(a == i) for a in range(dim)))] for i in range(dim)
    ]
    L = float(np.ptp(points[:, axis]))
    I = (np.array(square) / V - mean**2) * V / L
    c = np.abs(points - mean).max(axis=0)
    tip = [f for f in tip_facets if len(f)]
    areas = [_areas(points, f) for f in tip]
    tip_area = float(sum(a.sum() for a in areas))
    centroid = sum(a @ points[f].mean(axis=1) for a, f in zip(areas, tip)) / tip_area
    nodes = np.unique(np.concatenate([f.ravel() for f in tip]))
    r = points[nodes] - centroid
    r[:, axis] = 0.0
    return Section(
        L,
        float(V / L),
        tuple(map(float, I)),
        tuple(map(float, c)),
        tip_area,
        float(np.linalg.norm(r, axis=1).max()) if dim == 3 else math.nan,
    )
