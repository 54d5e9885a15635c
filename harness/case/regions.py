"""How much of the body a clamp or load region holds, and the rule that grows the default
ones until they hold a meaningful part of it.

A region's share is its area projected on the axis it ends, sum of facet area x |n . e|,
over the body's mean section across that axis, A = V / L (V the volume, L the extent along
the axis). A flat end face of a prismatic body (a box, a cylinder, a bar, a lug) holds its
whole section, a share of about 1; the cap within 5 % of the length of a rounded end a
few facets (a 756-tet ellipsoid 0.4 x 0.2 x 0.14 m: 10, a share of 0.26).

The rule: a default region is the first end face (harness.io.end_faces) of :func:`bands`,
from the start band x 1.5 at a time up to half the extent, each band with normals
n . e >= 0.5 and then >= 0, whose share is at least SHARE (a clamp also holds three
non-collinear nodes, two in 2-D; a load region a facet). A flat end reaches the share at
the first band with the faces' cos, so a prismatic body's regions are its flat end faces,
the same facets as the band alone gives. When no band reaches it, the region of the
largest share is taken and warned about (harness.case.default_loads.near_point_warnings).

SHARE = 0.5, by the FEM error the regions give: the reference's own estimate at calibrate's
defaults (max_refine 1, nu 0.3; worst held-out load) on gmsh ellipsoids 0.4 x 0.2 x 0.14 m,
share 0.26 (the 5 % cap) / ~0.45 / ~0.6 / ~0.8: 756 tets 36 / 18 / 14-22 / 10 %, 1,939 tets
15 / 9 / 8 / 8 %, 8,254 tets 13 / 9 / 6 / 6 %; beyond ~0.8 the two-end load (bridge) loses
more than the others gain (13-16 % at 1.1-1.4). Independently (scikit-fem P2, the mesh
against its uniform refinement, the tip load): 11 % at 0.26, 7-8 % at ~0.5. Half the
section halves the error a near-point cap gives and keeps every body whose ends are flat
or nearly so (the lug's rounded eye: 0.78) as it is. What remains is not the region's size:
a clamp whose rim lies inside a smooth surface is singular along that rim (P2 against its
refinement: a cylinder's flat end clamped, 0.6 %; the same face inside r < 0.075 / 0.05,
3 / 12 %), which only a finer mesh (or a flat face group) mends.

A user's group or selected region (harness.case.selectors) is used as given; its share is
its facet area over A (a bolt hole's wall projects to nothing on any axis), and a region
below SHARE or of fewer than FEW_FACETS facets is warned about.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from harness.io.end_faces import COS, end_masks

SHARE = 0.5  # a default region's area across the axis, at least this share of V / L
FEW_FACETS = 4  # a region of fewer facets is a near-point on the mesh it is given
NORMAL_MIN = 0.2  # a region whose mean normal is shorter faces every way: no twist axis


@dataclass(frozen=True)
class Region:
    """What a clamp or load region holds: ``where`` it is (``the x0 end face``, ``group
    'clamp'``), its facet ``area`` (m^2; 2-D: m), its area ``across`` the axis it ends
    (end faces), the body's mean ``section`` A = V / L across that axis, its ``facets`` and
    ``nodes``, the end face's ``band`` and ``cos`` (None for a group)."""

    where: str
    role: str  # "clamp" or "load region"
    area: float
    across: float
    section: float
    facets: int
    nodes: int
    band: float | None = None
    cos: float | None = None

    @property
    def group(self) -> bool:
        return self.band is None

    @property
    def share(self) -> float:
        """The share of the section the region holds (module doc)."""
        return (self.area if self.group else self.across) / max(self.section, 1e-300)

    @property
    def near_point(self) -> bool:
        """Below SHARE, or a group of fewer than FEW_FACETS facets (an end face of fewer is
        a coarse mesh's whole section)."""
        return self.share < SHARE or (self.group and self.facets < FEW_FACETS)

    def describe(self, axis: int, dim: int, nodes: bool = True) -> str:
        """'facets within .. of the length, normals ..: area .., .. % of the mean section,
        N nodes' (``nodes`` False: without the count)."""
        a, unit = "xyz"[axis], "m^2" if dim == 3 else "m"
        face = (
            ""
            if self.group
            else f"facets within {self.band:.3g} of the length, normals n . e_{a} >= {self.cos:g}: "
        )
        across = "" if self.group else f", {self.across:.3g} {unit} across {a}"
        count = f", {self.nodes} nodes" if nodes else ""
        return (
            f"{face}{self.area:.3g} {unit}{across}, {percent(self.share)} % of the mean "
            f"section{count}"
        )


