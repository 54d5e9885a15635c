"""What ``springbench run`` does with a case: an ordered list of stages.

A stage is a module with ``NAME``, ``applies(case) -> bool`` and
``run(case, ctx) -> list[dict]`` (rows of the suite's summary table; every row has
``case`` and ``model``; the runner fills ``case``, ``stage``, ``seed``, ``status`` and
``seconds`` when a row leaves them out). ``ctx`` is a :class:`StageContext`. A new stage
is one module and its line in ``harness.registry.STAGES``; a case's ``[run] stages = [NAME, ...]``
restricts it
to those stages. A stage may also have ``check(case)``: the case mistakes it can see
without solving anything (raised as CaseError); ``springbench validate`` calls it.

Rules for stages (the runner relies on them):
- write data files only inside ``ctx.out_dir`` (``ctx.file(name)`` gives a path there);
  the runner moves them into ``results/<suite>/<case>/`` once the case has finished,
  so a killed run never leaves half a result. Formats the report draws figures from are
  defined in :mod:`harness.report.build` (trace.csv, lloyd.csv, volume.csv, frequencies.csv,
  anisotropy.csv, deformed*.npz).
- draw randomness only from ``ctx.seed`` (``ctx.rng()``), so the same seed gives the
  same table bit for bit;
- call ``ctx.status("T 12/80, G 0.53")`` during long steps; it is cheap (throttled) and
  shows in the suite's progress bar, also from worker processes and Dask workers;
- raise :class:`harness.errors.SpringbenchError` (one line: file, field, fix) for bad
  input; the runner records it as an error row and carries on with the next case.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from harness import registry


@dataclass
class StageContext:
    """What a stage may use: where to write files, the mode, the seed, a status callback.

    ``n_seeds`` is how many seeds the case runs (its data files then live in a
    ``seed<N>/`` sub-folder of the case folder)."""

    out_dir: Path
    mode: str = "quick"
    seed: int = 0
    status: Callable[[str], None] = field(default=lambda msg: None)
    n_seeds: int = 1

    def file(self, name: str) -> Path:
        """``out_dir / name``, with ``out_dir`` created."""
        self.out_dir.mkdir(parents=True, exist_ok=True)
        return self.out_dir / name

    def rng(self, stream: int = 0):
        """A numpy Generator seeded by (seed, stream): independent streams per purpose."""
        return np.random.default_rng([self.seed, stream])


def stage_modules() -> tuple[str, ...]:
    """The registered stages' module names, in pipeline order."""
    return tuple(registry.STAGES.module(name) for name in registry.STAGES)


def load_stages(names=None):
    """Import the stage modules named in ``names`` (default: every registered stage)."""
    return [importlib.import_module(name) for name in (stage_modules() if names is None else names)]


def check_case(case, stages=None):
    """Run the ``check(case)`` of every stage that applies to ``case`` (validate's view of
    the mistakes the schema alone cannot see)."""
    for st in load_stages(stages):
        if hasattr(st, "check") and st.applies(case):
            st.check(case)
