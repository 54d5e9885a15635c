"""Progress with an ETA (harness/progress.py): bars only on a terminal and never with
--quiet; calibrate's line names its phases and, from the first fit on, an ETA from the
work done (tests/commands/test_calibrate_progress.py); run --quiet prints no per-case lines."""

from __future__ import annotations

import io
import re
import sys
import time

import pytest

from harness import cli, progress
from tests.fakestage import write_case


class Terminal(io.StringIO):
    """stderr as a terminal (tqdm and the commands ask isatty)."""

    def isatty(self):
        return True


def terminal(monkeypatch) -> Terminal:
    """stderr replaced by a terminal, inside the test (pytest's capture sets sys.stderr
    again between a fixture's setup and the test)."""
    out = Terminal()
    monkeypatch.setattr(sys, "stderr", out)
    monkeypatch.setattr(progress, "_QUIET", [False])
    return out


def test_bars_only_on_a_terminal_and_never_quiet(monkeypatch):
    tty = terminal(monkeypatch)
    assert progress.shown()
    done = []
    for i in progress.steps(range(3), "bench demo", "size"):
        time.sleep(0.15)  # tqdm redraws at most every 0.1 s
        done.append(i)
    text = tty.getvalue()
    assert done == [0, 1, 2] and "bench demo" in text and "2/3" in text
    assert re.search(r"2/3 \[\d\d:\d\d<\d\d:\d\d", text)  # elapsed < ETA
    progress.configure(True)
    assert not progress.shown()
    tty.seek(0)
    tty.truncate()
    assert list(progress.steps(range(2), "quiet", "size")) == [0, 1] and tty.getvalue() == ""
    progress.configure(False)
    monkeypatch.setattr(sys, "stderr", io.StringIO())  # a log file or a pipe
    assert not progress.shown()


def test_clock_shows_the_phase_and_then_an_eta(monkeypatch):
    tty = terminal(monkeypatch)
    clock = progress.Clock("calibrate")
    clock.set("FEM reference", "level 1")
    assert "calibrate: FEM reference" in tty.getvalue() and "left" not in tty.getvalue()
    clock.bound(120.0)
    clock.set("fit", "lbfgs it 3")
    clock.close()
    last = [line for line in tty.getvalue().split("\r") if "calibrate:" in line][-1]
    assert "calibrate: fit" in last and "lbfgs it 3" in last
    # the 120 s the phase's estimate says, not tqdm's rate
    assert re.search(r"about 0(1:5\d|2:00) left", last), last


@pytest.mark.slow
@pytest.mark.parametrize("quiet", [False, True])
@pytest.mark.filterwarnings("error::pytest.PytestUnhandledThreadExceptionWarning")  # the ticker
def test_calibrate_on_a_terminal(monkeypatch, tmp_path, quiet):
    from tests import meshes

    pytest.importorskip("gmsh")
    mesh = meshes.cylinder(tmp_path)
    argv = (
        ["calibrate", str(mesh), "--E", "1e5", "--nu", "0.3"]
        + ["--prior-weight", "1", "--max-refine", "0"]
        + ["--out", str(tmp_path / "m.vtu")]
    ) + (["--quiet"] if quiet else [])
    tty = terminal(monkeypatch)
    assert cli.main(argv) == 0
    text = tty.getvalue()
    if quiet:
        assert "calibrate:" not in text
    else:
        assert "calibrate: FEM reference" in text and "calibrate: fit" in text and " left" in text


def test_run_quiet_prints_no_case_lines(tmp_path, fake, capsys):
    suite = tmp_path / "cases" / "demo"
    write_case(suite, "a", "rows=1")
    res = tmp_path / "res"
    assert cli.main(["run", str(suite), "--results", str(res), "--jobs", "1", "--no-figures"]) == 0
    assert "[1/1] a: ok" in capsys.readouterr().out  # not a terminal: one line per case
    assert (
        cli.main(
            (
                ["run", str(suite), "--results", str(res), "--jobs", "1"]
                + ["--no-figures", "--force", "--quiet"]
            )
        )
        == 0
    )
    out = capsys.readouterr()
    assert "[1/1]" not in out.out and "suite" not in out.err
