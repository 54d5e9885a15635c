"""Every column a user sees is explained: each column of every committed summary.csv has
an entry in harness/report/columns.py (an exact name or a family such as G_<load>), with
a meaning; the page's glossary and docs/columns.md are made from that list."""

import pandas as pd

from harness.paths import ROOT
from harness.report.columns import COLUMNS, Column, describe, glossary


def test_every_column_of_every_committed_summary_is_described():
    missing = {}
    summaries = sorted((ROOT / "results").glob("*/summary.csv"))
    assert len(summaries) >= 5
    for path in summaries:
        for col in pd.read_csv(path, nrows=0).columns:
            if describe(col) is None:
                missing.setdefault(col, path.parent.name)
    assert not missing, missing


def test_entries_are_unique_and_say_something():
    names = [c.name for c in COLUMNS]
    assert len(names) == len(set(names)), sorted(n for n in names if names.count(n) > 1)
    assert all(len(c.meaning) > 10 for c in COLUMNS), [
        c.name for c in COLUMNS if len(c.meaning) <= 10
    ]
    assert all(not c.meaning.endswith(".") for c in COLUMNS), [
        c.name for c in COLUMNS if c.meaning.endswith(".")
    ]


def test_families_match_their_members_and_exact_names_win():
    assert describe("G_heldout_tip2").name == "G_heldout_<load>"
    assert describe("G_bend-xy").name == "G_<load>"
    assert describe("G_heldout").name == "G_heldout"  # exact before any family
    assert describe("paper_G_final").name == "paper_<col>"
    assert describe("no such column") is None
    assert Column("a_<x>_b", "", "m").pattern().match("a_1_2_b") and not Column(
        "a_<x>", "", "m"
    ).pattern().match("b_1")


def test_the_page_shows_the_key_columns_and_the_docs_all():
    page = dict(glossary())
    assert {"G_norm", "G_heldout", "G_ref", "status"} <= set(page) and len(page) < len(COLUMNS) / 2
    from harness.report.docs_gen import COL_BEGIN, COL_END, block, columns_reference

    text = (ROOT / "docs" / "columns.md").read_text(encoding="utf-8")
    assert block(text, COL_BEGIN, COL_END).strip() == columns_reference().strip(), (
        "docs/columns.md differs from harness/report/columns.py: run python docs/generate.py"
    )
    assert all(f"| `{c.name}` |" in text for c in COLUMNS)
