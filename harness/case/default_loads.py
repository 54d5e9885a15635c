"""Held-out structural loads for any mesh (what ``calibrate`` scores a fit on without
fitting it): the body is clamped at the low end of its longest axis and loaded across
it, the way a bar, a beam or an organ held at one end is.

- ``sag``: a uniform body force (gravity's form, rho g) along the body's thinnest other
  axis (``across``), the clamp holding;
- ``tip``: a traction along ``across`` on the high end's face;
- ``tip2`` (3-D): a traction along the third axis on the same face;
- ``torsion`` (3-D): the twist t = w e_axis x (x - c) on the same face (c its area
  centroid: a torque, no resultant); on a region the user chose, about its mean outward
  normal n instead of e_axis (w its radius about n);
- ``bridge``: the sag's body force with both ends clamped;
- training states (fitted, never held out): ``train-tip``, ``train-tip2`` and
  ``train-torsion``, the tip loads and the twist with the ends swapped (the high end
  clamped, the low end loaded); and per other axis b with faces at its ends (``sides``)
  ``train-<b>-<c>``: the low end face along b clamped, the high one sheared along c (each
  axis but b; tau = 2 G eps), so the clamps a fit is validated on are not all at one
  place. The side faces are end faces along b, grown like the ends from SIDE_BAND;
- validation loads (never fitted, never held out: they decide whether a fit beats every
  rule, harness/stages/sms_select.py) on other regions than the held-out loads': per side
  axis b ``val-<b>-<c>``, the high side face along b held and a body force along each other
  axis c (a weight rho g h_b = tau over the held face). As the held-out loads clamp a face
  the training states only load (the low end), these clamp the face ``train-<b>-<c>``
  only loads: a fit that learned its training clamps is judged where it has never been
  held (bodies without side faces have none).

The ends are end faces (harness.io.end_faces) grown until they hold a meaningful part of
the body (harness.case.regions): the boundary facets within a band of the length at each end
of the axis whose outward normals point along it (cos >= 0.5; then cos >= 0, for a pointed
end, which has no such face), from 5 % of the length, the band widened x 1.5 at a time until
the region's area across the axis is at least SHARE (0.5) of the body's mean section V / L
and the clamp holds three non-collinear nodes (two in 2-D), the tip a facet. A flat end
holds its whole section at 5 %: a prismatic body's ends are its flat end faces. A rounded
end gets a cap, never a near-point clamp (a singular problem whose FEM does not converge).
The clamp and the tip grow each on its own; the side faces the same way from SIDE_BAND.
Either end may instead be a named group of the mesh or a node file, box or sphere
(``calibrate --clamp`` / ``--load-region``; harness.case.selectors), used as given; a
region that is nearly a point is warned about (:func:`near_point_warnings`). The FEM and
the springs are clamped and loaded on the same facets (harness.case.facet_loads).

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
from harness.case.regions import centroid_normal, grow, mean_normal, region, vector, warning
from harness.case.selectors import check_nodes, facet_masks, kind_of, parse, require_facets
from harness.errors import SpringbenchError
from harness.io.end_faces import BAND, COS, facet_geometry, facet_sizes
from harness.io.meshfile import boundary_facets

PEAK_STRAIN = 1e-3
SIDE_BAND = 0.25  # the side faces' first band, of the body's extent across (a curved side)


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


# each held-out load's end-swapped twin (EndLoads.twins): the state loading the other end alike
TWIN = {"sag": "train-tip", "tip": "train-tip", "bridge": "train-tip"}
TWIN.update({"tip2": "train-tip2", "torsion": "train-torsion"})


@dataclass(frozen=True)
class EndLoads:
    axis: int  # the longest axis: clamp at its low end, tip at its high end
    across: int  # the sag's and tip's direction (the thinnest other axis)
    clamp: str | None  # a mesh group's name, or None: the low end face
    tip: str | None  # a mesh group's name, or None: the high end face
    band: float  # of the clamp's end face (and the tip's unless tip_band), of the length
    section: Section
    dim: int = 3
    clamp_info: str = ""  # where the clamp is: centroid, normal, node count
    cos: float = COS  # of the clamp's end face: outward normals n . e >= cos
    sides: tuple = ()  # (axis b, band, cos) of the side clamps' end faces
    tip_band: float | None = None  # of the tip's end face (None: band)
    tip_cos: float | None = None  # of the tip's end face (None: cos)
    regions: tuple = ()  # (clamp, tip) Regions: what each holds (harness.case.regions)
    tip_twist: tuple | None = None  # the torsion's axis: the tip's mean normal (None: e_axis)
    clamp_twist: tuple | None = None  # train-torsion's: the clamp's mean normal (None: -e_axis)

    @property
    def tip_end(self) -> tuple[float, float]:
        """(band, cos) of the tip's end face."""
        return (
            self.band if self.tip_band is None else self.tip_band,
            self.cos if self.tip_cos is None else self.tip_cos,
        )

    @property
    def names(self) -> tuple[str, ...]:
        return (
            ("sag", "tip", "tip2", "torsion", "bridge")
            if self.dim == 3
            else ("sag", "tip", "bridge")
        )

    @property
    def swapped(self) -> tuple[str, ...]:
        """The tip loads and the twist with the ends swapped (the high end held, the low end
        loaded): the training states most like the held-out loads (:attr:`twins`)."""
        return ("train-tip", "train-tip2", "train-torsion") if self.dim == 3 else ("train-tip",)

    @property
    def twins(self) -> tuple[str, ...]:
        """Each held-out load's end-swapped twin, in :attr:`names`' order: the swapped
        state that bends the same way (the sag, the tip and the bridge: ``train-tip``) or
        twists. Calibrate ranks the rules by their mean ([loads] rank_by, a name listed
        three times counting three times), so the ranking weighs the bending across, the
        bending along the third axis and the twist as the held-out mean does."""
        return tuple(TWIN[n] for n in self.names)

    @property
    def training(self) -> tuple[str, ...]:
        """Clamped training states (the family 'clamped'): :attr:`swapped`, so a fit sees how
        a clamp behaves without seeing a held-out load, and the side states."""
        return self.swapped + tuple(name for name, *_ in self._side_states())

    def _side_states(self, prefix: str = "train"):
        """(name, side axis b, load axis c) of the side states (``prefix`` 'val': the
        validation loads')."""
        return [
            (f"{prefix}-{'xyz'[b]}-{'xyz'[c]}", b, c)
            for b, *_ in self.sides
            for c in range(self.dim)
            if c != b
        ]

    @property
    def validation(self) -> tuple[str, ...]:
        """The validation loads (module doc): a body force, a high side face held."""
        return tuple(name for name, *_ in self._side_states("val"))

    @property
    def second(self) -> int:
        """tip2's direction: the axis neither ``axis`` nor ``across``."""
        return 3 - self.axis - self.across

    @property
    def radius(self) -> float:
        return self.section.tip_radius

    def describe(self) -> str:
        """The held-out loads and where they act: each region's place, area (absolute and a
        share of the body's mean section) and node count (the clamp's after its normal)."""
        a, b = "xyz"[self.axis], "xyz"[self.across]
        extra = (
            f", 'tip2' (along -{'xyz'[self.second]}), 'torsion' ({self._twist_words()})"
            if self.dim == 3
            else ""
        )
        clamp, tip = self.regions or (None, None)
        names = {"0": clamp, "1": tip}

        def where(p, end):
            if names[end] is not None:
                return names[end].where
            return f"group '{p}'" if isinstance(p, str) else f"the {a}{end} end face"

        info = lambda r, n: f" ({r.describe(self.axis, self.dim, n)})" if r is not None else ""  # noqa: E731
        band = (
            ""
            if self.regions or (isinstance(self.clamp, str) and isinstance(self.tip, str))
            else f" (facets within {self.band:.3g} of the length of each end, "
            f"normals n . e_{a} >= {self.cos:g})"
        )
        return (
            f"held-out loads: 'sag' (body force along -{b}), 'tip' (traction along -{b}){extra} on "
            f"{where(self.tip, '1')}{info(tip, True)}, 'bridge' (the sag with both ends clamped); "
            f"{where(self.clamp, '0')} "
            f"clamped{info(clamp, False)}{band}{self.clamp_info}"
        )

    def _twist_words(self) -> str:
        """What the torsion turns about: the axis, or the load region's mean normal."""
        if self.tip_twist is not None:
            return f"a twist about the load region's mean normal {vector(self.tip_twist)}"
        every = ": the load region faces every way" if self.tip is not None else ""
        return f"a twist about {'xyz'[self.axis]}{every}"

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
        for side, *_ in self.sides:  # the weight over the side face: rho g h_b = tau
            out[f"val-{'xyz'[side]}"] = out["side"] / (density * 2 * s.c[side])
        return out

    def toml(self, magnitudes: dict) -> tuple[str, str]:
        """:meth:`tables` (no validation loads) as case-file text: ([body.parts] lines,
        [[loads.case]] tables), the form the generated suites (cases/*/_generate.py) write."""
        parts, cases = self.tables(magnitudes)
        inline = lambda d: "{ " + ", ".join(f"{k} = {json.dumps(v)}" for k, v in d.items()) + " }"  # noqa: E731
        text = "".join(f"{name} = {inline(p)}\n" for name, p in parts.items())
        out = ""
        for case in cases:
            out += f'[[loads.case]]\nname = "{case["name"]}"\n'
            if "gravity" in case:
                out += f"gravity = {case['gravity']}\n"
            for c in case["constraint"]:
                out += f'[[loads.case.constraint]]\npart = "{c["part"]}"\ncomponents = "all"\n'
            for t in case.get("traction", ()):
                out += "[[loads.case.traction]]\n" + "".join(
                    f"{k} = {json.dumps(v)}\n" for k, v in t.items()
                )
        return text, out

    def tables(self, magnitudes: dict, validation: bool = False) -> tuple[dict, list]:
        """(the case's [body.parts], its [[loads.case]] tables) of the loads with these
        magnitudes (docs/case-files.md), for an in-memory case; with ``validation`` the
        validation loads (:attr:`validation`) too."""
        dim, m, ax = self.dim, magnitudes, "xyz"

        def vec(axis, value):
            v = [0.0] * dim
            v[axis] = float(value)
            return v

        def part(p, end, band, cos):
            if isinstance(p, str):
                return {"facets": p} if kind_of(p) else {"group": p}
            return {"end": end, "band": float(band), "cos": float(cos)}

        def twist(normal, sign):  # about the region's mean normal, or the axis
            if normal is None:
                return vec(self.axis, sign * m["torsion"])
            return [float(m["torsion"] * x) for x in normal]

        def load(name, holds, gravity=None, on=None, **traction):
            case = {"name": name}
            if gravity is not None:
                case["gravity"] = gravity
            case["constraint"] = [{"part": h, "components": "all"} for h in holds]
            if on is not None:
                case["traction"] = [{"part": on, **traction}]
            return case

        a, b, c = self.axis, self.across, self.second
        cases = [load("sag", ["clamp"], vec(b, -m["sag"]))]
        cases.append(load("tip", ["clamp"], on="tip", vector=vec(b, -m["tip"])))
        if dim == 3:
            cases.append(load("tip2", ["clamp"], on="tip", vector=vec(c, -m["tip2"])))
            cases.append(load("torsion", ["clamp"], on="tip", twist=twist(self.tip_twist, 1)))
        cases.append(load("bridge", ["clamp", "tip"], vec(b, -m["bridge"])))
        cases.append(load("train-tip", ["tip"], on="clamp", vector=vec(b, m["tip"])))
        if dim == 3:
            cases.append(load("train-tip2", ["tip"], on="clamp", vector=vec(c, m["tip2"])))
            twisted = twist(self.clamp_twist, -1)
            cases.append(load("train-torsion", ["tip"], on="clamp", twist=twisted))
        parts = {
            "clamp": part(self.clamp, f"{ax[a]}0", self.band, self.cos),
            "tip": part(self.tip, f"{ax[a]}1", *self.tip_end),
        }
        for side, band, cos in self.sides:
            for end in (0, 1):
                parts[f"side-{ax[side]}{end}"] = part(None, f"{ax[side]}{end}", band, cos)
        for name, side, along in self._side_states():
            held, pulled = f"side-{ax[side]}0", f"side-{ax[side]}1"
            cases.append(load(name, [held], on=pulled, vector=vec(along, m["side"])))
        if validation:
            cases += self._validation_tables(m, vec, load)
        return parts, cases

    def _validation_tables(self, m: dict, vec, load) -> list:
        """The validation loads' [[loads.case]] tables (:attr:`validation`)."""
        return [
            load(name, [f"side-{'xyz'[b]}1"], vec(c, -m[f"val-{'xyz'[b]}"]))
            for name, b, c in self._side_states("val")
        ]


