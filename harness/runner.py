"""Run suites of cases: each (case, seed) through every stage that applies, in parallel,
resumable, and with the same table bit for bit for the same seed and inputs.

- A *job* is one (case file, mode, seed). Its input hash covers the case file's bytes,
  the mode, the seed, the stage list and the mesh file the case references; its code
  version is the SHA-256 of every source file of ``harness/`` and ``reference/`` (and of
  stage modules living elsewhere) that was loaded when the job ran, recorded in the
  manifest. A finished job is skipped while its input hash and each of those files are
  unchanged: editing the report, the figures, the CLI or a module the job never imported
  re-runs nothing, editing anything the job imported re-runs it. (Code is only ever
  reached through imports, so the files a job loaded are all the code it depends on.)
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

import hashlib
import json
import os
import re
import shutil
import sys
import time
import traceback
import uuid
from dataclasses import dataclass, field
from pathlib import Path

from harness.errors import CaseError, SpringbenchError
from harness.runlock import clean_stale_scratch, run_lock, scratch_dir

ROOT = Path(__file__).resolve().parent.parent
# an editable install / checkout runs its own cases/ into its own results/; an installed
# package (no cases/ beside it) uses the current folder's
_HOME = ROOT if (ROOT / "cases").is_dir() else Path.cwd()
DEFAULT_CASES = _HOME / "cases"
DEFAULT_RESULTS = _HOME / "results"   # the published tables: the --full run, committed
DEFAULT_RUNS = _HOME / "runs"         # where a user's runs go by default (git-ignored)
RESULT_PREFIX = "result-seed"
HASH_VERSION = "springbench-job-1"
# loaded sources that cannot change a result (drawing, tables, command-line plumbing)
_NOT_CODE = ("harness/report.py", "harness/figures/", "harness/commands/", "harness/cli.py",
             "harness/bench/")
DASK_CONNECT_TIMEOUT = "15s"
_NAME_OK = re.compile(r"[^A-Za-z0-9._+-]")


# -- jobs and their identity ------------------------------------------------------------

@dataclass(frozen=True)
class Job:
    """One (case file, mode, seed) to run; everything a worker needs, picklable."""
    case_file: str
    mode: str
    seed: int
    suite: str
    case: str          # folder name under results/<suite>/
    n_seeds: int
    key: str           # input hash
    stages: tuple[str, ...]
    rel_file: str = ""  # the case file as shown in tables and messages
    expect: dict = field(default_factory=dict, hash=False, compare=False)

    @property
    def label(self) -> str:
        return self.case if self.n_seeds == 1 else f"{self.case}#{self.seed}"


@dataclass
class JobResult:
    """What a job produced: rows, data files (relative name -> bytes), error text."""
    job: Job
    status: str                      # "ok" | "error" | "skipped" (finished earlier)
    rows: list[dict]
    files: dict[str, bytes] = field(default_factory=dict)
    error: str = ""
    traceback: str = ""
    seconds: float = 0.0
    log: str = ""                    # path of the traceback log, if any
    code: dict = field(default_factory=dict)  # {source file: sha256} the job loaded


_SHA_CACHE: dict[tuple, str] = {}


def file_sha(path: Path) -> str | None:
    """SHA-256 of a file (cached by path, size and mtime); None if it is gone."""
    try:
        st = path.stat()
    except OSError:
        return None
    key = (str(path), st.st_size, st.st_mtime_ns)
    if key not in _SHA_CACHE:
        _SHA_CACHE[key] = hashlib.sha256(path.read_bytes()).hexdigest()
    return _SHA_CACHE[key]


def loaded_sources(stage_modules=()) -> dict[str, str]:
    """{file: sha256} of the code this process has loaded that a result can depend on:
    modules under ``harness/`` and ``reference/`` (paths relative to the checkout) and the
    stage modules (absolute paths when they live elsewhere)."""
    out = {}
    roots = (ROOT / "harness", ROOT / "reference")
    for name, mod in list(sys.modules.items()):
        f = getattr(mod, "__file__", None)
        if not f or not f.endswith(".py"):
            continue
        p = Path(f).resolve()
        inside = any(p.is_relative_to(r) for r in roots)
        if inside or name in stage_modules:
            key = p.relative_to(ROOT).as_posix() if inside else str(p)
            if any(key.startswith(n) if n.endswith("/") else key == n for n in _NOT_CODE):
                continue
            sha = file_sha(p)
            if sha:
                out[key] = sha
    return dict(sorted(out.items()))


def code_unchanged(code: dict) -> bool:
    """True if every recorded source file still has its recorded hash."""
    if not isinstance(code, dict) or not code:
        return False
    for key, sha in code.items():
        p = Path(key) if Path(key).is_absolute() else ROOT / key
        if file_sha(p) != sha:
            return False
    return True


def input_hash(case, seed: int, stages) -> str:
    """Hash of everything but the code that determines a job's result."""
    h = hashlib.sha256(HASH_VERSION.encode())
    for part in (case.mode, str(seed), "\0".join(stages)):
        h.update(part.encode() + b"\0")
    h.update(Path(case.path).read_bytes())
    if case.body.shape == "mesh" and case.body.file is not None:
        h.update(b"\0mesh\0" + Path(case.body.file).read_bytes())
    return h.hexdigest()


