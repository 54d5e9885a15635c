"""Missing engines are a state, not "ok": with the engines' packages (newton, warp, mujoco)
made unimportable here (their ``sys.modules`` entries set to None, which is what a missing
package looks like to ``import`` and ``importlib.util.find_spec``), one engines case run
through ``springbench run``'s runner gives rows whose status is ``not-installed``; the
page counts them as such, says which engines are missing and how to install them, and its
findings name the install command and hold no ``nan`` and no empty parentheses."""

from __future__ import annotations

import re
import subprocess
import sys

import pandas as pd
import pytest

from harness.engines import EXTRA
from harness.paths import ROOT
from harness.report.findings import case_lines, legend, summary_text
from harness.report.page import index_html
from harness.run.runner import run_suite
from harness.stages import engines as S

CASE = ROOT / "cases" / "engines" / "beam-coarse_nu0.30.toml"
PACKAGES = ("newton", "warp", "mujoco", "pybullet", "pydrake")
BAD = re.compile(r"\bnan\b|\(\)|\bNone\b", re.IGNORECASE)


@pytest.fixture
def no_engines(monkeypatch):
    """The engines' packages fail to import; ``springbench pack`` (the FEM, a subprocess)
    is replaced by a no-op: with no engine to run, its pack is never read."""
    for name in PACKAGES:
        monkeypatch.setitem(sys.modules, name, None)
    done = subprocess.CompletedProcess(["pack"], 0, "", "")
    monkeypatch.setattr(S, "cli", lambda *argv: done)
    monkeypatch.setattr(S, "read_pack", lambda folder: None)


def test_the_simulation_is_a_failed_import(no_engines):
    for name in PACKAGES:
        with pytest.raises(ImportError):
            __import__(name)
    assert not any(S._installed(e) for e in S.ENGINES)


@pytest.fixture
def ran(no_engines, tmp_path):
    rep = run_suite([CASE], "quick", tmp_path, jobs=1, stages=[S.__name__], progress=False)
    assert not rep.failed
    return tmp_path


def test_rows_are_not_installed_not_ok(ran):
    df = pd.read_csv(ran / "engines" / "summary.csv")
    assert len(df) and set(df["status"]) == {"not-installed"}
    loads = df[df["load"] != "mean"]
    assert set(loads["engine_status"]) == {"not-installed"}
    assert all(EXTRA in n for n in loads["note"])
    lines = case_lines(df)
    assert list(lines["findings"]) == [["not-installed"]]
    text = "\n".join(summary_text("engines", lines) + legend(lines["findings"]))
    assert "not-installed" in text and EXTRA in text


def test_the_page_shows_the_status_and_the_install_command(ran):
    page = index_html(ran)
    n = len(pd.read_csv(ran / "engines" / "summary.csv"))
    assert f"{n} not-installed" in page and f"{n} ok" not in page
    assert "<td>not installed</td>" in page  # the engine table's cells
    assert EXTRA.replace('"', "&quot;") in page
    found = re.search(r"<section id='findings'>(.*?)</section>", page, re.S).group(1)
    sentences = re.findall(r"<li>(.*?)</li>", found, re.S)
    assert sentences and any(EXTRA.replace('"', "&quot;") in s for s in sentences)
    assert not [s for s in sentences if BAD.search(s)], sentences
