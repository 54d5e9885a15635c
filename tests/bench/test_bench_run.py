"""``springbench bench run`` (harness/bench/run.py): README's first command timed in its own
process into a temporary folder; here its --quick smoke (one small case): one row with the
wall and CPU seconds of the child, what it left behind, and the exit status 0; the user's
runs/ and results/ untouched."""

from __future__ import annotations

import pytest

from harness.paths import DEFAULT_RESULTS, DEFAULT_RUNS
from harness.registry import BENCHES


def _mtimes(folder):
    return {p: p.stat().st_mtime_ns for p in folder.rglob("*")} if folder.exists() else {}


def test_the_run_bench_times_a_run_in_a_subprocess():
    bench = BENCHES.load("run")
    before = (_mtimes(DEFAULT_RUNS), _mtimes(DEFAULT_RESULTS))
    df = bench.run(quick=True)
    assert len(df) == 1
    row = df.iloc[0]
    assert row["exit"] == 0, row["last_line"]
    assert row["cases"] == 1 and row["command"].startswith("springbench run cases/")
    assert row["wall_s"] > 0 and row["cpu_s"] == pytest.approx(row["user_s"] + row["sys_s"])
    assert row["cpu_s"] > 0.5  # the child and its workers, not this process
    assert 0 < row["runs_mb"] < bench.TARGET_MB
    assert row["target_wall_s"] == 300
    assert (_mtimes(DEFAULT_RUNS), _mtimes(DEFAULT_RESULTS)) == before
