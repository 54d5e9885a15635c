"""The findings the page and README open with, one sentence each with its number, generated
from the suites' stored summaries (nothing recomputed, nothing typed in by hand): what each
suite shows, and per suite the lists of findings its section shows (the nu sweep's per
body and nu, the verification's per check). A suite these do not know gets the generic
sentences of :func:`generic` (memorised fits, fits worse than the rule); the ref-coarse
rows of every suite are counted in one last sentence."""

from __future__ import annotations

import math

from harness.report.engines import engines_finding
from harness.report.findings import MEMORISED, case_lines
from harness.report.headlines import fmt
from harness.report.nu_sweep import family_frame, findings


def _num(df, col):
    import pandas as pd

    return (
        pd.to_numeric(df[col], errors="coerce")
        if col in df
        else pd.Series(math.nan, index=df.index)
    )


def _range(values, digits=2, unit="") -> str:
    v = [x for x in values if math.isfinite(x)]
    if not v:
        return ""
    lo, hi = min(v), max(v)
    return (
        f"{fmt(lo, digits)}{unit}"
        if fmt(lo, digits) == fmt(hi, digits)
        else f"{fmt(lo, digits)}{unit} to {fmt(hi, digits)}{unit}"
    )


def generic(name: str, df) -> list[str]:
    """Memorised fits and fits worse than the best rule held out."""
    lines = case_lines(df)
    scored = lines[lines["fitted"].notna() & (lines["fitted"] == lines["fitted"])]
    out = []
    n = len(scored)
    mem = scored[[("memorised" in f) for f in scored["findings"]]]
    worse = scored[[("fit-worse-than-rule" in f) for f in scored["findings"]]]
    if n and len(mem):
        w = mem.loc[(mem["heldout"] / mem["fitted"]).idxmax()]
        out.append(
            f"{name}: the best fit memorised its training loads in {len(mem)} of {n} cases "
            "(held-out G above "
            f"{MEMORISED:g}x the fitted G; worst {w['case']}: {fmt(w['heldout'])} held out against "
            f"{fmt(w['fitted'])} fitted)."
        )
    if n and len(worse):
        out.append(
            f"{name}: in {len(worse)} of {n} cases the best fit predicts the held-out loads "
            "worse than the "
            f"best stiffness rule does without any fit."
        )
    return out


def coarse(df) -> tuple[int, int]:
    """(ref-coarse rows, scored rows) of a summary."""
    if "status" not in df:
        return 0, 0
    st = df["status"].astype(str)
    return int((st == "ref-coarse").sum()), int(st.isin(("ok", "ref-coarse")).sum())


def deussen(df) -> list[str]:
    """SA's improvement factor against the paper's, and the generic ones."""
    sa = (
        df[(df.get("optimizer") == "sa") & (df.get("objective").fillna("G") == "G")]
        if "optimizer" in df
        else df.iloc[:0]
    )
    out = []
    if len(sa):
        g = sa.groupby("case", sort=False)
        ours = (g["G_initial"].mean() / g["G_final"].mean()).tolist()
        paper = (
            [(p0 / p1) for p0, p1 in zip(g["paper_G_initial"].mean(), g["paper_G_final"].mean())]
            if {"paper_G_initial", "paper_G_final"} <= set(sa)
            else []
        )
        paper = [p for p in paper if math.isfinite(p)]
        ours = [x for x in ours if math.isfinite(x)]
        if ours:
            text = (
                f"Deussen 1995: simulated annealing lowers G by {_range(ours, 2, 'x')} on "
                f"the paper's {len(ours)} plate and box cases"
            )
            out.append(
                text
                + (
                    f" (the paper: {_range(paper, 2, 'x')} where it gives both numbers)."
                    if paper
                    else "."
                )
            )
    return out + generic("Deussen 1995", df)


def bourguignon(df) -> list[str]:
    out = []
    v = df[df["case"] == "volume_cube343"] if "case" in df else df.iloc[:0]
    mt = v[v.get("model") == "MT"] if len(v) else v
    if len(mt) and "peak_abs_dV_percent" in mt and _num(mt, "peak_abs_dV_percent").notna().any():
        peak, paper = (
            float(_num(mt, "peak_abs_dV_percent").max()),
            float(_num(mt, "paper_peak_abs_dV_percent").max()),
        )
        dev = float(
            _num(
                df[df["case"].astype(str).str.startswith("volume_")], "max_dev_vs_original_percent"
            ).max()
        )
        out.append(
            f"Bourguignon & Cani 2000: MT keeps cube_343's volume within {fmt(peak)} % "
            "under gravity"
            + (f" (the paper: under {fmt(paper)} %)" if math.isfinite(paper) else "")
            + (
                f", and our volume curves match the original program's records to {fmt(dev, 2)} %"
                if math.isfinite(dev)
                else ""
            )
            + "."
        )
    fem = (
        df[df["case"].astype(str).str.startswith("fem_") & df["G_norm_final"].notna()]
        if "G_norm_final" in df
        else df.iloc[:0]
    )
    fitted = fem[fem.get("model").isin(("MT0", "MT"))] if len(fem) else fem
    if len(fitted):
        start = _range(_num(fitted, "G_norm_initial"))
        out.append(
            f"Bourguignon & Cani 2000: calibrated against the FEM, MT0 and MT reach normalised G "
            f"{_range(_num(fitted, 'G_norm_final'))} on the cube_333 cases"
            + (f" ({start} with the program's own constants, scaled)." if start else ".")
        )
    return out


