"""The curated headline tables of each suite (README's), built from a stored summary.csv.

``headline_tables(suite, df)`` returns ``[(title, table, note)]``: ``table`` is a DataFrame
of display strings (numbers already formatted), so the HTML page only escapes and lays it
out. A suite without a curated builder gets the generic one-line-per-case table of
:func:`harness.report.frames.headline_frame`. Nothing is recomputed: every number is a column of
summary.csv, a mean over seeds of one, or a ratio of two shown numbers.
"""

from __future__ import annotations

import math

from harness.registry import REPORT_TABLES
from harness.report.frames import REF_COARSE, SCORED, headline_frame, optimizer_frame
from harness.report.numbers import fmt
from harness.report.text import case_label

ARROW = " \u2192 "
DASH = "\u2013"
METHOD_NAMES = {
    "sa": "SA",
    "sa-refactor": "SA (refactor)",
    "lbfgs": "L-BFGS-B",
    "gauss-newton": "Gauss-Newton",
    "nelder-mead": "Nelder-Mead",
    "equilibrium-gap": "equilibrium gap",
}


def given(v) -> str:
    """A paper's number as the paper printed it (2.8, not 2.80); "" if missing."""
    return f"{float(v):g}" if v is not None and math.isfinite(float(v)) else ""


def pair(a, b, digits: int = 3) -> str:
    """``a → b``, or one number when nothing changed, or "" when both are missing."""
    fa, fb = fmt(a, digits), fmt(b, digits)
    if not fa or not fb or fa == fb:
        return fb or fa
    return f"{fa}{ARROW}{fb}"


def _worst(status) -> str:
    s = set(map(str, status))
    return "error" if "error" in s else REF_COARSE if REF_COARSE in s else "ok"


def _scored(df):
    return df[df["status"].isin(SCORED)] if "status" in df else df


def _col(df, name):
    """Column ``name`` or an all-NaN one (a quick or foreign run may lack it)."""
    import pandas as pd

    return df[name] if name in df else pd.Series(math.nan, index=df.index)


def _fits(df, objective: str = "G"):
    """Optimised rows (an optimiser other than none) with the given objective."""
    if "optimizer" not in df:
        return df.iloc[:0]
    opt = df[df["optimizer"].notna() & (df["optimizer"].astype(str) != "none")]
    return opt[_col(opt, "objective").fillna("G") == objective]


def _mean(g, col):
    v = _col(g, col)
    return float(v.mean()) if v.notna().any() else math.nan


def _seeds(g) -> int:
    return int(g["seed"].nunique()) if "seed" in g else 1


def _label(case, n_seeds) -> str:
    return case_label(case) + (f" (mean of {n_seeds} seeds)" if n_seeds > 1 else "")


# -- Deussen 1995 -------------------------------------------------------------------------


def deussen_tables(df) -> list:
    import pandas as pd

    out = []
    fits = _fits(_scored(df))
    rows = []
    for case, g in fits.groupby("case", sort=False):
        methods = list(dict.fromkeys(g["optimizer"].astype(str)))
        m = "sa" if "sa" in methods else methods[0]
        f = g[g["optimizer"] == m]
        g0, g1 = _mean(f, "G_initial"), _mean(f, "G_final")
        p0, p1 = _mean(f, "paper_G_initial"), _mean(f, "paper_G_final")
        ours = g0 / g1 if g1 > 0 else math.nan
        paper = p0 / p1 if p1 > 0 else math.nan
        rows.append(
            {
                "case": _label(case, _seeds(f)),
                "weights": next(iter(_col(f, "weights").dropna().astype(str)), ""),
                "springs": fmt(_mean(f, "n_springs")),
                "fit": METHOD_NAMES.get(m, m),
                "G before → after": pair(g0, g1),
                "paper G before → after": f"{given(p0) or DASH}{ARROW}{given(p1)}"
                if math.isfinite(p1)
                else DASH,
                "improvement ours / paper": " / ".join(
                    f"{fmt(v, 2)}x" if math.isfinite(v) else DASH for v in (ours, paper)
                ),
                "normalised G before → after": pair(
                    _mean(f, "G_norm_initial"), _mean(f, "G_norm_final")
                ),
                "held-out G (normalised)": pair(
                    _mean(f, "G_heldout_initial"), _mean(f, "G_heldout")
                ),
                "G_ref": fmt(_mean(f, "G_ref"), 2),
                "status": _worst(f["status"]) if "status" in f else "",
            }
        )
    if rows:
        out.append(
            (
                "Deussen 1995: G before and after the fit, ours beside the paper's",
                pd.DataFrame(rows),
                "G is G_{a:b:c} with the case's weights, ours in metres; the paper's G is "
                "in units it does "
                "not state, so compare the improvement factors (G before / G after), not "
                "the values. "
                "Held-out: sag and tip loads never fitted. The fit is SA with the paper's "
                "schedule where "
                "the case ran it.",
            )
        )
    for item in (_optimizers_table(df), _heldout_table(df), _rules_table(df), _frequency_table(df)):
        if item:
            out.append(item)
    return out


