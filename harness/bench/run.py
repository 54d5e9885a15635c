"""springbench bench run: README's first command, ``springbench run`` (the quick tier of
harness/suites.py), timed as a user runs it: in its own process, into an empty temporary
folder (``--results``) with an empty reference cache (``SPRINGBENCH_CACHE``), as on a
fresh machine: nothing is skipped, nothing of runs/, results/ or the user's cache touched.

Columns: the command, the cases and jobs it ran, ``wall_s`` (its wall time), ``cpu_s``
(user + system CPU of the process and every process it waited for: the workers, the
engines' subprocesses), ``user_s`` and ``sys_s``, ``peak_gb`` (the largest process),
``runs_mb`` (what it left in its results folder), ``cores`` and ``load_1min`` at the
start, the exit status, and the targets: 5 minutes of wall time on an idle 2-core
machine, 100 MB. A shared machine stretches the wall time by its load; the CPU time
barely moves, so ``cpu_s / cores`` is the idle machine's wall time at best.
``--quick``: one small case, a smoke test of the benchmark itself.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

from harness.paths import ROOT
from harness.suites import QUICK

TARGET_WALL_S, TARGET_MB = 300.0, 100.0
SMOKE = ["cases/verification/plate_strain_quad.toml"]


def folder_mb(folder: Path) -> float:
    """Megabytes of the files under ``folder``."""
    return sum(f.stat().st_size for f in Path(folder).rglob("*") if f.is_file()) / 1e6


def timed(argv: list[str], cwd: Path, env: dict | None = None) -> dict:
    """Run ``argv`` and wait for it: wall seconds, its CPU and peak memory (os.wait4: the
    process and the descendants it waited for), exit status, the tail of its output."""
    t0 = time.perf_counter()
    with tempfile.TemporaryFile() as log:
        proc = subprocess.Popen(argv, cwd=cwd, env=env, stdout=log, stderr=subprocess.STDOUT)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        log.seek(0)
        tail = log.read().decode(errors="replace").strip().splitlines()[-1:]
    return dict(
        wall_s=wall,
        cpu_s=usage.ru_utime + usage.ru_stime,
        user_s=usage.ru_utime,
        sys_s=usage.ru_stime,
        peak_gb=usage.ru_maxrss / 1e6,
        exit=os.waitstatus_to_exitcode(status),
        last_line=tail[0] if tail else "",
    )


def run(quick: bool = False) -> pd.DataFrame:
    """One row: ``springbench run`` (``--quick``: one small case) timed into a temporary
    folder."""
    paths = SMOKE if quick else []
    cores = len(os.sched_getaffinity(0))
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="springbench-bench-run-") as tmp:
        out = Path(tmp) / "runs"
        argv = [sys.executable, "-m", "harness", "run", *paths, "--results", str(out)]
        env = dict(os.environ, SPRINGBENCH_CACHE=str(Path(tmp) / "cache"))
        row = timed(argv, ROOT, env)
        size = folder_mb(out) if out.exists() else 0.0
    return pd.DataFrame(
        [
            dict(
                command="springbench run" + "".join(f" {p}" for p in paths),
                cases=len(paths) or len(QUICK),
                runs_mb=size,
                cores=cores,
                load_1min=load,
                **row,
                target_wall_s=TARGET_WALL_S,
                target_mb=TARGET_MB,
                cpu_per_core_s=row["cpu_s"] / max(min(cores, 2), 1),
            )
        ]
    )
