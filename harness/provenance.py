"""Which code and which machine produced a number (asv records the same with every result):
the results format version, the git commit and whether the tree was dirty, the versions of
Python and of the libraries the numbers depend on, the CPU model, its core count and the
load average when the work started.

``collect()`` is called once when a run or a benchmark starts; ``springbench run`` stores
it in every result file it writes and each suite folder's ``provenance.json`` gathers
those of its cases (harness/report/build.py); ``springbench bench`` adds it to every row
of its CSV as the columns of FIELDS. ``describe()`` is the one line the report shows; a
value that was never recorded (results older than this) reads "not recorded". A result
the engines stage made also records ENGINE_VERSIONS, the installed version of every engine
package (``with_engines``; None where not installed): an engine's numbers are its package's.
"""

from __future__ import annotations

import os
import platform
import subprocess
from importlib import metadata
from pathlib import Path

from harness import __version__
from harness.paths import ROOT
from harness.registry import ENGINES, PIP_NAMES

FORMAT_VERSION = 1  # of result files, summaries and bench CSVs; raise it when their meaning changes
LIBRARIES = {
    "numpy_version": "numpy",
    "scipy_version": "scipy",
    "skfem_version": "scikit-fem",
    "pandas_version": "pandas",
}
FIELDS = (
    "format_version",
    "springbench_version",
    "git_commit",
    "git_dirty",
    "python_version",
    *LIBRARIES,
    "cpu_model",
    "cpu_cores",
    "load_average",
)
ENGINE_VERSIONS = "engine_versions"  # {pip name: version or None} of the engine packages
NOT_RECORDED = "not recorded"
# what a dirty tree means: changed code or cases, not the outputs of runs (results/, runs/)
OUTPUTS = ("results", "runs")


def collect(root: Path | None = None) -> dict:
    """The provenance of work starting now (FIELDS; None where unknown)."""

    commit, dirty = git_state(Path(root or ROOT))
    out = {
        "format_version": FORMAT_VERSION,
        "springbench_version": __version__,
        "git_commit": commit,
        "git_dirty": dirty,
        "python_version": platform.python_version(),
    }
    for key, dist in LIBRARIES.items():
        out[key] = version(dist)
    try:
        load = round(os.getloadavg()[0], 2)
    except OSError:  # pragma: no cover - no load average on this system
        load = None
    out.update(cpu_model=cpu_model(), cpu_cores=os.cpu_count(), load_average=load)
    return out


def version(dist: str) -> str | None:
    """The installed version of the distribution ``dist`` (None when not installed)."""
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def engine_packages() -> tuple[str, ...]:
    """The pip names of the engine packages: each engine's (registry ENGINES.about) and
    those PIP_NAMES names besides (warp, which Newton runs on)."""
    imports = dict.fromkeys([about[0] for about in ENGINES.about.values()] + list(PIP_NAMES))
    return tuple(PIP_NAMES.get(name, name) for name in imports)


def with_engines(p: dict) -> dict:
    """``p`` and ENGINE_VERSIONS: the installed version of every engine package."""
    return {**p, ENGINE_VERSIONS: {dist: version(dist) for dist in engine_packages()}}


def git_state(root: Path) -> tuple[str | None, bool | None]:
    """(HEAD's commit, whether tracked or untracked files outside OUTPUTS differ from it);
    (None, None) outside a git checkout or without git."""

    def git(*args):
        return subprocess.run(
            ["git", "-C", str(root), *args], capture_output=True, text=True, timeout=30
        )

    try:
        head = git("rev-parse", "HEAD")
        if head.returncode != 0:
            return None, None
        status = git("status", "--porcelain", "--", ".", *[f":(exclude){o}" for o in OUTPUTS])
    except (OSError, subprocess.SubprocessError):
        return None, None
    return head.stdout.strip(), (bool(status.stdout.strip()) if status.returncode == 0 else None)


def cpu_model() -> str | None:
    """The CPU's model name (Linux: /proc/cpuinfo; else what platform knows)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            if key.strip() in ("model name", "Hardware", "Processor") and value.strip():
                return value.strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or None


def describe(p: dict | None) -> str:
    """One line: commit (clean / dirty), library versions, CPU, cores, load at start and
    the engine packages' versions where recorded; "not recorded" for what is missing."""
    p = p or {}

    def get(key):
        v = p.get(key)
        return NOT_RECORDED if v is None or v != v or v == "" else v  # NaN: a CSV's empty cell

    # every record has it: without it, nothing was recorded
    if get("format_version") == NOT_RECORDED:
        return NOT_RECORDED
    commit = get("git_commit")
    dirty = p.get("git_dirty")
    state = (
        ""
        if commit == NOT_RECORDED
        else (
            " (dirty tree)"
            if str(dirty).lower() in ("true", "1")
            else " (clean tree)"
            if str(dirty).lower() in ("false", "0")
            else ""
        )
    )
    libs = ", ".join(f"{dist} {get(key)}" for key, dist in LIBRARIES.items())
    return (
        f"format {get('format_version')}, springbench {get('springbench_version')}, commit "
        f"{str(commit)[:12]}{state}; Python {get('python_version')}, {libs}; CPU "
        f"{get('cpu_model')}, "
        f"{get('cpu_cores')} cores, load average {get('load_average')} at start"
        f"{engines_part(p.get(ENGINE_VERSIONS))}"
    )


def engines_part(versions) -> str:
    """The report line's engine part: "; engines newton 1.8.0, drake not installed, ..."
    ('' when not recorded)."""
    if not isinstance(versions, dict):
        return ""
    return "; engines " + ", ".join(f"{d} {v or 'not installed'}" for d, v in versions.items())


def columns(p: dict) -> dict:
    """The FIELDS of ``p`` as CSV columns (the bench CSVs)."""
    return {k: p.get(k) for k in FIELDS}
