"""Run suites of cases: each (case, seed) through every stage that applies, in parallel,
resumable, and with the same table bit for bit for the same seed and inputs.

- A *job* is one (case file, mode, seed). Its input hash covers the case file's bytes,
  the mode, the seed, the stage list and the mesh file the case references; its code
  version is the SHA-256 of every source file of ``harness/`` and ``reference/`` (and of
  stage modules living elsewhere) that was loaded when the job ran, recorded in the
  manifest. A finished job is skipped while its input hash and each of those files are
  unchanged: editing the report, the figures, the CLI or a module the job never imported
  re-runs nothing, editing anything the job imported re-runs it. (Code is only ever
  reached through imports, so the files a job loaded are all the code it depends on; a
  stage that runs springbench commands in their own processes, ``SUBPROCESS_CODE`` as the
  engines stage, depends on every source file but the report's and the bench's.)
- A job runs in a fresh temporary folder (in a worker process, a Dask worker or, for a
  single job or ``--jobs 1``, in this process). It returns its rows and the bytes of the
  data files its stages wrote; the parent writes them under
  ``results/<suite>/<case>/`` (``seed<N>/`` when the case runs several seeds), each
  atomically (temp file + ``os.replace``), and last ``result-seed<N>.json`` (manifest +
  rows): a finished job is exactly a job whose result file exists, so a run killed with
  SIGKILL loses no finished case, and a re-run skips every finished job whose input hash
  is unchanged (``force=True`` recomputes).
- A failing job (``SpringbenchError``) becomes an error row; the suite carries on. Other
  exceptions become one line plus a log file holding the traceback.
- Live status: stages call ``ctx.status(msg)``; worker processes send it through a
  ``multiprocessing.Manager`` queue, Dask workers through ``log_event`` on a topic the
  client subscribes to; the parent shows it in the suite's tqdm bar.

Heavy imports (numpy, pandas, the stages) happen inside functions so worker processes
can pin BLAS to one thread before numpy loads.
"""

from __future__ import annotations

import os
import queue as queue_mod
import traceback
import uuid
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path

from harness.errors import SpringbenchError
from harness.paths import DEFAULT_RESULTS
from harness.progress import SuiteProgress as _Progress
from harness.provenance import collect
from harness.report import build as report
from harness.run.execute import DaskSink, QueueSink, _ignore_sigint, _init_worker, execute
from harness.run.jobs import Job, JobResult, _error_row, code_unchanged, plan
from harness.run.lock import clean_stale_scratch, run_lock
from harness.run.store import _prune_seeds, read_result, result_path, store
from harness.suites import quick_seconds

DASK_CONNECT_TIMEOUT = "15s"


# -- running a suite ---------------------------------------------------------------------


@dataclass
class RunReport:
    """What a run did: every job's result (skipped ones included), the suites touched."""

    results: list[JobResult]
    suites: list[Path]
    results_root: Path

    @property
    def failed(self) -> list[JobResult]:
        return [r for r in self.results if r.status == "error"]

    @property
    def skipped(self) -> list[JobResult]:
        return [r for r in self.results if r.status == "skipped"]

    @property
    def ran(self) -> list[JobResult]:
        return [r for r in self.results if r.status == "ok"]


def error_line(res: JobResult) -> str:
    """The one line that reports a failed job (its file is named once)."""
    where = (
        ""
        if res.job.rel_file and res.job.rel_file in res.error
        else f"{res.job.rel_file or res.job.label}: "
    )
    if res.job.n_seeds > 1:
        where += f"seed {res.job.seed}: "
    extra = f" (traceback in {res.log})" if res.log else ""
    return f"springbench: error: {where}{res.error}{extra}"


def _default_jobs() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover
        return os.cpu_count() or 1


def run_suite(
    paths=(),
    mode: str = "quick",
    results: Path | None = None,
    *,
    jobs: int | None = None,
    executor: str = "local",
    scheduler: str | None = None,
    force: bool = False,
    figures: bool = True,
    stages=None,
    progress=None,
) -> RunReport:
    """Run case files / suites; write results, tables, figures and the index.

    ``stages`` overrides the registered stages (module names); ``progress`` None
    shows the bar only on a terminal."""
    results = Path(results or DEFAULT_RESULTS)
    jobs_n = jobs or _default_jobs()
    if jobs_n < 1:
        raise SpringbenchError(
            f"--jobs {jobs_n}: must be at least 1", field="--jobs", fix="e.g. --jobs 2"
        )
    if executor not in ("local", "dask"):
        raise SpringbenchError(
            f"unknown executor '{executor}'", field="--executor", fix="local or dask"
        )
    if scheduler and executor != "dask":
        raise SpringbenchError(
            "--scheduler needs --executor dask", field="--scheduler", fix="add --executor dask"
        )
    if results.exists() and not results.is_dir():
        raise SpringbenchError(
            "exists and is not a folder",
            file=str(results),
            field="--results",
            fix="give a folder for the results",
        )
    try:
        results.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SpringbenchError(
            f"cannot create the results folder ({exc.strerror})",
            file=str(results),
            field="--results",
            fix="give a writable folder",
        )
    clean_stale_scratch()
    with run_lock(results):
        return _run_locked(
            paths,
            mode,
            results,
            jobs_n,
            executor,
            scheduler,
            force,
            figures,
            stages,
            progress,
            collect(),
        )


