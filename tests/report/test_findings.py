"""The findings vocabulary (harness/report/findings.py) and calibrate's verdict sentences on
hand-made rows whose answers are worked out here: a fit worse than the best rule held out,
a tie inside the spread over starts, a better fit, an exported rule, no held-out loads;
memorised (held-out G > 3 x fitted) and ref-coarse."""

from __future__ import annotations

import math

import numpy as np
import pytest

from harness.commands.calibrate_verdict import heldout_sentence, reference_sentence, verdict
from harness.optimize.gradient import scipy_stop
from harness.report.findings import MEMORISED, against_rule, flags, heldout_error

RULES = [
    dict(
        stiffness="lloyd",
        optimizer="none",
        G_norm_final=0.30,
        G_heldout=0.20,
        G_heldout_mean=0.1200,
    ),
    dict(
        stiffness="vangelder",
        optimizer="none",
        G_norm_final=0.25,
        G_heldout=0.10,
        G_heldout_mean=0.0926,
    ),
    dict(
        stiffness="uniform",
        optimizer="none",
        G_norm_final=0.40,
        G_heldout=0.50,
        G_heldout_mean=math.nan,
    ),
]
NAMES = ("sag", "tip", "bridge")


def fit(mean, spread=0.0, fitted=0.10, pooled=0.11, **kw):
    """A fitted row: held-out error ``mean`` (G_heldout_mean), pooled G_heldout ``pooled``."""
    return dict(
        stiffness="vangelder",
        optimizer="lbfgs",
        G_norm_final=fitted,
        G_heldout=pooled,
        G_heldout_mean=mean,
        G_heldout_mean_spread=spread,
        **kw,
    )


def test_the_newcomers_case_is_fit_worse_than_rule():
    """0.0940 held out against the best rule's 0.0926 (the rule on fitted loads would hide it)."""
    row = fit(0.0940, spread=0.0005)
    assert verdict(row, RULES) == ("fit-worse-than-rule", RULES[1])
    text = heldout_sentence(row, RULES, NAMES)
    assert "the fit 9.4 %" in text and "the best rule (vangelder) 9.26 %" in text
    assert (
        "fit worse than the rule on held-out loads: export the rule instead (--method rule "
        "--rule vangelder)" in text
    )
    assert flags(row, RULES) == ["fit-worse-than-rule"]


@pytest.mark.parametrize(
    "mean, spread, want",
    [
        (0.0930, 0.0005, "tie"),
        (0.0922, 0.0005, "tie"),
        (0.0900, 0.0005, "better"),
        (0.0926, 0.0, "tie"),
    ],
)
def test_ties_are_inside_the_spread(mean, spread, want):
    assert against_rule(fit(mean, spread), RULES) == (want, RULES[1])
    text = heldout_sentence(fit(mean, spread), RULES, NAMES)
    assert ("a tie within the spread over starts" in text) == (want == "tie")
    if want == "better":
        assert f"x{0.0900 / 0.0926:.2f} the rule's error" in text


def test_an_exported_rule_is_compared_with_the_best_rule_in_hindsight():
    mine = dict(RULES[0], optimizer="lbfgs", choice="rule")  # the validation kept the rule lloyd
    assert verdict(mine, RULES)[0] == "rule"
    text = heldout_sentence(mine, RULES, NAMES)
    assert (
        "the exported rule (lloyd) 12 %" in text
        and "--method rule --rule vangelder exports that one" in text
    )
    assert "it is the best of the rules there" in heldout_sentence(RULES[1], RULES, NAMES)
    near = dict(RULES[0], stiffness="near", G_heldout_mean=RULES[1]["G_heldout_mean"] * 1.015)
    assert "a tie (within 2%)" in heldout_sentence(near, RULES, NAMES)  # 1.5 % apart: no ranking
    far = dict(near, G_heldout_mean=RULES[1]["G_heldout_mean"] * 1.03)
    assert "--method rule --rule vangelder exports that one" in heldout_sentence(far, RULES, NAMES)


