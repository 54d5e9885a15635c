"""Outputs that cannot be written: ``--out`` into a read-only folder, onto an
existing folder, under a file, and a disk that fills up, for build, score, reference,
calibrate, bench, run and report. Each is exit 2 and one line naming the user's path (never
a temporary file) and what to do, and nothing is half-written: the old file stays, no
temporary file is left, finished results of a run are kept.

Read-only and disk-full run twice: on the real thing where this machine allows it (a
read-only bind mount / a 1 MiB tmpfs when root with mount rights; chmod when not root) and
simulated (tests/fs_faults.py: the writes under the folder raise EROFS / ENOSPC), the
fallback a CI machine without mount rights takes; never skipped."""

from __future__ import annotations

from pathlib import Path

import pytest

from harness import cli
from tests.fakestage import write_case
from tests.fs_faults import disk_full, read_only

pytestmark = pytest.mark.usefixtures("cache")  # the reference cache of the ``made`` inputs

FILE_OUT = {"build": "net.vtu", "score": "g.csv", "reference": "u.csv", "calibrate": "m.vtu"}


def argv(cmd: str, made: Path, out: Path) -> list[str]:
    return {
        "build": ["build", made / "tiny.toml", "--out", out],
        "score": ["score", made / "net.vtu", made / "tiny.toml", "--out", out],
        "reference": [
            "reference",
            made / "tiny.toml",
            "--points",
            made / "points.csv",
            "--out",
            out,
        ],
        "calibrate": [
            "calibrate",
            made / "cube.vtu",
            "--E",
            "1e5",
            "--nu",
            "0.3",
            "--method",
            "rule",
            "--heldout",
            "none",
            "--out",
            out,
        ],
        "bench": ["bench", "reference", "--quick", "--out", out],
    }[cmd]


def one_error(code, capsys, *must) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("springbench")]
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    line = lines[0]
    assert ".part" not in line and "springbench-" not in line, line  # never a temporary file
    assert all(m in line for m in must), (must, line)
    return line


def leftovers(folder: Path) -> list[str]:
    return sorted(
        p.name for p in Path(folder).rglob("*") if ".part" in p.name or p.name.endswith(".tmp")
    )


def run(argv_):
    try:
        return cli.main([str(a) for a in argv_])
    except SystemExit as exc:
        return exc.code


# -- read-only ----------------------------------------------------------------------------

READ_ONLY = ["build", "score", "reference", "calibrate", "bench", "run", "report"]


@pytest.mark.parametrize("simulate", [False, True], ids=["real", "simulated"])
@pytest.mark.parametrize("cmd", READ_ONLY)
def test_read_only_folder(cmd, simulate, made, tmp_path, capsys, fake):
    """The real case is a read-only bind mount (root) or chmod 555 (not root)."""
    ro = tmp_path / "ro"
    if cmd in ("run", "report"):
        suite = tmp_path / "cases" / "demo"
        write_case(suite, "a", "rows=1")
        assert run(["run", suite, "--results", ro, "--jobs", 1, "--no-figures"]) == 0
        target = ro / "demo" / "summary.csv"
        before = target.read_bytes()
        args = (
            ["run", suite, "--results", ro, "--jobs", 1, "--no-figures", "--force"]
            if cmd == "run"
            else ["report", ro / "demo", "--no-figures"]
        )
        # a stale table: report has something to write (it leaves current files alone)
        if cmd == "report":
            (ro / "demo" / "summary.md").write_text("stale\n")
    else:
        ro.mkdir()
        target, before = (ro / FILE_OUT.get(cmd, "b")), None
        args = argv(cmd, made, target)
    capsys.readouterr()
    with read_only(ro, simulate) as how:
        code = run(args)
    line = one_error(code, capsys, str(ro))
    assert "read-only" in line or "permission denied" in line, (how.method, line)
    assert (target.read_bytes() == before) if before is not None else not target.exists()
    assert leftovers(ro) == []


# -- a folder in the way, a file where a folder goes ----------------------------------------


@pytest.mark.parametrize("cmd", ["build", "score", "reference", "calibrate"])
def test_out_is_an_existing_folder(cmd, made, tmp_path, capsys):
    out = tmp_path / FILE_OUT[cmd]
    out.mkdir()
    one_error(run(argv(cmd, made, out)), capsys, str(out), "--out", "is a folder")
    assert out.is_dir() and not any(out.iterdir())


def test_bench_out_is_a_file(made, tmp_path, capsys):
    out = tmp_path / "bench.csv"
    out.write_text("old")
    one_error(run(argv("bench", made, out)), capsys, str(out), "--out", "not a folder")
    assert out.read_text() == "old"


