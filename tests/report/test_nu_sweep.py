"""The nu-sweep map (harness/report/nu_sweep.py, figures/nu_sweep.py): from summary rows
written here by hand, each (body, class, nu) takes its fitted row (p1: its only row), the
table pivots them per class, and the suite figure is drawn; no sweep rows, no figure."""

import math

import pandas as pd
import pytest

from harness.report.figures import nu_sweep as fig
from harness.report.nu_sweep import sweep_frame, sweep_table


def rows():
    out = []
    for body, dim in (("box", 3), ("plate", 2)):
        for nu in (0.0, 0.3, 0.49):
            for cls in ("springs", "springs+volume"):
                base = dict(case=f"{body}_nu{nu:.2f}", dim=dim, nu=nu, model_class=cls, status="ok", objective=None)
                out.append({**base, "optimizer": "none", "G_norm_final": 0.5, "G_heldout": 0.6})
                g = 0.1 + nu + (0.0 if cls == "springs" else -0.05)
                out.append({**base, "optimizer": "lbfgs", "objective": "G", "G_norm_final": g, "G_heldout": 2 * g,
                            "k_spread": 3.0, "dt_stable": 1e-3})
            out.append(dict(case=f"{body}_nu{nu:.2f}", dim=dim, nu=nu, model_class="p1", status="ok",
                            optimizer="none", G_norm_final=1e-14, G_heldout=0.01 + nu))
    out.append(dict(case="box_nu0.30", model="FEM", stage="reference", status="ok"))     # no class: ignored
    return pd.DataFrame(out)


def test_sweep_frame_takes_each_class_fitted_row_and_p1_only_row():
    f = sweep_frame(rows())
    assert len(f) == 2 * 3 * 3
    s = f[(f["body"] == "box") & (f["model_class"] == "springs+volume") & (f["nu"] == 0.49)].iloc[0]
    assert s["G_norm_final"] == pytest.approx(0.1 + 0.49 - 0.05) and s["G_heldout"] == pytest.approx(2 * 0.54)
    p = f[(f["body"] == "plate") & (f["model_class"] == "p1") & (f["nu"] == 0.3)].iloc[0]
    assert p["G_heldout"] == pytest.approx(0.31) and math.isnan(p["k_spread"])
    t = sweep_table(f)
    assert len(t) == 6 and "springs: G_norm" in t and "p1: G_heldout" in t
    assert t.loc[(t["body"] == "box") & (t["nu"] == 0.0), "springs: G_norm"].iloc[0] == pytest.approx(0.1)


def test_figure_is_drawn_from_the_summary_and_not_without_sweep_rows(tmp_path):
    rows().to_csv(tmp_path / "summary.csv", index=False)
    out = fig.make(tmp_path)
    assert [p.name for p in out] == ["fig-nu-sweep.png"] and out[0].stat().st_size > 1000
    other = tmp_path / "other"
    other.mkdir()
    pd.DataFrame([dict(case="a", model="m", G_norm_final=0.1)]).to_csv(other / "summary.csv", index=False)
    assert fig.make(other) == [] and sweep_frame(pd.read_csv(other / "summary.csv")).empty


def test_skipped_classes_are_listed_with_their_reason_and_never_in_the_map():
    """A 2-D body's mt rows (status "skip", no G) stay out of the map and are named once per
    body and class, with the note, under the table."""
    from harness.report.nu_sweep import skipped_lines
    skip = [dict(case=f"plate_nu{nu:.2f}", dim=2, nu=nu, model_class="mt", status="skip", optimizer="none",
                 note="no 2-D element") for nu in (0.0, 0.3)]
    df = pd.concat([rows(), pd.DataFrame(skip)], ignore_index=True)
    assert "mt" not in set(sweep_frame(df)["model_class"])
    assert skipped_lines(df) == ["- `mt` on `plate`: skipped (no 2-D element)"]
    assert skipped_lines(rows()) == []