def end_loads(
    points: np.ndarray, cells, clamp: str | None = None, tip: str | None = None, groups=None
) -> EndLoads:
    """The end loads of a mesh (points (n, dim), meshio-style cells): its end faces along
    the longest axis grown to hold SHARE of its section (module doc), or the mesh groups
    named ``clamp`` / ``tip`` (``groups``: harness.io.meshfile.Mesh.groups), and the side
    states' faces (the end faces of the other axes that hold, grown the same way)."""
    points = np.asarray(points, float)
    dim = points.shape[1]
    size = np.ptp(points, axis=0)
    axis = int(np.argmax(size))
    across = min((a for a in range(dim) if a != axis), key=lambda a: size[a])
    facets, inside = boundary_facets(cells, points)
    geometry = facet_geometry(points, facets, inside)
    moments = mesh_moments(points, cells)
    section = float(moments[0]) / size[axis]

    def holds(masks):
        fac = [f[m] for f, m in zip(facets, masks)]
        nodes = np.unique(np.concatenate([f.ravel() for f in fac]))
        c = points[nodes] - points[nodes].mean(axis=0) if len(nodes) else np.zeros((0, dim))
        return len(nodes) >= dim and np.linalg.matrix_rank(c, tol=1e-9 * size.max()) >= dim - 1

    def choose(name, side, ok, role):
        """(masks, band, cos, Region) of the group ``name`` (band, cos: None) or of the end
        face at ``side`` grown to SHARE; None: no end face satisfies ``ok``."""
        band = cos = None
        if name is not None:
            masks, where = user_masks(name, points, facets, groups, FLAGS[role])
        else:
            found = grow(points, geometry, axis, (side,), section, BAND, lambda m: ok(m[0]))
            if found is None:
                return None
            band, cos, (masks,) = found
            where = f"the {'xyz'[axis]}{side} end face"
        info = region(points, facets, geometry, masks, axis, section, where, role, band, cos)
        return masks, band, cos, info

    held = choose(clamp, 0, holds, "clamp")
    if clamp is not None and not holds(held[0]):
        raise SpringbenchError(
            f"{held[3].where} cannot clamp the body (a face with {dim} nodes not on one line "
            f"needed)",
            field="--clamp",
            fix="a face group of the mesh or a larger region",
        )
    loaded = choose(tip, 1, lambda m: any(x.any() for x in m), "load region")
    if held is None or loaded is None or not any(m.any() for m in loaded[0]):
        raise SpringbenchError(
            "no end of the mesh's longest axis can be clamped (no face there whose normals "
            "point along the axis)",
            field="mesh",
            fix="name a face group with --clamp, or --heldout none",
        )
    clamp_end = None if clamp is not None else held[1:3]
    tip_end = None if tip is not None else loaded[1:3]
    band, cos = clamp_end or tip_end or (BAND, COS)
    tip_twist, clamp_twist = (
        (None if name is None or dim != 3 else mean_normal(geometry, r[0]))
        for name, r in ((tip, loaded), (clamp, held))
    )
    tip_facets = [f[m] for f, m in zip(facets, loaded[0])]
    return EndLoads(
        axis,
        across,
        clamp,
        tip,
        band,
        _section(points, moments, axis, tip_facets, tip_twist),
        dim,
        centroid_normal(geometry, held[0], held[3].nodes),
        cos,
        _sides(points, geometry, axis, holds, float(moments[0])),
        *(tip_end or (None, None)),
        (held[3], loaded[3]),
        None if tip_twist is None else tuple(map(float, tip_twist)),
        None if clamp_twist is None else tuple(map(float, clamp_twist)),
    )