def percent(share: float) -> str:
    """A share in percent, to two digits: '2.1', '58', '100'."""
    p = 100 * share
    return f"{p:.2g}" if p < 10 else f"{p:.0f}"


def bands(start: float):
    """(band, cos) to try, narrowest first: the band from ``start`` x 1.5 at a time up to
    half the extent, each with the faces' cos and then 0 (a pointed end has no face: then
    the facets that face that way at all)."""
    band = start
    while band <= 0.5:
        yield band, COS
        yield band, 0.0
        band *= 1.5


def area_across(geometry, masks, axis: int) -> float:
    """Area of the masked facets projected on ``axis``: sum of area x |n . e|."""
    return float(sum((a * np.abs(n[:, axis]))[m].sum() for (_, n, a), m in zip(geometry, masks)))


def grow(points, geometry, axis: int, sides, section: float, start: float, ok):
    """(band, cos, [masks per side of ``sides``]) of the first :func:`bands` from ``start``
    whose end faces at ``sides`` of ``axis`` satisfy ``ok`` (masks per side -> bool) and
    each hold SHARE of ``section``; none holding SHARE: the one whose smallest share is
    largest; none satisfying ``ok``: None."""
    best, best_share = None, -1.0
    for band, cos in bands(start):
        masks = [end_masks(points, geometry, axis, s, band, cos) for s in sides]
        if not ok(masks):
            continue
        share = min(area_across(geometry, m, axis) for m in masks) / section
        if share >= SHARE:
            return band, cos, masks
        if share > best_share:
            best, best_share = (band, cos, masks), share
    return best


def region(points, facets, geometry, masks, axis, section, where, role, band=None, cos=None):
    """The :class:`Region` of the masked facets (one mask per facet array)."""
    chosen = [f[m] for f, m in zip(facets, masks)]
    nodes = np.unique(np.concatenate([f.ravel() for f in chosen])) if chosen else []
    return Region(
        where,
        role,
        float(sum(a[m].sum() for (_, _, a), m in zip(geometry, masks))),
        area_across(geometry, masks, axis),
        float(section),
        int(sum(m.sum() for m in masks)),
        len(nodes),
        None if band is None else float(band),
        None if cos is None else float(cos),
    )


def centroid_normal(geometry, masks, nodes: int) -> str:
    """': centroid (..) m, normal (..), N nodes' of the masked facets (area-weighted)."""
    area = sum(a[m].sum() for (_, _, a), m in zip(geometry, masks))
    centre = sum(a[m] @ c[m] for (c, _, a), m in zip(geometry, masks))
    normal = sum(a[m] @ n[m] for (_, n, a), m in zip(geometry, masks))
    n = normal / max(np.linalg.norm(normal), 1e-300)
    c = vector(centre / max(area, 1e-300), scale=np.sqrt(area))
    return f": centroid {c} m, normal {vector(n)}, {nodes} nodes"


def vector(v, scale: float = 0.0) -> str:
    """'(1, 0.5, 0)': a vector to three digits, a component below 1e-12 of its largest or of
    ``scale`` (the rounding of a sum that cancels, e.g. a symmetric face's centroid: -3e-19 m;
    a face at x = 0 has no large component, so its own size is the scale) as 0."""
    v = np.asarray(v, float)
    v = np.where(np.abs(v) < 1e-12 * max(np.abs(v).max(initial=0.0), scale), 0.0, v)
    return "(" + ", ".join(f"{x:.3g}" for x in v) + ")"


def mean_normal(geometry, masks):
    """The masked facets' mean outward unit normal (area-weighted), the axis a twist of
    them turns about; None when they face every way (its length below NORMAL_MIN of their
    area: a bore's wall, a whole closed surface)."""
    area = sum(a[m].sum() for (_, _, a), m in zip(geometry, masks))
    normal = sum(a[m] @ n[m] for (_, n, a), m in zip(geometry, masks))
    length = float(np.linalg.norm(normal))
    return None if length < NORMAL_MIN * area else normal / length


def warning(r: Region, flag: str) -> str:
    """The line that says a region is a near-point, and how to mend it."""
    name = r.where if r.group else f"{r.where} (within {r.band:.3g} of the length at most)"
    return (
        f"warning: {name} holds {percent(r.share)} % of the section ({r.facets} facets, "
        f"{r.nodes} nodes): a near-point {r.role}, the FEM cannot converge there; "
        f"give {flag} a larger region (a face group, nodes:FILE, box: or sphere:)"
    )
