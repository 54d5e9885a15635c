"""Derived tables of a suite's summary: one line per case (the console summary of a run)
and the optimisers side by side. Plain functions of the summary DataFrame, shared by the
Markdown tables (:mod:`harness.report.build`) and the results page (:mod:`harness.report.page`)."""

from __future__ import annotations

import math

SCORED = ("ok", "ref-coarse")  # row statuses whose numbers count (ref-coarse: kept, flagged)
REF_COARSE = "ref-coarse"


OPTIMIZER_COLUMNS = (
    ["case", "model", "optimizer", "objective", "n_seeds", "n_params"]
    + ["budget", "G_initial", "G_final", "G_final_vs_sa", "G_norm_final"]
    + ["G_ref", "G_heldout", "status", "seconds", "seconds_to_sa_G"]
    + ["opt_evaluations", "evals_to_sa_G", "opt_iterations", "opt_stop"]
    + ["opt_at_bounds", "jac_rank", "jac_cond_logk", "jac_cond_k", "f1_ratio"]
    + ["freq_error_initial", "freq_error_final"]
)


def headline_frame(df):
    """One line per case, what a person reads first: the worst status, the best stiffness
    rule and the best fit (normalised G on the fitted loads), the fit's G on held-out
    loads, the reference's own error (G_ref) and the case's seconds; cases without a G
    (dynamics experiments) show their status and a pointer to summary.md."""
    import pandas as pd

    out = []
    for case, g in df.groupby("case", sort=False):
        row = {"case": case, "rows": len(g)}
        status = g["status"].astype(str) if "status" in g else pd.Series(dtype=str)
        row["status"] = (
            "error"
            if (status == "error").any()
            else REF_COARSE
            if (status == REF_COARSE).any()
            else "ok"
        )
        scored = g[g["G_norm_final"].notna()] if "G_norm_final" in g else g.iloc[:0]
        if "optimizer" in scored:  # sms: rules (no optimiser) and fits
            opt = scored["optimizer"].astype(str)
            rules, fits, label = scored[opt == "none"], scored[opt != "none"], "optimizer"
        else:  # bc2000 fem: one calibrated row per model
            rules, fits, label = scored.iloc[:0], scored, "model"
        if len(rules):
            r = rules.loc[rules["G_norm_final"].idxmin()]
            row.update(best_rule=r["stiffness"], G_norm_rule=r["G_norm_final"])
        if len(fits):
            f = fits.loc[fits["G_norm_final"].idxmin()]
            row.update(
                best_fit=f[label],
                G_norm_fit=f["G_norm_final"],
                G_heldout=f.get("G_heldout", math.nan),
            )
        if "G_ref" in scored and scored["G_ref"].notna().any():
            row["G_ref"] = scored["G_ref"].max()
        if "seconds" in g:
            row["seconds"] = g["seconds"].sum()
        if not len(scored):
            row["note"] = (
                "; ".join(sorted({str(e) for e in g.get("error", pd.Series()).dropna()}))[:80]
                or "see summary.md"
            )
        out.append(row)
    order = ["case", "rows", "status", "best_rule", "G_norm_rule", "best_fit", "G_norm_fit"]
    order += ["G_heldout", "G_ref", "seconds", "note"]
    frame = pd.DataFrame(out)
    return frame[[c for c in order if c in frame]]


def optimizer_frame(df):
    """The optimised rows side by side (SA vs L-BFGS-B on the same cases): one
    line per case, model, optimizer and objective, numbers averaged over seeds (spread in
    seeds.csv); ``G_final_vs_sa`` = G_final / G_final of the case's SA row, same seed."""
    import pandas as pd

    if df.empty or "optimizer" not in df:
        return pd.DataFrame()
    opt = df[df["optimizer"].notna() & (df["optimizer"] != "none")]
    if "status" in opt:
        opt = opt[opt["status"].isin(SCORED)]
    if opt.empty or opt.groupby("case")["optimizer"].nunique().max() < 2:
        return pd.DataFrame()
    opt = opt.copy()
    if "objective" not in opt:
        opt["objective"] = "G"
    opt["objective"] = opt["objective"].fillna("G")
    sa = opt[(opt["optimizer"] == "sa") & (opt["objective"] == "G")].set_index(["case", "seed"])[
        "G_final"
    ]
    sa = sa[~sa.index.duplicated()]
    opt["G_final_vs_sa"] = [
        g / sa.get((c, s), math.nan) for c, s, g in zip(opt["case"], opt["seed"], opt["G_final"])
    ]
    keys = ["case", "model", "optimizer", "objective"]
    num = [
        c
        for c in OPTIMIZER_COLUMNS
        if c in opt and c not in keys and pd.api.types.is_numeric_dtype(opt[c])
    ]
    text = [c for c in ("budget", "opt_stop") if c in opt]
    g = opt.groupby(keys, sort=False, dropna=False)
    out = g[num].mean()
    for c in text:
        out[c] = g[c].first()
    if "status" in opt:  # flagged if any seed's row is
        out["status"] = g["status"].agg(lambda s: REF_COARSE if (s == REF_COARSE).any() else "ok")
    out.insert(0, "n_seeds", g["seed"].nunique())
    out = out.reset_index()
    return out[[c for c in OPTIMIZER_COLUMNS if c in out]]