FLAGS = {"clamp": "--clamp", "load region": "--load-region"}


def user_masks(name: str, points, facets, groups, flag: str):
    """(masks per facet array, where) of a region the user named with ``flag``: a group of
    the mesh (its facets all of whose nodes it holds) or a selector's (harness.case.selectors)."""

    def bad(message, fix):
        raise SpringbenchError(message, field=flag, fix=fix)

    sel = parse(name, bad, points.shape[1])
    if sel is None:
        g, held = groups[name], np.zeros(len(points), bool)
        nodes = np.concatenate([c.ravel() for c in g.cells.values()] + [g.nodes])
        held[np.unique(nodes).astype(int)] = True
        return [held[f].all(axis=1) for f in facets], f"group '{name}'"
    check_nodes(sel, len(points), bad)
    masks = facet_masks(sel, points, facets)
    require_facets(sel, masks, points, bad)
    return masks, sel.describe()


def near_point_warnings(ends: EndLoads) -> list[str]:
    """One warning line per region of ``ends`` that is nearly a point (a user's group below
    SHARE of the section or of few facets; an end face no band grows to SHARE), naming the
    fix; [] when both hold a meaningful part of the body. The caller prints them."""
    return [warning(r, FLAGS[r.role]) for r in ends.regions if r is not None and r.near_point]