def safe_name(name: str, file: str) -> str:
    """The results folder name of a case: a path-like name (``../x``, ``/x``, ``a/b``) is
    rejected; other unusual characters (spaces, ...) become ``_``."""
    if (not name or "/" in name or "\\" in name or name.startswith(".") or Path(name).is_absolute()
            or "\0" in name or len(name) > 120):
        raise CaseError(f"'{name}' cannot name a results folder", file=file, field="name",
                        fix="use letters, digits, '-', '_' and '.', not a path")
    return _NAME_OK.sub("_", name)


def parse_seeds(case, file: str) -> list[int]:
    """``[run] seeds``: an integer or a list of distinct non-negative integers."""
    run = case.section("run") or {}
    seeds = run.get("seeds", [0])
    if isinstance(seeds, int) and not isinstance(seeds, bool):
        seeds = [seeds]
    if (not isinstance(seeds, (list, tuple)) or not seeds
            or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in seeds)):
        raise CaseError(f"expected a non-negative integer or a non-empty list of them, got {seeds!r}",
                        file=file, field="run.seeds", fix="e.g. seeds = [0, 1, 2]")
    if len(set(seeds)) != len(seeds):
        raise CaseError("repeated seed", file=file, field="run.seeds", fix="list each seed once")
    return list(seeds)


def _jsonable(v):
    """Row values as plain JSON scalars (numpy scalars unwrapped, sequences joined)."""
    if hasattr(v, "item") and getattr(v, "ndim", 1) == 0:
        v = v.item()
    if v is None or isinstance(v, (bool, int, str)):
        return v
    if isinstance(v, float):
        return v
    if isinstance(v, Path):
        return str(v)
    if isinstance(v, (list, tuple)) or hasattr(v, "tolist"):
        items = list(v.tolist() if hasattr(v, "tolist") else v)
        if all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in items):
            return ":".join(f"{x:g}" for x in items)
        return json.dumps([_jsonable(x) for x in items])
    if isinstance(v, dict):
        return json.dumps({str(k): _jsonable(x) for k, x in v.items()}, sort_keys=True)
    return str(v)


def _plain(obj):
    """MappingProxy/tuples from a case section -> plain JSON data."""
    if isinstance(obj, dict) or hasattr(obj, "items"):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    return obj


# -- planning ---------------------------------------------------------------------------

def _rel(path: Path) -> str:
    try:
        return os.path.relpath(path)
    except ValueError:
        return str(path)


def plan(paths, mode: str, stages=None) -> tuple[list[Job], list[JobResult]]:
    """Case files -> jobs (one per seed); case files that do not load become error results."""
    from harness import stages as stage_registry
    from harness.cases import find_cases, load_case

    stage_names = tuple(stage_registry.STAGES if stages is None else stages)
    files, seen = [], set()
    for given in find_cases(paths or [DEFAULT_CASES]):
        r = Path(given).resolve()
        if r not in seen:
            seen.add(r)
            files.append((Path(given), r))
    jobs, failed = [], []
    used: dict[tuple[str, str], str] = {}
    for given, f in files:
        suite = _NAME_OK.sub("_", f.parent.name) or "cases"
        rel = str(given)
        try:
            case = load_case(given, mode)
            name = safe_name(case.name, rel)
            if (suite, name) in used:
                raise CaseError(f"name '{case.name}' is also used by {used[suite, name]} in suite {suite}",
                                file=rel, field="name", fix="give each case of a suite its own name")
            used[suite, name] = rel
            seeds = parse_seeds(case, rel)
        except SpringbenchError as exc:
            job = Job(str(f), mode, 0, suite, safe_stem(f), 1, "", stage_names, rel)
            failed.append(JobResult(job, "error", [_error_row(job, "case", str(exc))], error=str(exc)))
            continue
        expect = _plain((case.section("expect") or {}).get("values", {}))
        for seed in seeds:
            jobs.append(Job(str(f), mode, seed, suite, name, len(seeds),
                            input_hash(case, seed, stage_names), stage_names, rel,
                            expect if isinstance(expect, dict) else {}))
    return jobs, failed


