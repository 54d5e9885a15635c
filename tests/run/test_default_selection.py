"""What ``springbench run`` runs without a case: the quick tier (harness/suites.py), one case
per capability of every suite under cases/, listed here against the suites' folders; with
``--full`` every case; a folder or file given runs exactly that. The time left of the
progress line weighs the jobs by their recorded seconds."""

from __future__ import annotations

from pathlib import Path

import pytest

from harness import cli
from harness.case.reader import find_cases, load_case
from harness.paths import DEFAULT_CASES
from harness.suites import QUICK, quick_cases, suites

# suite -> the cases the default run runs, one per capability the suite shows
EXPECTED = {
    "verification": {"plate_strain_quad", "box_basic3d", "cantilever_2d"},
    "deussen1995": {"fig08_grid25_grouped"},
    "bourguignon2000": {"volume_cube343", "pull_cube353", "fibres_cube353", "fem_cube333_tetra"},
    "nu_sweep": {"box_nu0.30"},
    "engines": {"beam-coarse_nu0.30"},
}


def test_the_quick_tier_is_one_case_per_capability_of_every_suite():
    assert set(suites()) == set(EXPECTED)  # every suite of cases/ is in it
    chosen = {}
    for suite, stem, *_ in QUICK:
        chosen.setdefault(suite, set()).add(stem)
    assert chosen == EXPECTED
    capabilities = [what for _, _, what, _ in QUICK]
    assert len(set(capabilities)) == len(capabilities)  # one case per capability
    files = quick_cases()
    assert len(set(files)) == len(files) == len(QUICK)
    everything = set(find_cases([DEFAULT_CASES]))
    for f in files:
        assert f in everything, f
        case = load_case(f, "quick")
        assert case.name == f.stem  # the case's results folder: what the tier's seconds name
    assert len(files) < len(everything) / 4


@pytest.fixture
def planned(monkeypatch):
    """The paths and budgets each ``springbench run`` asks the runner for (nothing runs)."""
    from harness.run import runner

    calls = []

    def fake(paths, mode, results, **kw):
        calls.append((list(paths), mode))
        return runner.RunReport([], [], Path(results))

    monkeypatch.setattr(runner, "run_suite", fake)
    return calls


def test_run_without_a_case_runs_the_quick_tier(planned, tmp_path, capsys):
    assert cli.main(["run", "--results", str(tmp_path / "r")]) == 0
    assert planned[-1] == (quick_cases(), "quick")
    out = capsys.readouterr().out
    assert f"the quick tier, {len(QUICK)} cases" in out and "--full" in out


def test_full_and_a_folder_run_every_case_they_name(planned, tmp_path):
    assert cli.main(["run", "--full", "--results", str(tmp_path / "r")]) == 0
    assert planned[-1] == ([], "full")  # the runner's default: every case under cases/
    folder = str(DEFAULT_CASES / "verification")
    assert cli.main(["run", folder, "--results", str(tmp_path / "r")]) == 0
    assert planned[-1] == ([folder], "quick")


def test_the_time_left_weighs_jobs_by_their_recorded_seconds(tmp_path):
    from harness.run.jobs import plan
    from harness.run.runner import recorded_seconds

    jobs, failed = plan(quick_cases()[:2], "quick", stages=())
    assert not failed
    seconds = recorded_seconds(jobs, tmp_path)
    assert seconds == {
        job.label: float(s) for job, (*_, s) in zip(jobs, QUICK[:2])
    }  # no earlier run here: the tier's own record