def test_no_heldout_loads_says_so():
    rules = [dict(r, G_heldout=math.nan, G_heldout_mean=math.nan) for r in RULES]
    assert verdict(fit(math.nan, pooled=math.nan), rules) == (None, None)
    assert heldout_sentence(fit(math.nan, pooled=math.nan), rules, ()).startswith(
        "No held-out loads"
    )


def test_memorised_is_held_out_over_three_times_fitted_and_only_for_fits():
    assert "memorised" in flags(fit(MEMORISED * 0.10 * 1.01, fitted=0.10), RULES)
    assert "memorised" not in flags(fit(MEMORISED * 0.10 * 0.99, fitted=0.10, pooled=1.0), RULES)
    # pooled: no mean
    assert "memorised" in flags(fit(math.nan, fitted=0.10, pooled=MEMORISED * 0.10 * 1.01), RULES)
    # a rule memorises nothing
    assert flags(dict(RULES[2], status="ref-coarse"), RULES) == ["ref-coarse"]
    assert heldout_error(RULES[2]) == 0.50  # no per-load mean: the pooled G


def test_reference_sentence_names_where_the_fem_is_coarse():
    meta = dict(
        status="ref-coarse",
        reference_error=0.08,
        reference_error_heldout=0.005,
        reference_error_fitted=0.08,
    )
    # 0.02 > 0.005: fitted only
    row = fit(0.05, fitted=0.05, pooled=0.06, G_ref=0.02, G_ref_heldout=0.001)
    text = reference_sentence(row, meta, True, 1)
    assert text.startswith(
        "Reference ref-coarse (FEM error <= 0.5 % on held-out loads, 8 % on fitted ones)"
    )
    assert "on the fitted loads is above a tenth" in text and "--max-refine 2" in text
    ok = reference_sentence(dict(row, G_ref=0.001), dict(meta, status="ok"), True, 1)
    assert ok.startswith("Reference ok") and "the model's" in ok


def test_scipys_empty_detail_is_filled_in():
    """scipy >= 1.15 says "ABNORMAL: " for a failed line search (a gradient of the wrong
    sign gives one here); the stop message says what that means."""
    from scipy.optimize import minimize

    res = minimize(lambda x: (float(x @ x), -2 * x), np.ones(3), jac=True, method="L-BFGS-B")
    stop = scipy_stop(res)
    assert res.status == 2 and stop.startswith("scipy: ABNORMAL") and "line search" in stop
    good = minimize(lambda x: (float(x @ x), 2 * x), np.ones(3), jac=True, method="L-BFGS-B")
    assert scipy_stop(good) == f"scipy: {good.message}"