def safe_stem(f: Path) -> str:
    return _NAME_OK.sub("_", f.stem).lstrip(".") or "case"


def _error_row(job: Job, stage: str, message: str, seconds: float = 0.0) -> dict:
    return {"case": job.case, "model": "", "stage": stage, "seed": job.seed, "status": "error",
            "seconds": seconds, "error": message}


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
    import random
    random.seed(seed)
    try:
        import numpy as np
        np.random.seed(seed % 2**32)
    except ImportError:  # pragma: no cover
        pass


def execute(job: Job, sink=None) -> JobResult:
    """Run one job in a fresh temporary folder; never raises."""
    from harness.cases import load_case
    from harness.stages import StageContext, load_stages

    t_job = time.perf_counter()
    status = _Throttled(sink, job.label)
    tmp = scratch_dir()
    stage_name = "case"
    try:
        case = load_case(job.case_file, job.mode)
        modules = load_stages(list(job.stages))
        wanted = tuple((case.section("run") or {}).get("stages", ()))
        names = [m.NAME for m in modules]
        unknown = [w for w in wanted if w not in names]
        if unknown:
            raise CaseError(f"unknown stage '{unknown[0]}'", file=job.rel_file, field="run.stages",
                            fix=f"available: {', '.join(names) or 'none'}")
        rows = []
        for stage in modules:
            stage_name = stage.NAME
            if (wanted and stage.NAME not in wanted) or not stage.applies(case):
                continue
            _seed_everything(job.seed)
            ctx = StageContext(out_dir=tmp, mode=job.mode, seed=job.seed, status=status,
                               n_seeds=job.n_seeds)
            status(f"{stage.NAME}")
            t0 = time.perf_counter()
            out = stage.run(case, ctx) or []
            dt = time.perf_counter() - t0
            for row in out:
                row = dict(row)
                row["case"] = job.case
                row.setdefault("model", "")
                row.setdefault("stage", stage.NAME)
                row.setdefault("seed", job.seed)
                row.setdefault("status", "ok")
                row.setdefault("seconds", dt)
                rows.append({str(k): _jsonable(v) for k, v in row.items()})
        if not rows:
            rows = [{"case": job.case, "model": "", "stage": "", "seed": job.seed,
                     "status": "no stage applies"}]
        files = {}
        for f in sorted(tmp.rglob("*")):
            if f.is_file() and not f.is_symlink():
                files[f.relative_to(tmp).as_posix()] = f.read_bytes()
        return JobResult(job, "ok", rows, files, seconds=time.perf_counter() - t_job,
                         code=loaded_sources(job.stages))
    except SpringbenchError as exc:
        msg = str(exc).replace(job.case_file, job.rel_file or job.case_file)
        dt = time.perf_counter() - t_job
        return JobResult(job, "error", [_error_row(job, stage_name, msg, dt)], error=msg, seconds=dt)
    except Exception as exc:  # a bug, not bad input: one line here, the traceback in a log
        msg = f"{type(exc).__name__}: {exc}".replace("\n", " ")
        if len(msg) > 300:
            msg = msg[:297] + "..."
        dt = time.perf_counter() - t_job
        return JobResult(job, "error", [_error_row(job, stage_name, msg, dt)], error=msg,
                         traceback=traceback.format_exc(), seconds=dt)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _ignore_sigint():
    """Ctrl-C is the parent's business: it stops the workers itself, without their tracebacks."""
    import signal
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _init_worker():
    """Pool initializer: one BLAS thread per worker (the pool is the parallelism); Ctrl-C
    handled by the parent."""
    _ignore_sigint()
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
        os.environ.setdefault(var, "1")


# -- storing results ---------------------------------------------------------------------

