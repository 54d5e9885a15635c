"""The frozen types a case file becomes: :class:`Case` and its body, fibres, regions,
material and reference settings (harness/case/reader.py makes them)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import numpy as np

from harness.case.loadsets import LoadCase
from harness.io.meshfile import mesh_points


@dataclass(frozen=True)
class Body:
    shape: str
    origin: tuple[float, ...] | None = None
    size: tuple[float, ...] | None = None
    vertices: tuple[tuple[float, ...], ...] | None = None
    file: Path | None = None
    format: str | None = None
    parts: Mapping[str, tuple] = field(default_factory=dict)

    def bbox(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) of the body."""
        if self.shape in ("rectangle", "box"):
            lo = np.asarray(self.origin, float)
            return lo, lo + np.asarray(self.size, float)
        if self.shape == "polygon":
            v = np.asarray(self.vertices, float)
            return v.min(0), v.max(0)
        p = mesh_points(self.file, self.format)  # read once per version of the file
        return p.min(0), p.max(0)


@dataclass(frozen=True)
class Fibre:
    E_fibre: float
    E_cross: float
    nu_fibre: float
    nu_cross: float
    G_fibre: float
    direction: tuple[float, ...] | None = None
    azimuth_deg: float | None = None
    elevation_deg: float | None = None
    field: str | None = None
    seed: int = 0


@dataclass(frozen=True)
class Region:
    lo: tuple[float, ...]
    hi: tuple[float, ...]
    E: float
    nu: float | None = None
    density: float | None = None


@dataclass(frozen=True)
class Material:
    E: float
    nu: float
    density: float = 1.0
    plane: str = "stress"
    fibre: Fibre | None = None
    regions: tuple[Region, ...] = ()


@dataclass(frozen=True)
class ReferenceSpec:
    element: str = "P2"
    cell: str = "tri"
    divisions: int | None = None
    tol: float = 1e-4
    max_refine: int = 3
    solver: str = "auto"
    modes: int = 6
    method: str = "refine"  # resolved: "graded" or "refine"


@dataclass(frozen=True)
class Case:
    """A validated case. ``sections`` holds the stage-owned sections (read-only dicts)."""

    path: Path
    name: str
    dim: int
    body: Body
    material: Material
    loads: tuple[LoadCase, ...]
    reference: ReferenceSpec
    load_set: str | None = None
    magnitude: float = 1.0
    description: str = ""
    tags: tuple[str, ...] = ()
    mode: str = "quick"
    sections: Mapping[str, Mapping] = field(default_factory=dict)
    digest: str = ""
    heldout: tuple[str, ...] = ()
    validation: tuple[str, ...] = ()  # scored to accept or refuse a fit, never fitted
    rank_by: tuple[str, ...] = ()  # fitted loads the rules are ranked by first

    def section(self, name: str) -> Mapping | None:
        return self.sections.get(name)

    @property
    def fit_loads(self) -> tuple[str, ...]:
        """The load cases a fit uses: every one neither held out nor kept for validation."""
        kept = set(self.heldout) | set(self.validation)
        return tuple(l.name for l in self.loads if l.name not in kept)

    @property
    def suite(self) -> str:
        """The folder the case lives in, under cases/ (e.g. 'deussen1995')."""
        return self.path.parent.name