def _run_locked(
    paths,
    mode,
    results,
    jobs_n,
    executor,
    scheduler,
    force,
    figures,
    stages,
    progress,
    provenance=None,
) -> RunReport:
    planned, failed = plan(list(paths), mode, stages)
    _prune_seeds(results, planned)
    done: list[JobResult] = []
    pending: list[Job] = []
    for job in planned:
        stored = None if force else read_result(result_path(results, job))
        if (
            stored
            and stored.get("status") == "ok"
            and stored.get("input_hash") == job.key
            and code_unchanged(stored.get("code"))
        ):
            done.append(
                JobResult(
                    job, "skipped", stored.get("rows", []), seconds=stored.get("seconds", 0.0)
                )
            )
        else:
            pending.append(job)
    bar = _Progress(len(planned) + len(failed), progress, recorded_seconds(pending, results))
    for res in done:
        bar.done(res.job.label, "unchanged, skipped")
    all_results = list(done)

    def finish(res: JobResult):
        store(results, res, provenance)
        all_results.append(res)
        if res.status == "error":
            bar.write(error_line(res))
        bar.done(
            res.job.label,
            "error" if res.status == "error" else f"{res.status} ({res.seconds:.1f} s)",
        )

    try:
        for res in failed:
            finish(res)
        if pending:
            if executor == "dask":
                _run_dask(pending, scheduler, jobs_n, finish, bar)
            elif jobs_n == 1 or len(pending) == 1:
                for job in pending:
                    bar.set(job.label, "starting")
                    finish(execute(job, bar.set))
            else:
                _run_pool(pending, jobs_n, finish, bar)
    finally:
        bar.close()
    suites = sorted({results / r.job.suite for r in all_results})
    for s in suites:
        report.build_suite(s, figures=figures)
    if suites:
        report.build_index(results)
    order = {j: i for i, j in enumerate([r.job for r in failed] + planned)}
    all_results.sort(key=lambda r: order.get(r.job, 0))
    return RunReport(all_results, suites, results)


def recorded_seconds(jobs: list[Job], results: Path) -> dict[str, float | None]:
    """Each job's seconds as last recorded (None: never): by an earlier run of it in
    ``results`` at the same budgets, else in the quick tier's table (harness/suites.py),
    else in the published results/. The progress line's time left weighs the jobs by
    them; nothing else reads them."""
    tier = quick_seconds()
    out = {}
    for job in jobs:
        own = read_result(result_path(Path(results), job)) or {}
        published = read_result(result_path(Path(DEFAULT_RESULTS), job)) or {}
        found = (
            own.get("seconds") if own.get("mode") == job.mode else None,
            tier.get((job.suite, job.case)) if job.mode == "quick" else None,
            published.get("seconds"),
        )
        out[job.label] = next(
            (float(s) for s in found if isinstance(s, (int, float)) and s > 0), None
        )
    return out


def _run_pool(pending: list[Job], jobs_n: int, finish, bar):
    """Local process pool (spawned workers, one BLAS thread each). If a worker process
    dies (killed, out of memory), every job lost with the pool is retried alone in a
    fresh one-worker pool, so one bad job cannot take the others down; a job whose
    worker dies when alone is recorded as an error."""
    for job in _pool_round(list(pending), jobs_n, finish, bar, last=False):
        _pool_round([job], 1, finish, bar, last=True)


