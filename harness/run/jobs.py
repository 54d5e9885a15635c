"""Jobs of a run and their identity: one (case file, mode, seed), its input hash and the
code version it ran with (harness/run/runner.py tells the whole story); planning a suite."""

from __future__ import annotations

import hashlib
import json
import os
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

from harness.case.reader import find_cases, load_case
from harness.errors import CaseError, SpringbenchError
from harness.paths import DEFAULT_CASES, ROOT
from harness.sources import file_sha, relative
from harness.stages import stage_modules

HASH_VERSION = "springbench-job-1"
# loaded sources that cannot change a result (drawing, tables, command-line plumbing)
_NOT_CODE = (
    "harness/report/",
    "harness/outputs.py",
    "harness/paths.py",
    "harness/commands/",
    "harness/cli.py",
    "harness/bench/",
)
_NAME_OK = re.compile(r"[^A-Za-z0-9._+-]")


# -- jobs and their identity ------------------------------------------------------------


@dataclass(frozen=True)
class Job:
    """One (case file, mode, seed) to run; everything a worker needs, picklable."""

    case_file: str
    mode: str
    seed: int
    suite: str
    case: str  # folder name under results/<suite>/
    n_seeds: int
    key: str  # input hash
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
    status: str  # "ok" | "error" | "skipped" (finished earlier)
    rows: list[dict]
    files: dict[str, bytes] = field(default_factory=dict)
    error: str = ""
    traceback: str = ""
    seconds: float = 0.0
    log: str = ""  # path of the traceback log, if any
    code: dict = field(default_factory=dict)  # {source file: sha256} the job loaded


# what a stage whose commands run in their own processes depends on besides (SUBPROCESS_CODE)
_NOT_SUBPROCESS_CODE = ("harness/report/", "harness/bench/")


def loaded_sources(stage_modules=(), everything: bool = False) -> dict[str, str]:
    """{file: sha256} of the code this process has loaded that a result can depend on:
    modules under ``harness/`` and ``reference/`` (paths relative to the checkout) and the
    stage modules (absolute paths when they live elsewhere). ``everything``: a stage that
    ran says ``SUBPROCESS_CODE = True`` (it runs springbench commands in their own
    processes, whose imports this process never sees): every source file under both."""
    out = {}
    roots = (ROOT / "harness", ROOT / "reference")
    if everything:
        for p in sorted(q for r in roots for q in r.rglob("*.py")):
            key = relative(p)
            if not key.startswith(_NOT_SUBPROCESS_CODE) and (sha := file_sha(p)):
                out[key] = sha
    for name, mod in list(sys.modules.items()):
        f = getattr(mod, "__file__", None)
        if not f or not f.endswith(".py"):
            continue
        p = Path(f).resolve()
        inside = any(p.is_relative_to(r) for r in roots)
        if inside or name in stage_modules:
            key = relative(p)
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
    if (
        not name
        or "/" in name
        or "\\" in name
        or name.startswith(".")
        or Path(name).is_absolute()
        or "\0" in name
        or len(name) > 120
    ):
        raise CaseError(
            f"'{name}' cannot name a results folder",
            file=file,
            field="name",
            fix="use letters, digits, '-', '_' and '.', not a path",
        )
    return _NAME_OK.sub("_", name)


def parse_seeds(case, file: str) -> list[int]:
    """``[run] seeds``: an integer or a list of distinct non-negative integers."""
    run = case.section("run") or {}
    seeds = run.get("seeds", [0])
    if isinstance(seeds, int) and not isinstance(seeds, bool):
        seeds = [seeds]
    if (
        not isinstance(seeds, (list, tuple))
        or not seeds
        or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in seeds)
    ):
        raise CaseError(
            f"expected a non-negative integer or a non-empty list of them, got {seeds!r}",
            file=file,
            field="run.seeds",
            fix="e.g. seeds = [0, 1, 2]",
        )
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

    stage_names = stage_modules() if stages is None else tuple(stages)
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
                raise CaseError(
                    f"name '{case.name}' is also used by {used[suite, name]} in suite {suite}",
                    file=rel,
                    field="name",
                    fix="give each case of a suite its own name",
                )
            used[suite, name] = rel
            seeds = parse_seeds(case, rel)
        except SpringbenchError as exc:
            job = Job(str(f), mode, 0, suite, safe_stem(f), 1, "", stage_names, rel)
            failed.append(
                JobResult(job, "error", [_error_row(job, "case", str(exc))], error=str(exc))
            )
            continue
        expect = _plain((case.section("expect") or {}).get("values", {}))
        for seed in seeds:
            jobs.append(
                Job(
                    str(f),
                    mode,
                    seed,
                    suite,
                    name,
                    len(seeds),
                    input_hash(case, seed, stage_names),
                    stage_names,
                    rel,
                    expect if isinstance(expect, dict) else {},
                )
            )
    return jobs, failed


def safe_stem(f: Path) -> str:
    return _NAME_OK.sub("_", f.stem).lstrip(".") or "case"


def _error_row(job: Job, stage: str, message: str, seconds: float = 0.0) -> dict:
    return {
        "case": job.case,
        "model": "",
        "stage": stage,
        "seed": job.seed,
        "status": "error",
        "seconds": seconds,
        "error": message,
    }