def _optimizers_table(df):
    import pandas as pd

    opts = optimizer_frame(df)
    if opts.empty:
        return None
    opts = opts[opts["objective"].fillna("G") == "G"]
    methods = list(dict.fromkeys(opts["optimizer"].astype(str)))
    rows = []
    for case, g in opts.groupby("case", sort=False):
        g = g[g["model"] == g["model"].iloc[0]]
        row = {
            "case": _label(case, int(g["n_seeds"].max())),
            "constants": fmt(_mean(g, "n_params")),
        }
        for m in methods:
            r = g[g["optimizer"] == m]
            row[f"{METHOD_NAMES.get(m, m)}: G (s)"] = (
                f"{fmt(_mean(r, 'G_final'))} ({fmt(_mean(r, 'seconds'), 2)})" if len(r) else ""
            )
        lb = g[g["optimizer"] == "lbfgs"]
        if len(lb) and "evals_to_sa_G" in lb:
            row["L-BFGS-B evaluations to SA's G"] = fmt(_mean(lb, "evals_to_sa_G"))
        rows.append(row)
    return (
        "Optimisers compared on the same initial model (G, wall seconds)",
        pd.DataFrame(rows).fillna(""),
        "Same reference, weights and start per case; means over seeds. The seconds are this "
        "run's, on a "
        "busy machine they vary; G does not.",
    )


def _heldout_table(df):
    import pandas as pd

    sc = _scored(df)
    if (
        not {"G_heldout", "G_norm_final", "optimizer", "stiffness"} <= set(sc)
        or not sc["G_heldout"].notna().any()
    ):
        return None
    rows = []
    for case, g in sc.groupby("case", sort=False):
        rules = g[g["optimizer"].astype(str) == "none"].dropna(subset=["G_norm_final"])
        row = {"case": _label(case, _seeds(g))}
        if len(rules):
            means = rules.groupby("stiffness")[["G_norm_final", "G_heldout"]].mean()
            best = means["G_norm_final"].idxmin()
            row["best rule, no fit: fitted / held-out"] = (
                f"{best}: {fmt(means.loc[best, 'G_norm_final'])} / "
                f"{fmt(means.loc[best, 'G_heldout'])}"
            )
        fits = _fits(g)
        for m in dict.fromkeys(fits["optimizer"].astype(str)):
            f = fits[fits["optimizer"] == m]
            row[f"{METHOD_NAMES.get(m, m)}: fitted / held-out"] = (
                f"{fmt(_mean(f, 'G_norm_final'))} / {fmt(_mean(f, 'G_heldout'))}"
            )
        if len(row) > 1:
            rows.append(row)
    if not rows:
        return None
    return (
        "Held-out loads: normalised G on the fitted loads / on loads no fit saw",
        pd.DataFrame(rows).fillna(""),
        "A model that only memorised its training loads has a small fitted G and a large "
        "held-out G.",
    )


def _rules_table(df):
    sc = _scored(df)
    if not {"G_norm_final", "optimizer", "stiffness"} <= set(sc):
        return None
    rules = sc[sc["optimizer"].astype(str) == "none"].dropna(subset=["G_norm_final"])
    if rules.empty:
        return None
    t = rules.pivot_table(
        index="case", columns="stiffness", values="G_norm_final", aggfunc="mean", sort=False
    )
    t = t.map(fmt).reset_index()
    t["case"] = [case_label(c) for c in t["case"]]
    t.columns.name = None
    return (
        "Stiffness rules before any fit (normalised G on the fitted loads)",
        t,
        "Each rule sets every spring constant from the geometry and the material alone "
        "(means over seeds).",
    )


