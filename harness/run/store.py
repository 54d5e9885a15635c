"""Storing a job's result: data files and the result JSON under results/<suite>/<case>/,
each written atomically (harness/run/runner.py)."""

from __future__ import annotations

import json
import re
from pathlib import Path

from harness.outputs import atomic_write as write
from harness.provenance import with_engines
from harness.run.jobs import Job, JobResult
from harness.stages.engines import NAME as ENGINES_STAGE

RESULT_PREFIX = "result-seed"


# -- storing results ---------------------------------------------------------------------


def atomic_write(path: Path, data: bytes):
    """Write ``data`` to ``path`` so readers see the old file or the new one, never half; a
    full or read-only disk is one line naming the file (:mod:`harness.outputs`)."""
    write(path, data)


def case_dir(results: Path, job: Job) -> Path:
    return Path(results) / job.suite / job.case


def data_dir(results: Path, job: Job) -> Path:
    d = case_dir(results, job)
    return d if job.n_seeds == 1 else d / f"seed{job.seed}"


def result_path(results: Path, job: Job) -> Path:
    return case_dir(results, job) / f"{RESULT_PREFIX}{job.seed}.json"


def read_result(path: Path) -> dict | None:
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None


def store(results: Path, res: JobResult, provenance: dict | None = None) -> Path:
    """Write a job's data files, then its result file (the 'finished' marker), which
    records the run's ``provenance`` (harness/provenance.py; with the engine packages'
    versions when the engines stage made a row)."""
    job = res.job
    out = data_dir(results, job)
    root = out.resolve()
    old = read_result(result_path(results, job)) or {}
    for name, data in res.files.items():
        target = out / name
        if not target.resolve().is_relative_to(root):  # a stage cannot write outside its folder
            continue
        atomic_write(target, data)
    for name in old.get("files", []):  # files the previous run wrote and this one did not
        if name not in res.files:
            stale = out / name
            if stale.resolve().is_relative_to(root) and stale.is_file():
                stale.unlink()
    log = ""
    if res.traceback:
        logp = case_dir(results, job) / f"error-seed{job.seed}.log"
        atomic_write(logp, res.traceback.encode())
        log = str(logp)
        res.log = log
    manifest = {
        "case": job.case,
        "suite": job.suite,
        "file": job.rel_file,
        "mode": job.mode,
        "seed": job.seed,
        "n_seeds": job.n_seeds,
        "input_hash": job.key,
        "status": res.status,
        "error": res.error,
        "log": log,
        "stages": list(job.stages),
        "expect": job.expect,
        "files": sorted(res.files),
        "data_dir": "." if job.n_seeds == 1 else f"seed{job.seed}",
        "seconds": res.seconds,
        "code": res.code,
        "rows": res.rows,
    }
    if provenance is not None:
        engines = any(r.get("stage") == ENGINES_STAGE for r in res.rows)
        manifest["provenance"] = with_engines(provenance) if engines else provenance
    path = result_path(results, job)
    atomic_write(path, json.dumps(manifest, indent=1, allow_nan=True).encode())
    return path


def _prune_seeds(results: Path, jobs: list[Job]):
    """Drop stored results of seeds a case no longer asks for."""
    by_case: dict[Path, set[int]] = {}
    for j in jobs:
        by_case.setdefault(case_dir(results, j), set()).add(j.seed)
    for d, seeds in by_case.items():
        for f in d.glob(f"{RESULT_PREFIX}*.json"):
            m = re.fullmatch(rf"{RESULT_PREFIX}(\d+)\.json", f.name)
            if m and int(m.group(1)) not in seeds:
                f.unlink()
