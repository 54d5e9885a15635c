"""The engine benchmark's plot (results/bench/engines.csv), drawn as the engines suite's
(harness/report/figures/engines.py)."""

from __future__ import annotations

from pathlib import Path

from harness.report.figures import read_csv
from harness.report.figures.engines import draw

NAME, SCOPE = "bench_engines", "bench"
DATA = ("engines.csv",)
CODE = ("harness.report.figures.engines",)


def make(folder: Path) -> list[Path]:
    return draw(read_csv(folder, "engines.csv"), Path(folder) / "fig-bench-engines.png")