def _sides(points, geometry, axis: int, holds, volume: float) -> tuple:
    """((b, band, cos), ...) per axis b but ``axis``: the first bands from SIDE_BAND in
    which b's low end face holds, its high one has a facet and each holds SHARE of the
    section across b (harness.case.regions.grow; none holding: no entry)."""

    def first(b):
        section = volume / np.ptp(points[:, b])
        ok = lambda m: holds(m[0]) and any(x.any() for x in m[1])  # noqa: E731
        found = grow(points, geometry, b, (0, 1), section, SIDE_BAND, ok)
        return None if found is None else (b, found[0], found[1])

    return tuple(
        f for f in (first(b) for b in range(points.shape[1]) if b != axis) if f is not None
    )


def _section(points, m, axis: int, tip_facets, twist=None) -> Section:
    """The body's Section along ``axis`` (its exact volume moments m, int x^e dV for the
    exponents e of harness.case.moments.EXPONENTS; the tip face from ``tip_facets``, its
    radius about the ``twist`` axis through its centroid, default e_axis)."""
    dim = points.shape[1]
    V, mean = m[0], m[1 : 1 + dim] / m[0]
    square = [
        m[EXPONENTS[dim].index(tuple(2 * int(a == i) for a in range(dim)))] for i in range(dim)
    ]
    L = float(np.ptp(points[:, axis]))
    I = (np.array(square) / V - mean**2) * V / L
    c = np.abs(points - mean).max(axis=0)
    tip = [f for f in tip_facets if len(f)]
    areas = [facet_sizes(points, f) for f in tip]
    tip_area = float(sum(a.sum() for a in areas))
    centroid = sum(a @ points[f].mean(axis=1) for a, f in zip(areas, tip)) / tip_area
    nodes = np.unique(np.concatenate([f.ravel() for f in tip]))
    r = points[nodes] - centroid
    d = np.eye(dim)[axis] if twist is None else np.asarray(twist, float)
    r -= np.outer(r @ d, d)  # across the twist axis
    return Section(
        L,
        float(V / L),
        tuple(map(float, I)),
        tuple(map(float, c)),
        tip_area,
        float(np.linalg.norm(r, axis=1).max()) if dim == 3 else math.nan,
    )