def test_case_lines_pick_the_fitters_row_and_flag_it():
    """A hand-made summary: two seeds of a case whose L-BFGS-B fit (lowest fitted G) is
    memorised and worse than the rule lloyd held out; a case of rules only; a case without G."""
    import pandas as pd

    from harness.report.findings import case_lines, legend, summary_text

    rows = []
    for seed in (0, 1):
        rows += [
            dict(
                case="a",
                seed=seed,
                model="m[lloyd]",
                optimizer="none",
                stiffness="lloyd",
                status="ok",
                G_norm_final=0.20,
                G_heldout=0.10 + 0.02 * seed,
            ),
            dict(
                case="a",
                seed=seed,
                model="m[lloyd]",
                optimizer="sa",
                objective="G",
                stiffness="lloyd",
                status="ok",
                G_norm_final=0.05,
                G_heldout=0.12,
            ),
            dict(
                case="a",
                seed=seed,
                model="m[lloyd]",
                optimizer="lbfgs",
                objective="G",
                stiffness="lloyd",
                status="ref-coarse" if seed else "ok",
                G_norm_final=0.03,
                G_heldout=0.30 + 0.1 * seed,
            ),
            dict(
                case="a",
                seed=seed,
                model="m[lloyd]",
                optimizer="lbfgs",
                objective="G+freq",
                stiffness="lloyd",
                status="ok",
                G_norm_final=0.01,
                G_heldout=0.01,
            ),
        ]
    rows += [
        dict(
            case="b",
            seed=0,
            model="m[cauchy]",
            optimizer="none",
            stiffness="cauchy",
            status="ok",
            G_norm_final=0.3,
            G_heldout=0.2,
        ),
        dict(case="c", seed=0, model="FEM", status="ok"),
        dict(case="c", seed=0, model="FEM", status="error"),
    ]
    lines = case_lines(pd.DataFrame(rows)).set_index("case")
    a = lines.loc["a"]
    assert a.model == "lbfgs" and a.n_seeds == 2  # G+freq is not the G fit a fitter exports
    assert a.fitted == pytest.approx(0.03) and a.heldout == pytest.approx(0.35)  # means over seeds
    # 0.35 > 3 x 0.03; > 0.11
    assert a.findings == ["ref-coarse", "memorised", "fit-worse-than-rule"]
    assert lines.loc["b"].model == "rule cauchy" and lines.loc["b"].findings == []
    assert lines.loc["c"].model == "" and lines.loc["c"].findings == ["error"]
    text = summary_text("demo", lines.reset_index())
    assert text[0].split() == ["case", "model", "G_norm", "fitted", "/", "held-out", "status"]
    assert (
        "a (2 seeds)" in text[1]
        and "0.03 / 0.35" in text[1]
        and text[1].endswith("fit-worse-than-rule")
    )
    # the numbers are right-aligned under the header
    edge = text[0].index("held-out") + len("held-out")
    assert text[1][:edge].endswith("0.03 / 0.35") and text[2][:edge].endswith("0.3 / 0.2")
    assert text[3][:edge].endswith(" -") and text[3].split()[1] == "-"
    assert [ln.split(":")[0].strip() for ln in legend(lines["findings"])] == [
        "ref-coarse",
        "memorised",
        "fit-worse-than-rule",
    ]