def verification(df) -> list[str]:
    """What the reference was verified against, and to which error."""
    out = []
    closed = _num(df, "closed_form_error")
    est = _num(df, "error_estimate")
    tol = _num(df, "ref_tol")
    if closed.notna().any():
        out.append(
            "FEM reference: it meets the closed-form solution of "
            f"{int(closed.notna().sum())} loads to "
            f"{fmt(float(closed.max()), 2)} (relative to the largest displacement: rounding)."
        )
    other, tols = est[closed.isna()], tol[closed.isna()]
    if other.notna().any():
        within = int((other <= tols).sum())
        out.append(
            f"FEM reference: on {int(other.notna().sum())} loads without a closed form its "
            "own error "
            f"estimate is {fmt(float(other.min()), 2)} to {fmt(float(other.max()), 2)}"
            + (
                f", within its tolerance ({float(tol.max()):g}) on {within} of them."
                if tol.notna().any()
                else " (no tolerance recorded)."
            )
        )
    f1 = _num(df, "f1_eb_ratio").dropna()
    if len(f1):
        out.append(
            "FEM reference: the cantilever's first frequency is "
            f"{fmt(abs(float(f1.iloc[0]) - 1) * 100, 2)} % "
            f"from Euler-Bernoulli's beam formula."
        )
    return out


def nu_sweep(df) -> list[str]:
    """Per body: at how many Poisson ratios a fitted class beats the best unfitted rule on
    held-out loads (outside the fit's spread over its starts), and by how much."""
    frame = family_frame(df)
    out = []
    for body, b in frame.groupby("body", sort=True) if not frame.empty else ():
        wins, ratios, n = 0, [], 0
        for _, g in b.groupby("nu", sort=True):
            cls = g[(g["kind"] == "class") & (g["fit"] != "none") & g["G_heldout_mean"].notna()]
            rules = g[(g["kind"] == "rule") & g["G_heldout_mean"].notna()]
            if cls.empty or rules.empty:
                continue
            n += 1
            c = cls.loc[cls["G_heldout_mean"].idxmin()]
            r = float(rules["G_heldout_mean"].min())
            spread = (
                float(c["G_heldout_mean_spread"])
                if math.isfinite(float(c["G_heldout_mean_spread"]))
                else 0.0
            )
            ratios.append(float(c["G_heldout_mean"]) / r if r > 0 else math.nan)
            wins += bool(float(c["G_heldout_mean"]) < r - spread)
        if n:
            out.append(
                f"Poisson-ratio map, {body}: a fitted model class beats the best unfitted "
                "stiffness rule on "
                f"held-out loads at {wins} of {n} Poisson ratios (its held-out error "
                f"{_range(ratios, 2, 'x')} the rule's)."
            )
    return out


def engines(df) -> list[str]:
    """The engine table's sentence (harness/report/engines.py)."""
    return [f"Engines: {engines_finding(df)}"] if "engine" in df else []


NAMES = {
    "deussen1995": "Deussen 1995",
    "bourguignon2000": "Bourguignon & Cani 2000",
    "verification": "verification",
    "nu_sweep": "the Poisson-ratio map",
    "engines": "the engine table",
}
CLAIMS = {
    "deussen1995": deussen,
    "bourguignon2000": bourguignon,
    "verification": verification,
    "nu_sweep": nu_sweep,
    "engines": engines,
}


def headline_findings(suites) -> list[str]:
    """The sentences the page opens with, suite by suite (folders holding a summary.csv)."""
    import pandas as pd

    out, counts = [], []
    for suite in suites:
        try:
            df = pd.read_csv(suite / "summary.csv")
        except (OSError, ValueError, pd.errors.EmptyDataError):
            continue
        if df.empty or "case" not in df:
            continue
        make = CLAIMS.get(suite.name)
        try:
            out += make(df) if make else generic(suite.name, df)
        # a foreign or partial summary: no sentence, never a crash
        except (KeyError, TypeError, ValueError):
            continue
        # there: the estimate against tol
        k, m = coarse(df) if suite.name != "verification" else (0, 0)
        if k:
            counts.append(f"{k} of {m} in {NAMES.get(suite.name, suite.name)}")
    if counts:
        out.append(
            f"Ref-coarse rows: {', '.join(counts)}: there the FEM's own error is above a "
            "tenth of the "
            "model's (or missed its tolerance), so those G are partly the reference's; "
            "they stay in every "
            f"table, flagged."
        )
    return out


def suite_lists(name: str, df) -> list[tuple[str, list[str]]]:
    """[(heading, sentences)] a suite's section shows below its tables: the nu sweep's
    finding per body and nu (harness/report/nu_sweep.py: the lowest held-out mean wins,
    gaps inside the fit's spread over its starts are ties)."""
    if name != "nu_sweep":
        return []
    out: dict[str, list[str]] = {}
    for body, _, sentence in findings(family_frame(df)):
        out.setdefault(body, []).append(sentence.removeprefix(f"{body}, "))
    return [
        (f"{body}: which model predicts the held-out loads best, per Poisson ratio", lines)
        for body, lines in out.items()
    ]
