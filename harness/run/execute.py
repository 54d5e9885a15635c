"""Executing one job in a fresh scratch folder (in this process, a worker process or a
Dask worker), with live status sent back to the parent (harness/run/runner.py)."""

from __future__ import annotations

import os
import random
import shutil
import signal
import time
import traceback
from pathlib import Path

import numpy as np

from harness.case.reader import load_case
from harness.errors import CaseError, SpringbenchError
from harness.run.jobs import Job, JobResult, _error_row, _jsonable, loaded_sources
from harness.run.lock import scratch_dir
from harness.stages import StageContext, load_stages

# -- executing one job (in a worker) ----------------------------------------------------


class _Throttled:
    """``ctx.status``: forwards at most a few messages per second to ``sink``."""

    def __init__(self, sink, label: str, every: float = 0.2):
        self.sink, self.label, self.every, self.last = sink, label, every, 0.0

    def __call__(self, msg: str):
        now = time.monotonic()
        if self.sink is None or now - self.last < self.every:
            return
        self.last = now
        try:
            self.sink(self.label, str(msg))
        except Exception:  # status must never break a job
            pass


class QueueSink:
    """Status from worker processes through a Manager queue (picklable proxy)."""

    def __init__(self, queue):
        self.queue = queue

    def __call__(self, label, msg):
        self.queue.put_nowait((label, msg))


class DaskSink:
    """Status from Dask workers as events on ``topic``."""

    def __init__(self, topic: str):
        self.topic = topic

    def __call__(self, label, msg):
        from distributed import get_worker

        get_worker().log_event(self.topic, {"label": label, "msg": msg})


def _seed_everything(seed: int):
    random.seed(seed)
    np.random.seed(seed % 2**32)


def _stages(job: Job, case):
    """(the stage modules the job runs, the case's [run] stages: () for every one); an
    unknown name in the case is a one-line CaseError."""
    modules = load_stages(list(job.stages))
    wanted = tuple((case.section("run") or {}).get("stages", ()))
    names = [m.NAME for m in modules]
    unknown = [w for w in wanted if w not in names]
    if unknown:
        raise CaseError(
            f"unknown stage '{unknown[0]}'",
            file=job.rel_file,
            field="run.stages",
            fix=f"available: {', '.join(names) or 'none'}",
        )
    return modules, wanted


def _stage_rows(stage, case, job: Job, tmp: Path, status) -> list[dict]:
    """One stage's rows, seeded, each with the case, stage, seed, status and seconds."""
    _seed_everything(job.seed)
    ctx = StageContext(
        out_dir=tmp, mode=job.mode, seed=job.seed, status=status, n_seeds=job.n_seeds
    )
    status(f"{stage.NAME}")
    t0 = time.perf_counter()
    out = stage.run(case, ctx) or []
    dt = time.perf_counter() - t0
    rows = []
    for row in out:
        row = dict(row)
        row["case"] = job.case
        row.setdefault("model", "")
        row.setdefault("stage", stage.NAME)
        row.setdefault("seed", job.seed)
        row.setdefault("status", "ok")
        row.setdefault("seconds", dt)
        rows.append({str(k): _jsonable(v) for k, v in row.items()})
    return rows


def _files(tmp: Path) -> dict:
    """{relative path: bytes} of the files the stages wrote."""
    return {
        f.relative_to(tmp).as_posix(): f.read_bytes()
        for f in sorted(tmp.rglob("*"))
        if f.is_file() and not f.is_symlink()
    }


def execute(job: Job, sink=None) -> JobResult:
    """Run one job in a fresh temporary folder; never raises."""

    t_job = time.perf_counter()
    status = _Throttled(sink, job.label)
    tmp = scratch_dir()
    stage_name = "case"
    try:
        case = load_case(job.case_file, job.mode)
        modules, wanted = _stages(job, case)
        rows, everything = [], False
        for stage in modules:
            stage_name = stage.NAME
            if (wanted and stage.NAME not in wanted) or not stage.applies(case):
                continue
            everything |= bool(getattr(stage, "SUBPROCESS_CODE", False))
            rows += _stage_rows(stage, case, job, tmp, status)
        if not rows:
            rows = [
                {
                    "case": job.case,
                    "model": "",
                    "stage": "",
                    "seed": job.seed,
                    "status": "no stage applies",
                }
            ]
        return JobResult(
            job,
            "ok",
            rows,
            _files(tmp),
            seconds=time.perf_counter() - t_job,
            code=loaded_sources(job.stages, everything),
        )
    except SpringbenchError as exc:
        msg = str(exc).replace(job.case_file, job.rel_file or job.case_file)
        dt = time.perf_counter() - t_job
        return JobResult(
            job, "error", [_error_row(job, stage_name, msg, dt)], error=msg, seconds=dt
        )
    except Exception as exc:  # a bug, not bad input: one line here, the traceback in a log
        msg = f"{type(exc).__name__}: {exc}".replace("\n", " ")
        if len(msg) > 300:
            msg = msg[:297] + "..."
        dt = time.perf_counter() - t_job
        return JobResult(
            job,
            "error",
            [_error_row(job, stage_name, msg, dt)],
            error=msg,
            traceback=traceback.format_exc(),
            seconds=dt,
        )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _ignore_sigint():
    """Ctrl-C is the parent's business: it stops the workers itself, without their tracebacks."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _init_worker():
    """Pool initializer: one BLAS thread per worker (the pool is the parallelism); Ctrl-C
    handled by the parent."""
    _ignore_sigint()
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
        os.environ.setdefault(var, "1")