def _pool_round(pending: list[Job], jobs_n: int, finish, bar, last: bool) -> list[Job]:
    import multiprocessing as mp
    from multiprocessing.managers import SyncManager

    ctx = mp.get_context("spawn")
    lost: list[Job] = []
    manager = SyncManager(ctx=ctx)
    manager.start(_ignore_sigint)
    with manager:
        q = manager.Queue()
        sink = QueueSink(q)
        ex = ProcessPoolExecutor(
            max_workers=min(jobs_n, len(pending)), mp_context=ctx, initializer=_init_worker
        )
        try:
            futs = {ex.submit(execute, job, sink): job for job in pending}
            waiting = set(futs)
            while waiting:
                finished, waiting = wait(waiting, timeout=0.3, return_when=FIRST_COMPLETED)
                try:
                    while True:
                        label, msg = q.get_nowait()
                        bar.set(label, msg)
                except (queue_mod.Empty, EOFError, OSError):
                    pass
                for fut in finished:
                    job = futs[fut]
                    try:
                        res = fut.result()
                    except BrokenProcessPool:
                        if not last:
                            lost.append(job)
                            continue
                        msg = "its worker process died (killed, or out of memory?)"
                        res = JobResult(job, "error", [_error_row(job, "case", msg)], error=msg)
                    except Exception as exc:  # e.g. a result that cannot be pickled
                        msg = f"{type(exc).__name__}: {exc}".replace("\n", " ")
                        res = JobResult(
                            job,
                            "error",
                            [_error_row(job, "case", msg)],
                            error=msg,
                            traceback=traceback.format_exc(),
                        )
                    finish(res)
        except BaseException:  # Ctrl-C or a bug here: stop the workers now, keep what finished
            procs = list((getattr(ex, "_processes", None) or {}).values())
            ex.shutdown(wait=False, cancel_futures=True)
            for proc in procs:
                proc.terminate()
            raise
        ex.shutdown(wait=True)
    if lost:
        bar.write(
            f"springbench: warning: a worker process died; retrying {len(lost)} job(s) one "
            "at a time"
        )
    return lost


def _run_dask(pending: list[Job], scheduler: str | None, jobs_n: int, finish, bar):
    """The same jobs on a Dask cluster (``scheduler`` address; none: a LocalCluster).
    A worker that dies is the scheduler's business: it re-runs the lost job on another
    worker up to ``distributed.scheduler.allowed-failures`` times (default 3) and then
    gives up with KilledWorker, which becomes this job's error row; other jobs go on."""
    try:
        from distributed import Client, LocalCluster, wait
    except ImportError:
        raise SpringbenchError(
            "the Dask executor needs dask.distributed",
            field="--executor",
            fix="pip install 'springbench[dask]'",
        )
    cluster = None
    try:
        if scheduler:
            try:
                client = Client(scheduler, timeout=DASK_CONNECT_TIMEOUT)
            except (OSError, TimeoutError, ValueError) as exc:
                raise SpringbenchError(
                    f"cannot connect to the Dask scheduler at {scheduler} ({exc})",
                    field="--scheduler",
                    fix="start one with 'dask scheduler' or check the address",
                )
        else:
            cluster = LocalCluster(n_workers=jobs_n, threads_per_worker=1, processes=True)
            client = Client(cluster)
        topic = f"springbench-status-{uuid.uuid4().hex}"
        latest: dict[str, str] = {}

        def on_event(event):
            _, msg = event
            if isinstance(msg, dict):
                latest[msg.get("label", "?")] = msg.get("msg", "")

        client.subscribe_topic(topic, on_event)
        with client:
            futs = {
                client.submit(
                    execute,
                    job,
                    DaskSink(topic),
                    pure=False,
                    key=f"springbench-{job.label}-{uuid.uuid4().hex[:8]}",
                ): job
                for job in pending
            }
            waiting = set(futs)
            while waiting:
                try:
                    res_wait = wait(list(waiting), timeout=0.5, return_when="FIRST_COMPLETED")
                    finished = res_wait.done
                except TimeoutError:
                    finished = set()
                for label, msg in list(latest.items()):
                    bar.set(label, msg)
                latest.clear()
                for fut in finished:
                    waiting.discard(fut)
                    job = futs[fut]
                    try:
                        res = fut.result()
                    except Exception as exc:  # worker lost, unpicklable result, ...
                        msg = f"{type(exc).__name__}: {exc}".replace("\n", " ")
                        if type(exc).__name__ == "KilledWorker":
                            msg = (
                                "its Dask worker died each time it ran this job (killed, or out "
                                "of memory?); the other jobs went on"
                            )
                        res = JobResult(
                            job,
                            "error",
                            [_error_row(job, "case", msg)],
                            error=msg,
                            traceback=traceback.format_exc(),
                        )
                    finish(res)
    finally:
        if cluster is not None:
            cluster.close()


def run_paths(paths, mode: str = "quick", results: Path = DEFAULT_RESULTS, **kw):
    """Backward-compatible wrapper: ``{suite: DataFrame}`` of the suites touched."""
    import pandas as pd

    rep = run_suite(paths, mode, results, **kw)
    return {
        s.name: pd.read_csv(s / "summary.csv") for s in rep.suites if (s / "summary.csv").exists()
    }
