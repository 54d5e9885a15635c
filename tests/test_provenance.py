"""Provenance (harness/provenance.py): the commit and dirty flag checked against git run
here on a repository made here, the versions against importlib.metadata, the cores against
os; a run stores it in every result file and its suite's provenance.json, the report shows
it per suite and copes with results stored before it ("not recorded"); bench CSVs carry it
in every row."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from importlib import metadata

import pandas as pd
import pytest

from harness import cli, provenance
from tests.fakestage import write_case
from tests.report.test_report_clean import fake_bench


def git(root, *args):
    return subprocess.run(
        ["git", "-C", str(root), *args], capture_output=True, text=True, check=True
    ).stdout.strip()


@pytest.fixture
def repo(tmp_path):
    root = tmp_path / "repo"
    (root / "harness").mkdir(parents=True)
    (root / "harness" / "a.py").write_text("x = 1\n")
    git(root, "init", "-q")
    git(root, "add", "-A")
    git(root, "-c", "user.email=t@t", "-c", "user.name=t", "commit", "-qm", "one")
    return root


def test_commit_and_dirty_flag_follow_git(repo, tmp_path):
    head = git(repo, "rev-parse", "HEAD")
    assert provenance.git_state(repo) == (head, False)
    (repo / "results").mkdir()
    (repo / "results" / "x.csv").write_text("a\n1\n")  # outputs of runs do not make the code dirty
    (repo / "runs").mkdir()
    (repo / "runs" / "y.csv").write_text("b\n")
    assert provenance.git_state(repo) == (head, False)
    (repo / "harness" / "a.py").write_text("x = 2\n")  # changed code does
    assert provenance.git_state(repo) == (head, True)
    (repo / "harness" / "a.py").write_text("x = 1\n")
    (repo / "harness" / "new.py").write_text("y = 1\n")  # so does code not yet committed
    assert provenance.git_state(repo) == (head, True)
    outside = tmp_path / "plain"
    outside.mkdir()
    assert provenance.git_state(outside) == (None, None)


def test_collect_records_every_field(repo):
    p = provenance.collect(repo)
    assert tuple(p) == provenance.FIELDS and p["format_version"] == provenance.FORMAT_VERSION
    assert p["git_commit"] == git(repo, "rev-parse", "HEAD") and p["git_dirty"] is False
    assert p["python_version"] == ".".join(map(str, sys.version_info[:3]))
    for key, dist in provenance.LIBRARIES.items():
        assert p[key] == metadata.version(dist)
    assert p["cpu_cores"] == os.cpu_count() and p["cpu_model"]
    assert p["load_average"] is None or p["load_average"] >= 0
    line = provenance.describe(p)
    assert (
        p["git_commit"][:12] in line
        and "(clean tree)" in line
        and f"scipy {p['scipy_version']}" in line
    )
    assert (
        provenance.describe(None)
        == provenance.NOT_RECORDED
        == provenance.describe({"git_commit": float("nan")})
    )


def test_a_run_records_it_and_the_report_shows_it(tmp_path, fake, capsys):
    from harness.report.origin import lines
    from harness.run.runner import run_suite

    suite = tmp_path / "cases" / "demo"
    write_case(suite, "a", "rows=2")
    write_case(suite, "b", "rows=1")
    res = tmp_path / "results"
    assert not run_suite([suite], results=res, jobs=1, progress=False, figures=False).failed
    stored = json.loads((res / "demo" / "a" / "result-seed0.json").read_text())
    assert tuple(stored["provenance"]) == provenance.FIELDS
    gathered = json.loads((res / "demo" / "provenance.json").read_text())
    assert [r["cases"] for r in gathered["runs"]] == [["a", "b"]] and gathered["not_recorded"] == []
    # a result stored before provenance was recorded: the report copes and says so
    old = json.loads((res / "demo" / "b" / "result-seed0.json").read_text())
    del old["provenance"]
    (res / "demo" / "b" / "result-seed0.json").write_text(json.dumps(old))
    assert cli.main(["report", "--results", str(res), "--no-figures"]) == 0
    said = lines(res / "demo")
    assert said[0].startswith("1 of 2 results: format 1, springbench ") and "cores" in said[0]
    assert said[1] == "1 of 2 results: not recorded (stored before provenance was recorded)."
    page = (res / "index.html").read_text()
    readme = (res / "README.md").read_text()
    for text in (page, readme):
        assert (
            "Code and machine" in text
            and "not recorded (stored before provenance was recorded)" in text
        )
    assert lines(tmp_path) == ["not recorded."]  # a folder without the file


def test_bench_rows_carry_it(tmp_path, monkeypatch):
    from harness.commands import bench

    fake_bench(tmp_path, monkeypatch, "pandas.DataFrame({'n': [1, 2], 'seconds': [0.1, 0.2]})")
    args = cli.build_parser().parse_args(["bench", "reference", "--quick", "--out", str(tmp_path)])
    assert bench.main(args) == 0
    df = pd.read_csv(tmp_path / "reference.csv")
    assert list(df.columns) == ["n", "seconds", *provenance.FIELDS]
    assert (df["format_version"] == provenance.FORMAT_VERSION).all() and (
        df["cpu_cores"] == os.cpu_count()
    ).all()
