"""calibrate's settings: the command line read once, at the command's edge, into one frozen
object every later step takes (no ``args`` namespace travels through the work)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from harness.case.default_loads import PEAK_STRAIN


@dataclass(frozen=True)
class Settings:
    """What ``springbench calibrate`` was asked for; defaults are the command line's
    (harness/commands/calibrate.py names each flag's meaning)."""

    mesh: Path
    E: float
    nu: float
    out: Path
    density: float = 1000.0
    method: str = "lbfgs"
    model: str = "springs"
    engine: str | None = None
    prior_weight: float | None = None
    init: str = "none"
    rule: str = "best"
    loads: str = "linear"
    heldout: str = "ends"
    clamp: str | None = None
    load_region: str | None = None
    masses: str = "lumped"
    damping_ratio: float = 0.05
    k_ratio: float | None = None
    length_unit: str = "m"
    plane: str = "stress"
    magnitude: float | None = None
    peak_strain: float = PEAK_STRAIN
    tol: float = 1e-2
    max_refine: int = 100
    solver: str = "auto"
    budget: float | None = None
    format: str | None = None
    seed: int = 0
    quiet: bool = False
    wide: bool = False
    save_case: Path | None = None

    @classmethod
    def of(cls, args) -> Settings:
        """The settings of a parsed command line (an argparse namespace; flags it lacks
        keep their defaults)."""
        given = vars(args)
        return cls(**{f.name: given[f.name] for f in dataclasses.fields(cls) if f.name in given})