def test_headline_sentences_carry_the_numbers_of_hand_made_tables():
    """The page's findings on small summaries whose answers are worked out here."""
    import pandas as pd

    from harness.report.claims import deussen, nu_sweep, verification

    d = pd.DataFrame(
        [
            dict(
                case="f8",
                seed=0,
                optimizer="sa",
                objective="G",
                G_initial=2.0,
                G_final=0.5,
                paper_G_initial=2.8,
                paper_G_final=0.55,
                status="ok",
                G_norm_final=0.1,
                G_heldout=0.1,
            ),
            dict(
                case="f9",
                seed=0,
                optimizer="sa",
                objective="G",
                G_initial=3.0,
                G_final=0.1,
                status="ok",
                G_norm_final=0.01,
                G_heldout=0.5,
            ),
            dict(
                case="f9",
                seed=0,
                optimizer="none",
                stiffness="lloyd",
                status="ok",
                G_norm_final=0.2,
                G_heldout=0.2,
            ),
        ]
    )
    said = deussen(d)
    assert said[0].startswith(
        "Deussen 1995: simulated annealing lowers G by 4x to 30x on the paper's 2 "
    )
    assert "(the paper: 5.1x where it gives both numbers)" in said[0]  # 2.8 / 0.55
    assert (
        "memorised its training loads in 1 of 2 cases" in said[1]
        and "f9: 0.500 held out against 0.0100" in said[1]
    )
    assert said[2] == (
        "Deussen 1995: in 1 of 2 cases the best fit predicts the held-out loads worse than "
        "the best "
        "stiffness rule does without any fit."
    )
    v = pd.DataFrame(
        [
            dict(
                case="b",
                load="stretch-x",
                closed_form_error=2e-13,
                error_estimate=3e-13,
                ref_tol=1e-4,
            ),
            dict(case="b", load="shear-xy", error_estimate=5e-5, ref_tol=1e-4),
            dict(case="b", load="shear-yx", error_estimate=2e-3, ref_tol=1e-4),
            dict(case="c", load="tip", error_estimate=1e-5, ref_tol=1e-4, f1_eb_ratio=0.9986),
        ]
    )
    said = verification(v)
    assert said[0].startswith(
        "FEM reference: it meets the closed-form solution of 1 loads to 2.0e-13"
    )
    assert "on 3 loads without a closed form its own error estimate is 1.0e-05 to 0.0020" in said[1]
    assert said[1].endswith("within its tolerance (0.0001) on 2 of them.")
    assert said[2] == (
        "FEM reference: the cantilever's first frequency is 0.14 % from Euler-Bernoulli's "
        "beam formula."
    )
    rows = []
    for nu, fit, rule, spread in (
        (0.1, 0.05, 0.10, 0.0),
        (0.3, 0.099, 0.10, 0.002),
        (0.45, 0.20, 0.10, 0.0),
    ):
        rows += [
            dict(
                case=f"bar_nu{nu}",
                model_class="springs",
                nu=nu,
                optimizer="lbfgs",
                objective="G",
                stiffness="lloyd",
                G_norm_final=0.05,
                G_heldout_sag=fit,
                G_heldout_mean=fit,
                G_heldout_mean_spread=spread,
                status="ok",
            ),
            dict(
                case=f"bar_nu{nu}",
                model_class="springs",
                nu=nu,
                optimizer="none",
                stiffness="lloyd",
                G_norm_final=0.2,
                G_heldout_sag=rule,
                G_heldout_mean=rule,
                status="ok",
            ),
        ]
    said = nu_sweep(pd.DataFrame(rows))
    # nu 0.1 wins; 0.3 is inside the spread (0.099 vs 0.100 +- 0.002); 0.45 loses
    assert said == [
        "Poisson-ratio map, bar: a fitted model class beats the best unfitted stiffness "
        "rule on held-out "
        "loads at 1 of 3 Poisson ratios (its held-out error 0.50x to 2x the rule's)."
    ]


def test_a_capped_rule_is_still_a_rule():
    """calibrate --method rule --k-ratio: the exported row is a rule's constants, capped."""
    capped = dict(RULES[0], optimizer="none+k-ratio 10")
    assert verdict(capped, RULES)[0] == "rule" and "the exported rule (lloyd)" in heldout_sentence(
        capped, RULES, NAMES
    )
    # 0.12 > 0.0926
    assert verdict(dict(capped, optimizer="lbfgs+k-ratio 10"), RULES)[0] == "fit-worse-than-rule"


def test_the_engine_tables_finding_and_summary_say_what_a_hand_made_table_holds():
    """Two engines and one springbench export on one body at nu 0.3 and 0.49, numbers
    chosen here: the sentence gives the spans at each nu and the settled count; the
    summary has one column per engine and model and names a load that did not settle."""
    import pandas as pd

    from harness.report.bench_tables import bench_table, engines_finding

    rows = []
    for nu, own, ours, status in (
        (0.3, (0.20, 0.25), 0.05, "settled"),
        (0.49, (0.50, 0.70), 0.10, "not-settled"),
    ):
        for engine, g in zip(("newton-tets", "mujoco-flex"), own):
            rows += [
                dict(
                    body="b",
                    n_tets=100,
                    nu=nu,
                    engine=engine,
                    model="own (E, nu)",
                    load=load,
                    G_norm=g,
                    status="settled",
                )
                for load in ("sag", "mean")
            ]
        rows += [
            dict(
                body="b",
                n_tets=100,
                nu=nu,
                engine="newton-springs",
                model="springbench rule: rule learned",
                load="sag",
                G_norm=ours,
                status=status,
            ),
            dict(
                body="b",
                n_tets=100,
                nu=nu,
                engine="newton-springs",
                model="springbench rule: rule learned",
                load="mean",
                G_norm=ours,
                status="see loads" if status != "settled" else "settled",
            ),
        ]
    df = pd.DataFrame(rows)
    text = engines_finding(df)
    assert "20-25 % from the FEM at nu = 0.3" in text and "50-70 % at nu = 0.49" in text
    assert "are 5-10 % at every nu" in text and "5 of 6 engine runs settled" in text
    table, note = bench_table("engines", df)
    assert list(table.columns) == (
        ["body", "tets", "nu", "newton-tets: own (E, nu)"]
        + ["mujoco-flex: own (E, nu)", "newton-springs: springbench rule"]
    )
    assert table.iloc[1]["newton-springs: springbench rule"] == "0.100 (see loads)" and text in note
    from harness.report.engines import engines_tables  # the suite's summary.csv: engine_status

    [(_, suite_table, suite_note)] = engines_tables(df.rename(columns={"status": "engine_status"}))
    assert suite_table.equals(table) and text in suite_note