@pytest.mark.parametrize("cmd", ["build", "score", "reference", "calibrate", "bench"])
def test_out_under_a_file(cmd, made, tmp_path, capsys):
    (tmp_path / "afile").write_text("old")
    out = tmp_path / "afile" / FILE_OUT.get(cmd, "b")
    one_error(run(argv(cmd, made, out)), capsys, str(tmp_path / "afile"), "--out", "not a folder")
    assert (tmp_path / "afile").read_text() == "old"


@pytest.mark.parametrize("cmd", ["build", "score", "reference", "calibrate"])
def test_out_into_a_missing_folder_creates_it(cmd, made, tmp_path, capsys):
    """Not a mistake: missing folders are made (so the catalogue does not count these)."""
    out = tmp_path / "new" / "deeper" / FILE_OUT[cmd]
    assert run(argv(cmd, made, out)) == 0, capsys.readouterr().err
    assert out.is_file() and leftovers(tmp_path) == []


# -- disk full ------------------------------------------------------------------------------


@pytest.mark.parametrize("simulate", [False, True], ids=["real", "simulated"])
@pytest.mark.parametrize("cmd", ["build", "score", "reference", "calibrate"])
def test_disk_full_keeps_the_old_file(cmd, simulate, made, tmp_path, capsys):
    """The disk fills while the result is written: one line naming the user's file and
    'disk full'; the file from before is untouched, no part of the new one is left."""
    folder = tmp_path / "disk"
    out = folder / FILE_OUT[cmd]
    siblings = [out] + (
        [out.with_suffix(".json"), out.with_suffix(".csv")] if cmd == "calibrate" else []
    )
    with disk_full(folder, simulate) as disk:
        for f in siblings:
            f.write_text("old")
        disk.fill(0)
        line = one_error(run(argv(cmd, made, out)), capsys, str(out), "disk full", "free space")
        assert all(f.read_text() == "old" for f in siblings), (disk.method, line)
        assert leftovers(folder) == []


@pytest.mark.parametrize("simulate", [False, True], ids=["real", "simulated"])
def test_disk_full_during_a_run_loses_no_finished_case(simulate, tmp_path, capsys, fake):
    """Two cases finish; one is edited and re-run onto a disk with one free page (the run's
    lock takes it): the store fails with one line, exit 2; every stored file is whole (the
    edited case's old result included) and nothing half-written is left; once there is
    space again the run recomputes only the edited case."""
    import json

    suite = tmp_path / "cases" / "demo"
    write_case(suite, "a", "rows=1")
    write_case(suite, "b", "rows=2 files=1")
    res = tmp_path / "results"
    args = ["run", suite, "--results", res, "--jobs", 1, "--no-figures"]
    with disk_full(res, simulate) as disk:
        assert run(args) == 0
        stored = {
            p: p.read_bytes()
            for p in res.rglob("*")
            if p.is_file() and not p.name.startswith(".filler")
        }
        write_case(suite, "b", "rows=3 files=1")
        capsys.readouterr()
        disk.fill(1)
        one_error(run(args), capsys, str(res), "disk full")
        assert leftovers(res) == [] and not (res / ".springbench.lock").exists()
        for p, data in stored.items():
            assert p.read_bytes() == data, p
            if p.name.startswith("result-seed"):
                assert json.loads(data)["status"] == "ok"
        disk.free_up()
        capsys.readouterr()
        assert run(args) == 0, capsys.readouterr().err
        assert "1 ran, 1 unchanged" in capsys.readouterr().out


@pytest.mark.parametrize("simulate", [False, True], ids=["real", "simulated"])
def test_disk_full_in_report_keeps_the_tables(simulate, tmp_path, capsys, fake):
    suite = tmp_path / "cases" / "demo"
    write_case(suite, "a", "rows=2")
    res = tmp_path / "results"
    with disk_full(res, simulate) as disk:
        assert run(["run", suite, "--results", res, "--jobs", 1, "--no-figures"]) == 0
        before = (res / "demo" / "summary.csv").read_bytes()
        capsys.readouterr()
        # something to write (current files are left alone)
        (res / "demo" / "summary.md").write_text("stale\n")
        disk.fill(0)
        one_error(run(["report", res / "demo", "--no-figures"]), capsys, "summary", "disk full")
        assert (res / "demo" / "summary.csv").read_bytes() == before and leftovers(res) == []


OUTPUT_CASES = (
    [f"read-only {c}" for c in READ_ONLY]
    + [f"folder {c}" for c in FILE_OUT]
    + ["bench onto a file"]
    + [f"under a file {c}" for c in [*FILE_OUT, "bench"]]
    + [f"disk full {c}" for c in FILE_OUT]
    + ["disk full run", "disk full report"]
)
