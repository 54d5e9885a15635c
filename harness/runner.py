"""Run suites of cases: each case through every stage that applies, rows into tables.

Minimal serial version; the suite runner issue makes it parallel and resumable.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import pandas as pd

from harness.cases import find_cases, load_case
from harness.stages import StageContext, load_stages

DEFAULT_CASES = Path(__file__).resolve().parent.parent / "cases"
DEFAULT_RESULTS = Path(__file__).resolve().parent.parent / "results"


def run_case(path: Path, mode: str, results: Path, status=lambda m: None) -> list[dict]:
    case = load_case(path, mode)
    rows = []
    for stage in load_stages():
        if stage.applies(case):
            t0 = time.perf_counter()
            ctx = StageContext(out_dir=results / case.suite / case.name, mode=mode, status=status)
            for row in stage.run(case, ctx):
                row.setdefault("case", case.name)
                row.setdefault("stage", stage.NAME)
                row.setdefault("seconds", time.perf_counter() - t0)
                rows.append(row)
    return rows


def run_paths(paths, mode: str = "quick", results: Path = DEFAULT_RESULTS) -> dict[str, pd.DataFrame]:
    from tqdm import tqdm
    files = find_cases(paths or [DEFAULT_CASES])
    by_suite: dict[str, list[dict]] = {}
    bar = tqdm(files, desc="suite", unit="case", file=sys.stderr)
    for f in bar:
        bar.set_postfix_str(f.stem)
        rows = run_case(f, mode, results, status=lambda m: bar.set_postfix_str(f"{f.stem}: {m}"))
        by_suite.setdefault(f.parent.name, []).extend(rows)
    tables = {}
    for suite, rows in by_suite.items():
        df = pd.DataFrame(rows)
        out = results / suite
        out.mkdir(parents=True, exist_ok=True)
        df.to_csv(out / "summary.csv", index=False)
        tables[suite] = df
    return tables