def _frequency_table(df):
    import pandas as pd

    f = _fits(_scored(df), "G+freq")
    if f.empty:
        return None
    rows = [
        {
            "case": _label(case, _seeds(g)),
            "fit": METHOD_NAMES.get(str(g["optimizer"].iloc[0]), ""),
            "frequency error before → after": pair(
                _mean(g, "freq_error_initial"), _mean(g, "freq_error_final")
            ),
            "G after": fmt(_mean(g, "G_final")),
        }
        for case, g in f.groupby("case", sort=False)
    ]
    return (
        "Fits with the frequency term (Deussen Sec. 8)",
        pd.DataFrame(rows),
        "RMS relative error of the first natural frequencies against the FEM's, and G of "
        "the same fit.",
    )


# -- Bourguignon & Cani 2000 ----------------------------------------------------------------


# -- verification ---------------------------------------------------------------------------


def verification_tables(df) -> list:
    """One row per case and check: what the FEM reference was verified against (the
    closed form where the load has one, else its own two-mesh error estimate; the
    cantilever's first frequency against Euler-Bernoulli) and to which error."""
    import pandas as pd

    rows = []
    for case, g in df.groupby("case", sort=False):
        method = (
            str(_col(g, "ref_method").dropna().iloc[0])
            if _col(g, "ref_method").notna().any()
            else ""
        )
        fem = f"{method}, {fmt(_col(g, 'n_dofs').max())} dofs".strip(", ")
        tol = _mean(g, "ref_tol")
        closed, est = _col(g, "closed_form_error"), _col(g, "error_estimate")
        has = closed.notna()
        for what, errs, loads in (
            ("closed-form solution", closed[has], g[has]),
            (
                "its own error estimate (no closed form)",
                est[~has & est.notna()],
                g[~has & est.notna()],
            ),
        ):
            if len(errs):
                rows.append(
                    {
                        "case": case_label(case),
                        "FEM": fem,
                        "verified against": what,
                        "loads": ", ".join(map(str, _col(loads, "load").dropna()))
                        or str(len(errs)),
                        "error (max)": fmt(errs.max(), 2),
                        "within tol": f"{int((errs <= tol).sum())} of {len(errs)} (tol {tol:g})"
                        if math.isfinite(tol)
                        else "",
                    }
                )
        f1 = _mean(g, "f1_eb_ratio")
        if math.isfinite(f1):
            rows.append(
                {
                    "case": case_label(case),
                    "FEM": fem,
                    "verified against": "Euler-Bernoulli first frequency",
                    "loads": "modes",
                    "error (max)": fmt(abs(f1 - 1), 2),
                    "within tol": "",
                }
            )
    if not rows:
        return []
    return [
        (
            "What the FEM reference was verified against, and to which error",
            pd.DataFrame(rows),
            "Errors relative to the largest displacement (frequency: relative). A closed "
            "form is met to rounding; "
            "elsewhere the reference is only as good as its estimate (the difference from a "
            "refined mesh), and "
            "a load above tol is ref-coarse: its rows are kept and flagged in every table.",
        )
    ]


def generic_tables(df) -> list:
    h = headline_frame(df)
    if h.empty:
        return []
    t = h.copy()
    for c in t.columns:
        if t[c].dtype.kind == "f":
            t[c] = t[c].map(fmt)
    t["case"] = [case_label(c) for c in t["case"]]
    return [
        (
            "One line per case",
            t.fillna(""),
            "Best stiffness rule and best fit by normalised G on the fitted loads; "
            "G_heldout of that fit; "
            "G_ref the reference's own error.",
        )
    ]


# sections that show their figures and findings (harness/report/claims.py), no table
FINDINGS_ONLY = "nu_sweep"


def headline_tables(suite: str, df) -> list:
    """[(title, DataFrame of strings, note)] for the suite folder named ``suite``."""
    if df.empty or "case" not in df or suite in FINDINGS_ONLY:
        return []
    build = REPORT_TABLES.load(suite) if suite in REPORT_TABLES else generic_tables
    tables = build(df)
    return tables or generic_tables(df)
