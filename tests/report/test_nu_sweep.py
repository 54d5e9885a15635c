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
            for cls in ("springs", "springs+volume-shared"):
                base = dict(
                    case=f"{body}_nu{nu:.2f}",
                    dim=dim,
                    nu=nu,
                    model_class=cls,
                    status="ok",
                    objective=None,
                )
                out.append({**base, "optimizer": "none", "G_norm_final": 0.5, "G_heldout": 0.6})
                g = 0.1 + nu + (0.0 if cls == "springs" else -0.05)
                out.append(
                    {
                        **base,
                        "optimizer": "lbfgs",
                        "objective": "G",
                        "G_norm_final": g,
                        "G_heldout": 2 * g,
                        "k_spread": 3.0,
                        "dt_stable": 1e-3,
                    }
                )
            out.append(
                dict(
                    case=f"{body}_nu{nu:.2f}",
                    dim=dim,
                    nu=nu,
                    model_class="p1",
                    status="ok",
                    optimizer="none",
                    G_norm_final=1e-14,
                    G_heldout=0.01 + nu,
                )
            )
    # no class: ignored
    out.append(dict(case="box_nu0.30", model="FEM", stage="reference", status="ok"))
    return pd.DataFrame(out)


def test_sweep_frame_takes_each_class_fitted_row_and_p1_only_row():
    f = sweep_frame(rows())
    assert len(f) == 2 * 3 * 3
    s = f[
        (f["body"] == "box") & (f["model_class"] == "springs+volume-shared") & (f["nu"] == 0.49)
    ].iloc[0]
    assert s["G_norm_final"] == pytest.approx(0.1 + 0.49 - 0.05) and s[
        "G_heldout"
    ] == pytest.approx(2 * 0.54)
    p = f[(f["body"] == "plate") & (f["model_class"] == "p1") & (f["nu"] == 0.3)].iloc[0]
    assert p["G_heldout"] == pytest.approx(0.31) and math.isnan(p["k_spread"])
    t = sweep_table(f)
    assert len(t) == 6 and "springs: G_norm" in t and "p1: G_heldout" in t
    assert t.loc[(t["body"] == "box") & (t["nu"] == 0.0), "springs: G_norm"].iloc[
        0
    ] == pytest.approx(0.1)


def test_figure_is_drawn_from_the_summary_and_not_without_sweep_rows(tmp_path):
    rows().to_csv(tmp_path / "summary.csv", index=False)
    out = fig.make(tmp_path)
    assert [p.name for p in out] == ["fig-nu-sweep.png"] and out[0].stat().st_size > 1000
    other = tmp_path / "other"
    other.mkdir()
    pd.DataFrame([dict(case="a", model="m", G_norm_final=0.1)]).to_csv(
        other / "summary.csv", index=False
    )
    assert fig.make(other) == [] and sweep_frame(pd.read_csv(other / "summary.csv")).empty


def test_skipped_classes_are_listed_with_their_reason_and_never_in_the_map():
    """A 2-D body's mt rows (status "skip", no G) stay out of the map and are named once per
    body and class, with the note, under the table."""
    from harness.report.nu_sweep import skipped_lines

    skip = [
        dict(
            case=f"plate_nu{nu:.2f}",
            dim=2,
            nu=nu,
            model_class="mt",
            status="skip",
            optimizer="none",
            note="no 2-D element",
        )
        for nu in (0.0, 0.3)
    ]
    df = pd.concat([rows(), pd.DataFrame(skip)], ignore_index=True)
    assert "mt" not in set(sweep_frame(df)["model_class"])
    assert skipped_lines(df) == ["- `mt` on `plate`: skipped (no 2-D element)"]
    assert skipped_lines(rows()) == []


# -- held-out families: tiny frames whose numbers are checked by hand -----------------------

LOADS = ("sag", "tip", "tip2", "torsion", "bridge")


def held(*g):
    """G_heldout_<load> of LOADS from five numbers."""
    return {f"G_heldout_{n}": v for n, v in zip(LOADS, g)}


