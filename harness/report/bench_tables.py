"""The benchmarks as tables of display strings (``springbench bench NAME`` writes
bench/NAME.csv): the columns that say what was measured, numbers to 3 digits; the held-out
benchmark as its summary (calibrate's error against the best rule's, per body and nu). A
benchmark without a curated view shows its first columns. Nothing is recomputed but that
summary's geometric mean of the stored ratios."""

from __future__ import annotations

from harness.report.headlines import fmt

MAX_ROWS = 40
COLUMNS = {   # bench name -> the columns shown, in order (those present)
    "calibrate": ["n_tets", "seconds", "rule_seconds", "peak_gb", "choice", "validation_skipped", "start_rule",
                  "G_heldout_mean", "best_rule", "G_heldout_mean_best_rule", "reference_error_heldout"],
    "reference": ["task", "dim", "element", "n_dofs", "solver", "method", "seconds", "ratio", "true_error",
                  "estimate"],
    "sa": ["dim", "n_springs", "method", "engine", "steps_per_s", "acceptance", "G_ratio", "speedup"],
    "fit": ["dim", "n_springs", "method", "init", "noise", "G_ratio", "G_truth_ratio", "seconds", "stop", "met"],
    "dynamics": ["bench", "case", "engine", "value", "unit", "ratio", "ratio_to_cxx"],
}


def _display(df, cols):
    t = df[[c for c in cols if c in df]].head(MAX_ROWS).copy()
    for c in t.columns:
        t[c] = [fmt(v) if isinstance(v, float) else ("" if v is None else str(v)) for v in t[c]]
    return t


def heldout_summary(df):
    """Per body, mesh and nu: calibrate's choice and the geometric mean over the loads of
    its error / the best rule's (the rule chosen in hindsight per mesh), < 1: calibrate wins."""
    import numpy as np
    import pandas as pd
    need = {"body", "nu", "model", "ratio_to_best_rule"}
    if not need <= set(df.columns):
        return None
    cal = df[df["model"] == "calibrate"]
    rows = []
    for (body, nu), g in cal.groupby(["body", "nu"], sort=True):
        r = pd.to_numeric(g["ratio_to_best_rule"], errors="coerce")
        r = r[r > 0]
        rows.append({"body": body, "tets": fmt(g["n_tets"].iloc[0]) if "n_tets" in g else "", "nu": f"{nu:g}",
                     "choice": str(g["choice"].iloc[0]) if "choice" in g else "",
                     "best rule": str(g["best_rule"].iloc[0]) if "best_rule" in g else "",
                     "loads": str(len(r)),
                     "calibrate / best rule (geometric mean)": fmt(float(np.exp(np.log(r).mean()))) if len(r) else ""})
    return pd.DataFrame(rows) if rows else None


def engines_summary(df):
    """Per body, mesh and nu: each engine's (and springbench export's) mean G_norm over the
    held-out loads; a cell says why when an engine found no equilibrium."""
    import pandas as pd
    if not {"body", "nu", "engine", "model", "load", "G_norm", "status"} <= set(df.columns):
        return None
    m = df[df["load"] == "mean"].copy()
    m["who"] = m["engine"] + ": " + m["model"].str.replace(r"springbench (\w+):.*", r"springbench \1", regex=True)
    rows = []
    for (body, tets, nu), g in m.groupby(["body", "n_tets", "nu"], sort=False):
        row = {"body": body, "tets": fmt(tets), "nu": f"{nu:g}"}
        for _, r in g.iterrows():
            row[r["who"]] = fmt(r["G_norm"]) if r["status"] == "settled" else f"{fmt(r['G_norm'])} ({r['status']})"
        rows.append(row)
    return pd.DataFrame(rows).fillna("") if rows else None


def engines_finding(df) -> str:
    """One sentence from the engine table: how far the engines' own models and
    springbench's exports are from the FEM (mean G_norm over the held-out loads) at the
    lowest and highest nu, and how many engine runs settled."""
    m = df[df["load"] == "mean"]
    runs = df[df["load"] != "mean"]
    own = m[~m["model"].astype(str).str.startswith("springbench")]
    ours = m[m["model"].astype(str).str.startswith("springbench")]
    lo, hi = float(m["nu"].min()), float(m["nu"].max())

    def span(g) -> str:
        return f"{100 * g['G_norm'].min():.0f}-{100 * g['G_norm'].max():.0f} %"
    engines = ", ".join(sorted(own["engine"].unique()))
    return (f"The engines' own models ({engines}) are {span(own[own['nu'] == lo])} from the FEM at nu = {lo:g} and "
            f"{span(own[own['nu'] == hi])} at nu = {hi:g}; springbench's exports run in Newton are {span(ours)} at "
            f"every nu; {int((runs['status'] == 'settled').sum())} of {len(runs)} engine runs settled.")


def bench_table(name: str, df):
    """(table of display strings, note) of one benchmark's CSV."""
    if name == "engines":
        t = engines_summary(df)
        if t is not None:
            return t, ("Each engine's deformable body against the FEM on gmsh bodies at two resolutions: the mean over "
                       "the held-out loads (sag, tip, tip2, torsion, bridge) of the RMS displacement error relative "
                       "to the FEM's (G_norm); springbench's exports (the best rule, the calibrated model) run in "
                       "Newton. " + engines_finding(df) + " Every load, step count and wall time is in engines.csv.")
    if name == "heldout":
        t = heldout_summary(df)
        if t is not None:
            return t, ("Each held-out gmsh body, its own loads and clamps, an independent P2 truth; per body and nu "
                       "the geometric mean over the loads of calibrate's error / the best rule's (below 1: calibrate "
                       "predicts better). Every load and rule is in heldout.csv.")
    cols = COLUMNS.get(name) or [c for c in df.columns if not c.endswith("_version")][:8]
    more = f" (first {MAX_ROWS} of {len(df)} rows)" if len(df) > MAX_ROWS else ""
    return _display(df, cols), f"Key columns of {name}.csv{more}; every column is in the CSV."


def provenance_line(df) -> str:
    """The code and machine of a bench CSV (its first row's provenance columns)."""
    from harness.provenance import FIELDS, describe
    first = df.iloc[0] if len(df) else {}
    return describe({k: (first[k] if k in df.columns else None) for k in FIELDS})

