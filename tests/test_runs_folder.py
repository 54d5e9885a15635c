"""A user's run never overwrites the published results: `springbench run` writes to runs/
by default, and a quick run into the published folder is refused with one line."""

import shutil
from pathlib import Path

import pytest

from harness import cli, runner

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def folders(tmp_path, monkeypatch):
    published, runs = tmp_path / "results", tmp_path / "runs"
    published.mkdir()
    (published / "keep.txt").write_text("published")
    monkeypatch.setattr(runner, "DEFAULT_RESULTS", published)
    monkeypatch.setattr(runner, "DEFAULT_RUNS", runs)
    monkeypatch.setenv("SPRINGBENCH_CACHE", str(tmp_path / "cache"))
    case = tmp_path / "cases" / "plate_stress_tri.toml"
    case.parent.mkdir()
    shutil.copy(ROOT / "cases" / "verification" / "plate_stress_tri.toml", case)
    return published, runs, case


def test_run_writes_to_runs_by_default(folders):
    published, runs, case = folders
    assert cli.main(["run", str(case), "--jobs", "1", "--no-figures"]) == 0
    assert (runs / "index.html").is_file() and list(runs.glob("*/summary.csv"))
    assert sorted(p.name for p in published.iterdir()) == ["keep.txt"]       # untouched


def test_a_quick_run_into_the_published_folder_is_refused(folders, capsys):
    published, runs, case = folders
    assert cli.main(["run", str(case), "--jobs", "1", "--no-figures", "--results", str(published)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--results" in err[0] and "--full" in err[0]
    assert sorted(p.name for p in published.iterdir()) == ["keep.txt"]
    assert not runs.exists()