def family_rows(spread=0.01, choice="springs-prior1"):
    """One body at nu 0.3: the springs rules lloyd and vangelder, the springs select row,
    springs+volume-shared's unfitted and fitted rows, p1's only row."""
    base = dict(case="cyl_nu0.30", dim=3, nu=0.3, status="ok", objective=None)
    sp = dict(base, model_class="springs")
    sv = dict(base, model_class="springs+volume-shared")
    return pd.DataFrame(
        [
            dict(
                sp,
                stiffness="lloyd",
                optimizer="none",
                G_norm_final=0.3,
                G_heldout_mean=0.30,
                **held(0.2, 0.1, 0.3, 0.4, 0.5),
            ),
            dict(
                sp,
                stiffness="vangelder",
                optimizer="none",
                G_norm_final=0.4,
                G_heldout_mean=0.20,
                **held(0.1, 0.2, 0.2, 0.2, 0.3),
            ),
            dict(
                sp,
                stiffness="lloyd",
                optimizer="lbfgs",
                objective="G",
                choice=choice,
                G_norm_final=0.05,
                G_heldout_mean=0.10,
                G_heldout_mean_spread=spread,
                **held(0.1, 0.05, 0.15, 0.1, 0.1),
            ),
            dict(
                sv,
                stiffness="lloyd",
                optimizer="none",
                G_norm_final=0.5,
                G_heldout_mean=0.01,
                **held(*[0.01] * 5),
            ),
            dict(
                sv,
                stiffness="lloyd",
                optimizer="lbfgs",
                objective="G",
                G_norm_final=0.02,
                G_heldout_mean=0.40,
                **held(0.4, 0.4, 0.4, 0.4, 0.4),
            ),
            dict(
                base,
                model_class="p1",
                stiffness="p1",
                optimizer="none",
                G_norm_final=1e-14,
                G_heldout_mean=0.105,
                **held(0.105, 0.105, 0.105, 0.105, 0.105),
            ),
            dict(case="cyl_nu0.30", model="FEM", stage="reference", status="ok"),
        ]
    )


def test_family_frame_takes_fitted_rows_never_the_heldout_best_and_rules_as_rows():
    from harness.report.nu_sweep import families_of, family_frame

    f = family_frame(family_rows())
    assert list(f["model"]) == [
        "springs",
        "springs+volume-shared",
        "p1",
        "rule: lloyd",
        "rule: vangelder",
    ]
    assert list(f["kind"]) == ["class"] * 3 + ["rule"] * 2
    assert list(f["fit"]) == ["select: springs-prior1", "lbfgs", "none", "none", "none"]
    assert families_of(f) == ["sag", "tip", "torsion", "bridge"]
    row = f.set_index("model")
    # springs+volume-shared is its fitted row (held-out mean 0.40), not its unfitted one (0.01)
    assert row.loc["springs+volume-shared", "G_heldout_mean"] == pytest.approx(0.40)
    # tip is the mean of tip and tip2: (0.05 + 0.15) / 2 for the fit, (0.1 + 0.3) / 2 for lloyd
    assert row.loc["springs", "tip"] == pytest.approx(0.10) and row.loc[
        "rule: lloyd", "tip"
    ] == pytest.approx(0.2)
    assert row.loc["rule: lloyd", "sag"] == pytest.approx(0.2) and row.loc[
        "rule: lloyd", "bridge"
    ] == pytest.approx(0.5)
    assert row.loc["springs", "G_heldout_mean_spread"] == pytest.approx(0.01)
    assert math.isnan(row.loc["rule: vangelder", "G_heldout_mean_spread"])


def test_family_frame_computes_the_mean_where_rows_predate_it_and_is_empty_without_heldout_loads():
    from harness.report.nu_sweep import family_frame

    df = family_rows().drop(columns=["G_heldout_mean", "G_heldout_mean_spread"])
    f = family_frame(df).set_index("model")
    assert f.loc["rule: lloyd", "G_heldout_mean"] == pytest.approx(
        (0.2 + 0.1 + 0.3 + 0.4 + 0.5) / 5
    )
    assert family_frame(rows()).empty  # no G_heldout_<load> columns: no family table


def test_finding_names_the_winner_its_margin_and_the_best_rule():
    from harness.report.nu_sweep import family_frame, finding

    # springs 0.10, p1 0.105: the gap 0.005 is outside a spread of 0.001
    s = finding(family_frame(family_rows(spread=0.001)))
    assert s == (
        "cyl, nu = 0.3: springs wins on held-out loads, mean G 0.1 against 0.105 for p1 "
        "(the next), "
        "1.05x lower; the best unfitted rule, vangelder, 0.2."
    )


