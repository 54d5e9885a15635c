"""Every generated sentence reads as a sentence on tables with missing parts: each suite's
claims (harness/report/claims.py, every entry of CLAIMS and the generic ones), its listed
findings, its tables' headings and notes, the engine finding, the console's case lines and
legend, the nu sweep's Markdown sentences and the page's findings, on the published
summaries (a few cases of each) made incomplete in turn: one column the sentences read
emptied (NaN), every such column emptied at once, every row failed, NaN nu, an engine table
whose engines are not installed, one with no engine rows at all, no rows. No sentence may
hold ``nan``, ``None``, empty parentheses or a double space (an empty number)."""

from __future__ import annotations

import re

import numpy as np
import pandas as pd
import pytest

from harness.paths import ROOT
from harness.report import claims, findings, nu_sweep
from harness.report.bench_tables import bench_table
from harness.report.engines import engines_finding
from harness.report.headlines import headline_tables

STORED = ROOT / "results"
# the columns the sentences read (emptied one at a time, then all at once)
READ = (
    "G_initial G_final G_norm_initial G_norm_final G_heldout G_heldout_mean "
    "G_heldout_mean_spread paper_G_initial paper_G_final peak_abs_dV_percent "
    "paper_peak_abs_dV_percent max_dev_vs_original_percent closed_form_error error_estimate "
    "ref_tol f1_eb_ratio nu G_norm G_ref max_error"
).split()
BAD = re.compile(r"(?i:\bnan\b)|\(\)|\bNone\b|  ")


def _few(suite: str):
    """The published summary of ``suite``, cut to a few cases (every nu of two bodies in the
    nu sweep, so its findings still compare Poisson ratios)."""
    path = STORED / suite / "summary.csv"
    if not path.is_file():
        pytest.skip(f"no published {path}")
    df = pd.read_csv(path)
    if suite == "nu_sweep":
        keep = df["case"].str.contains(r"^(?:box|plate)_nu0\.(?:00|49)$")
    else:
        keep = df["case"].isin(df["case"].drop_duplicates().head(4))
    if suite == "bourguignon2000":  # the cases its sentences name
        keep |= df["case"].isin(("volume_cube343", "fem_cube333_tetra"))
    return df[keep].reset_index(drop=True)


def _not_installed(df):
    d = df.copy()
    for c in ("G_norm", "max_error", "G_ref", "steps", "wall_s"):
        d[c] = np.nan
    d["engine_status"] = np.where(d["load"] == "mean", "see loads", "not-installed")
    d["status"] = "not-installed"
    return d


def variants(suite: str, df):
    """(label, table) of ``df`` with parts missing."""
    yield "as published", df
    for col in READ:
        if col in df:
            yield f"{col} empty", df.assign(**{col: np.nan})
    yield "every read column empty", df.assign(**{c: np.nan for c in READ if c in df})
    yield "every row failed", df.assign(status="error")
    yield "no rows", df.iloc[:0]
    if suite == "engines":
        yield "not installed", _not_installed(df)
        part = df.copy()
        mujoco = part["engine"] == "mujoco-flex"
        part.loc[mujoco, "G_norm"] = np.nan
        part.loc[mujoco, ["engine_status", "status"]] = "not-installed"
        yield "one engine not installed", part
        yield "no engine rows", df[df["engine"] == "none"]


def sentences(suite: str, df, folder) -> list[str]:
    """Every sentence the report generates from ``df`` as the summary of ``suite``."""
    make = claims.CLAIMS.get(suite)
    out = (make(df) if make and len(df) else []) + claims.generic(suite, df)
    for heading, items in claims.suite_lists(suite, df):
        out += [heading, *items]
    for heading, _, note in headline_tables(suite, df):
        out += [heading, note or ""]
    if {"engine", "load"} <= set(df):
        out.append(engines_finding(df))
        out.append(bench_table("engines", df)[1])
    lines = findings.case_lines(df)
    # the console table pads its columns: its rows are checked with the spaces squeezed
    out += [re.sub(" {2,}", " ", x) for x in findings.summary_text(suite, lines)]
    out += findings.legend(lines["findings"])
    out += [x for x in nu_sweep.markdown_section(df) if not x.lstrip().startswith("|")]
    if "status" in df and (df["status"] == "not-installed").any():
        out.append(findings.not_installed_note(df))
    (folder / suite).mkdir(parents=True, exist_ok=True)
    df.to_csv(folder / suite / "summary.csv", index=False)
    return out + claims.headline_findings([folder / suite])


@pytest.mark.parametrize("suite", list(claims.CLAIMS))
def test_no_sentence_holds_nan_none_or_empty_parentheses(suite, tmp_path):
    df = _few(suite)
    bad = [
        f"{label}: {s}"
        for label, d in variants(suite, df)
        for s in sentences(suite, d, tmp_path / label.replace(" ", "-"))
        if BAD.search(s.strip())
    ]
    assert not bad, "\n".join(bad[:10])


def test_the_engine_finding_names_the_install_command_when_engines_are_missing():
    from harness.engines import EXTRA

    df = _few("engines")
    assert EXTRA in engines_finding(_not_installed(df))
    assert EXTRA not in engines_finding(df)
