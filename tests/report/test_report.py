"""Report: tables and figures rebuilt from stored results, the index, markdown, columns."""

from __future__ import annotations

import re
from pathlib import Path

import pandas as pd
import pytest

from harness import cli
from harness.report import build as report
from harness.run.runner import run_suite
from tests.fakestage import calls, write_case


def test_figures_from_stored_data_and_report_rebuild(tmp_path, fake, capsys):
    suite = tmp_path / "cases" / "demo"
    write_case(suite, "a", "rows=3 files=1")
    write_case(suite, "b", "rows=2", extra="[run]\nseeds = [0, 1]")
    res = tmp_path / "results"
    rep = run_suite([suite], results=res, jobs=1, progress=False)
    assert not rep.failed
    a = res / "demo" / "a"
    kinds = (
        ["fig-trace.png", "fig-volume.png", "fig-spectrum.png"]
        + ["fig-anisotropy.png", "fig-lloyd.png", "fig-deformed.png"]
        + ["fig-fibres.png"]
    )
    for k in kinds:
        assert (a / k).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", k
    assert (res / "demo" / "fig-lloyd-bars.png").exists()  # suite figure from summary.csv
    index = (res / "index.html").read_text()
    links = re.findall(r"(?:href|src)='([^']+)'", index)
    assert "demo/summary.md" in links and "demo/a/fig-trace.png" in links
    assert all(
        not Path(link).is_absolute() and (res / link).exists()
        for link in links
        if not link.startswith("#")
    )
    # rebuild from stored results only: no stage runs, same table, figures back
    n = len(calls(suite))
    table = (res / "demo" / "summary.csv").read_text()
    for f in list(res.rglob("*.png")) + [
        res / "demo" / "summary.csv",
        res / "demo" / "summary.md",
        res / "index.html",
    ]:
        f.unlink()
    assert cli.main(["report", str(res / "demo")]) == 0
    assert len(calls(suite)) == n
    assert (res / "demo" / "summary.csv").read_text() == table
    assert all((a / k).exists() for k in kinds) and (res / "index.html").exists()
    assert cli.main(["report", "--results", str(res), "--no-figures"]) == 0


def test_report_on_a_folder_without_results_is_one_line(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    assert cli.main(["report", str(tmp_path / "empty")]) == 2
    assert cli.main(["report", str(tmp_path / "missing")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "no stored results here" in err[0] and "no such folder" in err[1]


def test_broken_data_file_is_a_warning_not_a_crash(tmp_path, capsys):
    from harness.report import figures

    (tmp_path / "trace.csv").write_text("not,a\ntrace,file\n")
    (tmp_path / "volume.csv").write_text("t,MS\n0,0\n1,-1\n")
    out = figures.make_case_figures(tmp_path)
    assert [p.name for p in out] == ["fig-volume.png"]
    assert "warning: figure trace" in capsys.readouterr().err


def test_column_order_is_stable():
    cols = (
        ["zeta", "G_final", "seconds", "paper_G_final", "case", "alpha"]
        + ["ratio_G_final", "model", "paper_unknown", "error", "seed"]
        + ["G_initial"]
    )
    out = report.order_columns(cols)
    assert out == (
        ["case", "model", "seed", "G_initial", "G_final", "paper_G_final"]
        + ["ratio_G_final", "alpha", "zeta", "paper_unknown", "seconds", "error"]
    )
    assert report.order_columns(reversed(cols)) == out


def test_markdown_table_by_hand():
    df = pd.DataFrame({"case": ["a|b", "c"], "G": [0.123456, float("nan")], "n": [1, 2]})
    assert report.markdown_table(df) == (
        "| case | G | n |\n| --- | ---: | ---: |\n| a\\|b | 0.1235 | 1 |\n| c |  | 2 |\n"
    )


def test_timing_columns():
    t = report.TIMING
    assert all(
        t.search(c)
        for c in ["seconds", "wall_seconds", "solve_ms", "steps_per_s", "seconds_to_sa_G"]
    )
    assert not any(t.search(c) for c in ["G_s", "n_springs", "G_final", "ms_error", "seed"])


def test_expect_ratio_only_for_ok_numeric_rows():
    row = report._with_expect(
        {"model": "x", "status": "ok", "G_final": 1.0}, {"G_final": 0.5, "note": "t"}
    )
    assert row["paper_G_final"] == 0.5 and row["ratio_G_final"] == 2.0 and "paper_note" not in row
    err = report._with_expect({"model": "", "status": "error"}, {"G_final": 0.5})
    assert "paper_G_final" not in err
    fem = report._with_expect(
        {"model": "FEM", "status": "ok", "G_final": float("nan")}, {"G_final": 0.5}
    )
    assert "paper_G_final" not in fem
    opt = report._with_expect(
        {"model": "x", "status": "ok", "G_initial": 3.0, "G_final": 1.5},
        {"G_initial": 2.8, "G_final": 0.56},
    )
    assert opt["improvement"] == 2.0 and opt["paper_improvement"] == pytest.approx(5.0)


def test_figures_are_redrawn_only_when_their_data_change(tmp_path):
    from harness.report import figures

    (tmp_path / "volume.csv").write_text("t,MS\n0,0\n1,-1\n")
    png = figures.make_case_figures(tmp_path)[0]
    t0 = png.stat().st_mtime_ns
    assert figures.make_case_figures(tmp_path) == [png] and png.stat().st_mtime_ns == t0
    import os
    import time

    time.sleep(0.01)
    (tmp_path / "volume.csv").write_text("t,MS\n0,0\n1,-2\n")
    os.utime(tmp_path / "volume.csv", ns=(t0 + 10**9, t0 + 10**9))
    figures.make_case_figures(tmp_path)
    assert png.stat().st_mtime_ns != t0
    t1 = png.stat().st_mtime_ns
    figures.make_case_figures(tmp_path, redraw=True)
    assert png.stat().st_mtime_ns != t1