def test_finding_is_a_tie_inside_the_spread_over_starts():
    from harness.report.nu_sweep import family_frame, finding

    s = finding(family_frame(family_rows(spread=0.01)))
    assert s == (
        "cyl, nu = 0.3: tie on held-out loads between springs (0.1) and p1 (0.105): the gap "
        "is inside "
        "the fit's spread over its starts (0.01)."
    )


def test_finding_merges_a_fit_that_kept_the_rule_with_that_rule():
    """A validated fit whose choice is the rule has the rule's constants: one entry."""
    from harness.report.nu_sweep import family_frame, finding

    df = family_rows(spread=0.0, choice="rule")
    lloyd = df.index[
        (df["model_class"] == "springs")
        & (df["optimizer"] == "none")
        & (df["stiffness"] == "lloyd")
    ]
    fit = df.index[df["choice"].notna()]
    for c in ["G_heldout_mean"] + [f"G_heldout_{n}" for n in LOADS]:
        df.loc[lloyd, c] = df.loc[fit, c].to_numpy()
    f = family_frame(df)
    assert f.loc[f["model"] == "springs", "fit"].iloc[0] == "select: rule"
    s = finding(f)
    assert (
        s.startswith(
            "cyl, nu = 0.3: springs = rule: lloyd wins on held-out loads, mean G 0.1 against 0.105 "
            "for p1 (the next), 1.05x lower"
        )
        and "best unfitted rule" not in s
    )


def test_markdown_section_and_family_figure(tmp_path):
    from harness.report.nu_sweep import markdown_section

    two = pd.concat(
        [family_rows(), family_rows().assign(case="cyl_nu0.45", nu=0.45)], ignore_index=True
    )
    md = "\n".join(markdown_section(two))
    assert "## Held-out loads per family against Poisson's ratio" in md and "### cyl" in md
    assert md.count("wins on held-out loads") + md.count("tie on held-out loads") == 2
    assert (
        "| model | fit | sag | tip | torsion | bridge | mean | spread | fitted G | status |" in md
    )
    assert "| rule: vangelder | none | 0.1 | 0.2 | 0.2 | 0.3 | 0.2 |  | 0.4 | ok |" in md
    assert markdown_section(rows()) == []
    two.to_csv(tmp_path / "summary.csv", index=False)
    out = fig.make(tmp_path)
    assert [p.name for p in out] == ["fig-nu-sweep.png", "fig-nu-sweep-families.png"]
    assert all(p.stat().st_size > 1000 for p in out)


def test_a_fitted_row_without_normalised_heldout_g_gets_it_from_the_cases_reference_norm():
    """mt's fitted row reports G_<load> but no G_heldout_<load>: with the norms of the
    case's other rows (G_<load> / G_heldout_<load>, here 0.1 for every load; springs
    agrees), 0.005 -> 0.05; a case whose rows disagree on a norm keeps NaN."""
    from harness.report.nu_sweep import family_frame

    raw = {f"G_{n}": 0.1 * g for n, g in zip(LOADS, (0.2, 0.1, 0.3, 0.4, 0.5))}
    base = dict(case="cyl_nu0.30", dim=3, nu=0.3, status="ok", n_nodes=10)
    mt = dict(base, model_class="mt", stiffness="mt")
    df = pd.DataFrame(
        [
            dict(
                base,
                model_class="springs",
                stiffness="lloyd",
                optimizer="none",
                G_norm_final=0.3,
                **held(0.2, 0.1, 0.3, 0.4, 0.5),
                **raw,
            ),
            dict(mt, optimizer="none", G_norm_final=0.4, **held(0.2, 0.1, 0.3, 0.4, 0.5), **raw),
            dict(
                mt, optimizer="least-squares", G_norm_final=0.2, **{f"G_{n}": 0.005 for n in LOADS}
            ),
        ]
    )
    f = family_frame(df).set_index("model")
    assert f.loc["mt", "sag"] == pytest.approx(0.05) and f.loc[
        "mt", "G_heldout_mean"
    ] == pytest.approx(0.05)
    assert bool(f.loc["mt", "heldout_derived"]) and not f.loc["springs", "heldout_derived"]
    df.loc[0, "G_sag"] = 0.03  # the norms disagree: no sag derived
    f = family_frame(df).set_index("model")
    assert math.isnan(f.loc["mt", "sag"]) and f.loc["mt", "tip"] == pytest.approx(0.05)
