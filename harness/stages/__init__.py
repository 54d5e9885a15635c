"""What ``springbench run`` does with a case: an ordered list of stages.

A stage is a module with ``NAME``, ``applies(case) -> bool`` and
``run(case, ctx) -> list[dict]`` (rows of the suite's summary table; every row has
``case`` and ``model``). ``ctx`` is a :class:`StageContext`. A new stage is one module
added to ``STAGES``.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

STAGES = [
    "harness.stages.reference_check",   # FEM reference + its verification (issue 2)
    "harness.stages.sms",               # spring/mass build + score + optimise (issues 3, 4)
    "harness.stages.bc2000",            # Bourguignon & Cani experiments (issue 5)
]


@dataclass
class StageContext:
    """What a stage may use: where to write files, the mode, a status callback."""
    out_dir: Path
    mode: str = "quick"
    seed: int = 0
    status: Callable[[str], None] = field(default=lambda msg: None)


def load_stages():
    out = []
    for name in STAGES:
        try:
            out.append(importlib.import_module(name))
        except ModuleNotFoundError as exc:
            if exc.name != name:
                raise
    return out