def atomic_write(path: Path, data: bytes):
    """Write ``data`` to ``path`` so readers see the old file or the new one, never half."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp")
    try:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


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


def store(results: Path, res: JobResult) -> Path:
    """Write a job's data files, then its result file (the 'finished' marker)."""
    job = res.job
    out = data_dir(results, job)
    root = out.resolve()
    old = read_result(result_path(results, job)) or {}
    for name, data in res.files.items():
        target = (out / name)
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
        "case": job.case, "suite": job.suite, "file": job.rel_file, "mode": job.mode,
        "seed": job.seed, "n_seeds": job.n_seeds, "input_hash": job.key, "status": res.status,
        "error": res.error, "log": log, "stages": list(job.stages), "expect": job.expect,
        "files": sorted(res.files), "data_dir": "." if job.n_seeds == 1 else f"seed{job.seed}",
        "seconds": res.seconds, "code": res.code, "rows": res.rows,
    }
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


class _Progress:
    """One tqdm bar for the suite on a terminal; the postfix shows the latest status of
    the running jobs. Without a terminal (CI logs, pipes) one line per finished job on
    stdout instead. ``enabled`` None: decide by the terminal."""

    def __init__(self, total: int, enabled):
        import shutil
        from tqdm import tqdm
        tty = sys.stderr.isatty() if enabled is None else bool(enabled)
        size = shutil.get_terminal_size((0, 0))  # a pty without a size (0 x 0) hides tqdm bars
        self.bar = tqdm(total=total, desc="suite", unit="case", file=sys.stderr, disable=not tty,
                        dynamic_ncols=size.columns > 0, ncols=None if size.columns > 0 else 100,
                        nrows=None if size.lines > 0 else 24)
        self.lines = enabled is None and not tty
        self.total, self.n = total, 0
        self.status: dict[str, str] = {}

    def set(self, label: str, msg: str):
        self.status[label] = msg
        self._show()

    def done(self, label: str, what: str = ""):
        self.status.pop(label, None)
        self.n += 1
        self.bar.update(1)
        self._show()
        if self.lines and what:
            print(f"[{self.n}/{self.total}] {label}: {what}", flush=True)

    def _show(self):
        text = "; ".join(f"{k}: {v}" for k, v in list(self.status.items())[-3:])
        self.bar.set_postfix_str(text[:120], refresh=True)

    def write(self, line: str):
        self.bar.write(line, file=sys.stderr)

    def close(self):
        self.bar.close()


def error_line(res: JobResult) -> str:
    """The one line that reports a failed job (its file is named once)."""
    where = "" if res.job.rel_file and res.job.rel_file in res.error else f"{res.job.rel_file or res.job.label}: "
    if res.job.n_seeds > 1:
        where += f"seed {res.job.seed}: "
    extra = f" (traceback in {res.log})" if res.log else ""
    return f"springbench: error: {where}{res.error}{extra}"


def _default_jobs() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover
        return os.cpu_count() or 1


def run_suite(paths=(), mode: str = "quick", results: Path | None = None, *, jobs: int | None = None,
              executor: str = "local", scheduler: str | None = None, force: bool = False,
              figures: bool = True, stages=None, progress=None) -> RunReport:
    """Run case files / suites; write results, tables, figures and the index.

    ``stages`` overrides ``harness.stages.STAGES`` (module names); ``progress`` None
    shows the bar only on a terminal."""
    results = Path(results or DEFAULT_RESULTS)
    jobs_n = jobs or _default_jobs()
    if jobs_n < 1:
        raise SpringbenchError(f"--jobs {jobs_n}: must be at least 1", field="--jobs", fix="e.g. --jobs 2")
    if executor not in ("local", "dask"):
        raise SpringbenchError(f"unknown executor '{executor}'", field="--executor", fix="local or dask")
    if scheduler and executor != "dask":
        raise SpringbenchError("--scheduler needs --executor dask", field="--scheduler",
                               fix="add --executor dask")
    if results.exists() and not results.is_dir():
        raise SpringbenchError("exists and is not a folder", file=str(results), field="--results",
                               fix="give a folder for the results")
    try:
        results.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SpringbenchError(f"cannot create the results folder ({exc.strerror})", file=str(results),
                               field="--results", fix="give a writable folder")
    clean_stale_scratch()
    with run_lock(results):
        return _run_locked(paths, mode, results, jobs_n, executor, scheduler, force, figures, stages, progress)