def test_calibrates_verdict_says_memorised_as_run_flags_it():
    """The liver's numbers: fitted 1.86 %, held out 16.6 % (8.9x, above MEMORISED = 3):
    calibrate's held-out sentence says so, as `springbench run` flags the row; at 2.9x not."""
    names = ["sag", "tip"]
    liver = fit(0.166, fitted=0.0186, pooled=0.17)
    said = heldout_sentence(liver, RULES, names)
    assert "Memorised: its held-out error is 8.9x its fitted one (above 3x)" in said
    assert "memorised" in flags(liver, RULES)
    fine = fit(0.029, fitted=0.010, pooled=0.03)
    assert "Memorised" not in heldout_sentence(fine, RULES, names)
    assert "memorised" not in flags(fine, RULES)


def test_the_engine_findings_say_per_load_where_a_calibrated_material_helps_and_hurts():
    """A hand-made table: one fitted pair in mujoco-flex at two nu (sag 0.5x and 0.8x the
    engine's own error: geometric mean 0.63x; torsion 1.5x at both: it hurts there), and a
    per-tetrahedron material in newton-tets that helps on both loads."""
    import pandas as pd

    from harness.report.engines import engines_finding, material_findings

    rows = []
    own = {"sag": 0.4, "torsion": 0.2}
    fitted = {
        ("mujoco-flex", "springbench p1-global: E 9e+04 Pa, nu 0.400"): {
            0.3: {"sag": 0.2, "torsion": 0.3},
            0.45: {"sag": 0.32, "torsion": 0.3},
        },
        ("newton-tets", "springbench p1: a material per tetrahedron"): {
            0.3: {"sag": 0.1, "torsion": 0.1},
            0.45: {"sag": 0.1, "torsion": 0.1},
        },
    }
    for nu in (0.3, 0.45):
        for engine in ("mujoco-flex", "newton-tets"):
            rows += [
                dict(
                    body="b", n_tets=9, nu=nu, engine=engine, model="own (E, nu)", load=n, G_norm=g
                )
                for n, g in own.items()
            ]
        for (engine, model), by_nu in fitted.items():
            rows += [
                dict(body="b", n_tets=9, nu=nu, engine=engine, model=model, load=n, G_norm=g)
                for n, g in by_nu[nu].items()
            ]
    df = pd.DataFrame(rows).assign(engine_status="settled")
    mujoco, newton = material_findings(df)
    assert mujoco == (
        "p1-global in mujoco-flex against its own (E, nu): sag x0.63, torsion x1.5; "
        "it hurts on torsion"
    )
    assert newton.startswith("p1 in newton-tets") and "sag x0.25, torsion x0.5" in newton
    assert newton.endswith("it helps on every load")
    means = [dict(r, load="mean") for r in rows]  # the finding reads the load rows
    assert mujoco in engines_finding(
        pd.concat([df, pd.DataFrame(means).assign(engine_status="settled")])
    )
