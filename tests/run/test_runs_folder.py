"""A user's run never overwrites the published results: `springbench run` writes to runs/
by default, and a quick run into the published folder is refused with one line."""

import shutil
from pathlib import Path

import pytest

from harness import cli, paths

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def folders(tmp_path, monkeypatch):
    published, runs = tmp_path / "results", tmp_path / "runs"
    published.mkdir()
    (published / "keep.txt").write_text("published")
    monkeypatch.setattr(paths, "DEFAULT_RESULTS", published)
    monkeypatch.setattr(paths, "DEFAULT_RUNS", runs)
    monkeypatch.setenv("SPRINGBENCH_CACHE", str(tmp_path / "cache"))
    case = tmp_path / "cases" / "plate_stress_tri.toml"
    case.parent.mkdir()
    shutil.copy(ROOT / "cases" / "verification" / "plate_stress_tri.toml", case)
    return published, runs, case


def test_run_writes_to_runs_by_default(folders):
    published, runs, case = folders
    assert cli.main(["run", str(case), "--jobs", "1", "--no-figures"]) == 0
    assert (runs / "index.html").is_file() and list(runs.glob("*/summary.csv"))
    assert sorted(p.name for p in published.iterdir()) == ["keep.txt"]  # untouched


def test_a_quick_run_into_the_published_folder_is_refused(folders, capsys):
    published, runs, case = folders
    assert (
        cli.main(["run", str(case), "--jobs", "1", "--no-figures", "--results", str(published)])
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--results" in err[0] and "--full" in err[0]
    assert sorted(p.name for p in published.iterdir()) == ["keep.txt"]
    assert not runs.exists()


def test_a_second_run_into_a_locked_folder_is_refused_and_a_stale_lock_taken_over(
    folders, tmp_path, capsys
):
    import subprocess
    import sys

    from harness.run.lock import LOCK

    _, runs, case = folders
    runs.mkdir()
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        (runs / LOCK).write_text(f"{sleeper.pid}\n")  # a live run holds the folder
        assert cli.main(["run", str(case), "--jobs", "1", "--no-figures"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"pid {sleeper.pid}" in err[0] and "--results" in err[0]
        assert not list(runs.glob("*/summary.csv"))
    finally:
        sleeper.kill()
        sleeper.wait()
    assert cli.main(["run", str(case), "--jobs", "1", "--no-figures"]) == 0  # its process is gone
    assert list(runs.glob("*/summary.csv")) and not (runs / LOCK).exists()


def test_stale_scratch_folders_are_removed(tmp_path):
    import subprocess
    import sys

    from harness.run.lock import clean_stale_scratch

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    import os

    stale = tmp_path / f"springbench-{dead.pid}-abc"
    live = tmp_path / f"springbench-{os.getpid()}-def"
    other = tmp_path / "springbench-xyz"
    for d in (stale, live, other):
        d.mkdir()
    assert clean_stale_scratch(tmp_path) == 1
    assert not stale.exists() and live.exists() and other.exists()
