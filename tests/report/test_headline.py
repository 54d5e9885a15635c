"""The console summary of a run is a headline table, one line per case."""

import math

import pandas as pd

from harness import cli, paths
from harness.report.frames import headline_frame


def test_headline_picks_the_best_rule_and_fit_by_hand():
    df = pd.DataFrame(
        [
            dict(
                case="a",
                status="ok",
                stiffness="deussen",
                optimizer="none",
                G_norm_final=0.30,
                G_ref=1e-4,
                seconds=1.0,
            ),
            dict(
                case="a",
                status="ok",
                stiffness="lloyd",
                optimizer="none",
                G_norm_final=0.10,
                G_ref=1e-4,
                seconds=1.0,
            ),
            dict(
                case="a",
                status="ref-coarse",
                stiffness="deussen",
                optimizer="sa",
                G_norm_final=0.05,
                G_heldout=0.2,
                G_ref=2e-4,
                seconds=5.0,
            ),
            dict(
                case="a",
                status="ok",
                stiffness="deussen",
                optimizer="lbfgs",
                G_norm_final=0.02,
                G_heldout=0.3,
                G_ref=2e-4,
                seconds=2.0,
            ),
            dict(case="b", status="error", error="b.toml: model.grid: expected 2 integers"),
            dict(case="c", status="ok", seconds=0.5),
        ]
    )
    h = headline_frame(df).set_index("case")
    assert list(h.index) == ["a", "b", "c"]
    a = h.loc["a"]
    assert (
        a.status,
        a.best_rule,
        a.G_norm_rule,
        a.best_fit,
        a.G_norm_fit,
        a.G_heldout,
        a.G_ref,
        a.seconds,
    ) == ("ref-coarse", "lloyd", 0.10, "lbfgs", 0.02, 0.3, 2e-4, 9.0)
    assert h.loc["b", "status"] == "error" and "model.grid" in h.loc["b", "note"]
    assert h.loc["c", "note"] == "see summary.md" and math.isnan(h.loc["c", "G_norm_fit"])


def test_run_prints_one_line_per_case(tmp_path, monkeypatch, capsys):
    import shutil
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    monkeypatch.setattr(paths, "DEFAULT_RUNS", tmp_path / "runs")
    monkeypatch.setenv("SPRINGBENCH_CACHE", str(tmp_path / "cache"))
    suite = tmp_path / "cases" / "v"
    suite.mkdir(parents=True)
    for name in ("plate_stress_tri.toml", "plate_strain_quad.toml"):
        shutil.copy(root / "cases" / "verification" / name, suite / name)
    assert cli.main(["run", str(suite), "--jobs", "1", "--no-figures"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    start = next(i for i, line in enumerate(out) if line.startswith("== v:"))
    table = out[start + 1 : start + 4]
    assert table[0].split() == ["case", "model", "G_norm", "fitted", "/", "held-out", "status"]
    assert {table[1].split()[0], table[2].split()[0]} == {"plate_stress_tri", "plate_strain_quad"}
    assert all(line.split()[1:3] == ["-", "-"] for line in table[1:])  # the reference only: no G
    legend = [line for line in out[start:] if line.startswith("  ref-coarse: ")]
    assert len(legend) == (1 if any(line.endswith("ref-coarse") for line in table[1:]) else 0)
    # header, two cases, what model/held-out mean, the legend, the jobs line, blanks
    assert len(out) - start <= 10