def _run_locked(paths, mode, results, jobs_n, executor, scheduler, force, figures, stages, progress) -> RunReport:
    planned, failed = plan(list(paths), mode, stages)
    _prune_seeds(results, planned)
    done: list[JobResult] = []
    pending: list[Job] = []
    for job in planned:
        stored = None if force else read_result(result_path(results, job))
        if (stored and stored.get("status") == "ok" and stored.get("input_hash") == job.key
                and code_unchanged(stored.get("code"))):
            done.append(JobResult(job, "skipped", stored.get("rows", []), seconds=stored.get("seconds", 0.0)))
        else:
            pending.append(job)
    bar = _Progress(len(planned) + len(failed), progress)
    for res in done:
        bar.done(res.job.label, "unchanged, skipped")
    all_results = list(done)

    def finish(res: JobResult):
        store(results, res)
        all_results.append(res)
        if res.status == "error":
            bar.write(error_line(res))
        bar.done(res.job.label, "error" if res.status == "error" else f"{res.status} ({res.seconds:.1f} s)")

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
    from harness import report
    for s in suites:
        report.build_suite(s, figures=figures)
    if suites:
        report.build_index(results)
    order = {j: i for i, j in enumerate([r.job for r in failed] + planned)}
    all_results.sort(key=lambda r: order.get(r.job, 0))
    return RunReport(all_results, suites, results)


def _run_pool(pending: list[Job], jobs_n: int, finish, bar):
    """Local process pool (spawned workers, one BLAS thread each). If a worker process
    dies (killed, out of memory), every job lost with the pool is retried alone in a
    fresh one-worker pool, so one bad job cannot take the others down; a job whose
    worker dies when alone is recorded as an error."""
    for job in _pool_round(list(pending), jobs_n, finish, bar, last=False):
        _pool_round([job], 1, finish, bar, last=True)


def _pool_round(pending: list[Job], jobs_n: int, finish, bar, last: bool) -> list[Job]:
    import multiprocessing as mp
    import queue as queue_mod
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    from multiprocessing.managers import SyncManager

    ctx = mp.get_context("spawn")
    lost: list[Job] = []
    manager = SyncManager(ctx=ctx)
    manager.start(_ignore_sigint)
    with manager:
        q = manager.Queue()
        sink = QueueSink(q)
        ex = ProcessPoolExecutor(max_workers=min(jobs_n, len(pending)), mp_context=ctx,
                                 initializer=_init_worker)
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
                        res = JobResult(job, "error", [_error_row(job, "case", msg)], error=msg,
                                        traceback=traceback.format_exc())
                    finish(res)
        except BaseException:  # Ctrl-C or a bug here: stop the workers now, keep what finished
            procs = list((getattr(ex, "_processes", None) or {}).values())
            ex.shutdown(wait=False, cancel_futures=True)
            for proc in procs:
                proc.terminate()
            raise
        ex.shutdown(wait=True)
    if lost:
        bar.write(f"springbench: warning: a worker process died; retrying {len(lost)} job(s) one at a time")
    return lost


def _run_dask(pending: list[Job], scheduler: str | None, jobs_n: int, finish, bar):
    """The same jobs on a Dask cluster (``scheduler`` address; none: a LocalCluster).
    A worker that dies is the scheduler's business: it re-runs the lost job on another
    worker up to ``distributed.scheduler.allowed-failures`` times (default 3) and then
    gives up with KilledWorker, which becomes this job's error row; other jobs go on."""
    try:
        from distributed import Client, LocalCluster, wait
    except ImportError:
        raise SpringbenchError("the Dask executor needs dask.distributed", field="--executor",
                               fix="pip install 'springbench[dask]'")
    cluster = None
    try:
        if scheduler:
            try:
                client = Client(scheduler, timeout=DASK_CONNECT_TIMEOUT)
            except (OSError, TimeoutError, ValueError) as exc:
                raise SpringbenchError(f"cannot connect to the Dask scheduler at {scheduler} ({exc})",
                                       field="--scheduler",
                                       fix="start one with 'dask scheduler' or check the address")
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
            futs = {client.submit(execute, job, DaskSink(topic), pure=False,
                                  key=f"springbench-{job.label}-{uuid.uuid4().hex[:8]}"): job
                    for job in pending}
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
                            msg = ("its Dask worker died each time it ran this job (killed, or out "
                                   "of memory?); the other jobs went on")
                        res = JobResult(job, "error", [_error_row(job, "case", msg)], error=msg,
                                        traceback=traceback.format_exc())
                    finish(res)
    finally:
        if cluster is not None:
            cluster.close()


def run_paths(paths, mode: str = "quick", results: Path = DEFAULT_RESULTS, **kw):
    """Backward-compatible wrapper: ``{suite: DataFrame}`` of the suites touched."""
    import pandas as pd
    rep = run_suite(paths, mode, results, **kw)
    return {s.name: pd.read_csv(s / "summary.csv") for s in rep.suites if (s / "summary.csv").exists()}
