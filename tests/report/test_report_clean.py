"""Nothing a user runs dirties the repository: ``report`` and ``bench`` write into runs/
unless told ``--results``; ``report`` re-run on unchanged results rewrites nothing (every
output byte-identical, no dates, no machine, no mtimes), a copy of the results (a fresh
checkout) finds its figures current, and a figure is redrawn only when the data it reads
or its code changes. The committed results/ are current: reporting a copy of them changes
no file."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from harness import cli
from harness.report import figures
from tests.fakestage import write_case

ROOT = Path(__file__).resolve().parents[2]


def fake_bench(folder: Path, monkeypatch, frame: str):
    """``bench reference`` runs a module written here whose run() returns ``frame`` (Python
    source)."""
    import re

    from harness import registry

    # one module per test (imports are cached)
    name = "fake_bench_" + re.sub(r"\W", "_", folder.name)
    (folder / f"{name}.py").write_text(f"import pandas\ndef run(quick):\n    return {frame}\n")
    monkeypatch.syspath_prepend(str(folder))
    monkeypatch.setattr(
        registry,
        "BENCHES",
        registry.BENCHES.with_entries({**registry.BENCHES.entries, "reference": name}),
    )


def snapshot(folder: Path) -> dict:
    return {
        p.relative_to(folder).as_posix(): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


@pytest.fixture
def drawn(monkeypatch):
    """The figure kinds drawn (figure module names), in order."""
    names = []
    real = figures._make

    def counting(mods, folder):
        names.extend(m.NAME for m in mods)
        return real(mods, folder)

    monkeypatch.setattr(figures, "_make", counting)
    return names


def test_report_twice_is_byte_identical_and_a_copy_redraws_nothing(tmp_path, fake, drawn, capsys):
    from harness.run.runner import run_suite

    suite = tmp_path / "cases" / "demo"
    write_case(suite, "a", "rows=3 files=1")
    write_case(suite, "b", "rows=2", extra="[run]\nseeds = [0, 1]")
    res = tmp_path / "results"
    assert not run_suite([suite], results=res, jobs=1, progress=False).failed
    assert cli.main(["report", "--results", str(res)]) == 0
    first = snapshot(res)
    assert "README.md" in first and "index.html" in first
    copy = tmp_path / "copy"  # a fresh checkout: new mtimes, another folder
    shutil.copytree(res, copy)
    drawn.clear()
    assert cli.main(["report", "--results", str(copy)]) == 0
    assert drawn == [] and snapshot(copy) == first
    assert cli.main(["report", "--results", str(copy)]) == 0
    assert drawn == [] and snapshot(copy) == first
    # new data for one kind: that kind alone is redrawn in that folder
    import pandas as pd

    trace = copy / "demo" / "a" / "trace.csv"
    t = pd.read_csv(trace)
    more = t.tail(1).copy()
    more["step"], more["G"] = t["step"].max() + 1, t["G"].min() / 2
    pd.concat([t, more]).to_csv(trace, index=False)
    assert cli.main(["report", "--results", str(copy)]) == 0
    assert drawn == ["trace"]
    changed = {k for k, v in snapshot(copy).items() if first.get(k) != v}
    assert changed == {"demo/a/trace.csv", "demo/a/fig-trace.png", "demo/a/.figures.json"}, changed


def test_report_and_bench_write_into_runs_by_default(tmp_path, monkeypatch, capsys):
    import harness.paths as paths

    monkeypatch.setattr(paths, "DEFAULT_RUNS", tmp_path / "runs")
    monkeypatch.setattr(paths, "DEFAULT_RESULTS", tmp_path / "results")
    assert cli.main(["report"]) == 2
    err = capsys.readouterr().err
    assert str(tmp_path / "runs") in err and "--results results" in err
    assert cli.main(["bench", "reference", "--quick", "--results", str(tmp_path / "results")]) == 2
    assert "--quick run would overwrite them" in capsys.readouterr().err
    args = cli.build_parser().parse_args(["bench", "reference", "--quick"])
    import pandas as pd

    from harness.commands import bench

    fake_bench(tmp_path, monkeypatch, "pandas.DataFrame({'n': [1]})")
    assert bench.main(args) == 0
    assert pd.read_csv(tmp_path / "runs" / "bench" / "reference.csv")["n"].tolist() == [1]
    assert not (tmp_path / "results").exists()


@pytest.mark.slow
def test_the_committed_results_are_current(tmp_path, drawn):
    """springbench report --results results on a copy of the repository's results/ (the
    cases beside it, as in a checkout) changes no file and redraws nothing."""
    src = ROOT / "results"
    if not (src / "index.html").exists():
        pytest.skip("no committed results")
    copy = tmp_path / "results"
    shutil.copytree(src, copy, ignore=shutil.ignore_patterns("_work"))
    (tmp_path / "cases").symlink_to(ROOT / "cases")
    before = snapshot(copy)
    assert cli.main(["report", "--results", str(copy)]) == 0
    after = snapshot(copy)
    changed = sorted(k for k in set(before) | set(after) if before.get(k) != after.get(k))
    assert not changed and not drawn, (changed[:10], drawn[:10])
