"""The benchmarks as tables of display strings (``springbench bench NAME`` writes
bench/NAME.csv): the columns that say what was measured, numbers to 3 digits; the held-out
benchmark as its summary (calibrate's error against the best rule's, per body and nu). A
benchmark without a curated view shows its first columns. Nothing is recomputed but that
summary's geometric mean of the stored ratios."""

from __future__ import annotations

import numpy as np

from harness.provenance import FIELDS, describe
from harness.report.engines import engines_finding, engines_note, engines_summary
from harness.report.numbers import fmt

MAX_ROWS = 40
COLUMNS = {  # bench name -> the columns shown, in order (those present)
    "calibrate": (
        ["body", "n_tets", "seconds", "rule_seconds", "fit_ratio", "peak_gb", "choice"]
        + ["fit_level", "start_rule", "G_heldout_mean", "best_rule"]
        + ["G_heldout_mean_best_rule", "reference_error_heldout"]
    ),
    "reference": (
        ["task", "dim", "element", "n_dofs", "solver", "method", "seconds"]
        + ["ratio", "true_error", "estimate"]
    ),
    "sa": (
        ["dim", "n_springs", "method", "engine", "steps_per_s", "acceptance"]
        + ["G_ratio", "speedup"]
    ),
    "fit": (
        ["dim", "n_springs", "method", "init", "noise", "G_ratio"]
        + ["G_truth_ratio", "seconds", "stop", "met"]
    ),
    "dynamics": ["bench", "case", "engine", "value", "unit", "ratio", "ratio_to_cxx"],
    "run": (
        ["command", "cases", "wall_s", "cpu_s", "cpu_per_core_s", "runs_mb", "peak_gb"]
        + ["cores", "load_1min", "exit", "target_wall_s", "target_mb"]
    ),
}


def tets_summary(df):
    """Per body, mesh and nu (and overall): the geometric mean over the loads of the plain
    tetrahedra's error and, for each calibrated material, its error, its ratio to the
    plain's (below 1: it helps) and its pair (p1-global)."""
    import pandas as pd

    need = {"body", "nu", "model", "load", "err", "ratio_to_plain"}
    if not need <= set(df.columns):
        return None
    geo = df[df["load"] == "geomean"]
    rows = []
    for (body, nu), at in geo.groupby(["body", "nu"], sort=False, dropna=False):
        at = at.set_index("model")
        row = {"body": body, "tets": fmt(at["n_tets"].iloc[0]) if "n_tets" in at else ""}
        row["nu"] = f"{nu:g}" if nu == nu else ""
        row["plain error"] = fmt(at.loc["plain", "err"]) if "plain" in at.index else ""
        for m in ("p1-global", "p1"):
            if m in at.index:
                row[f"{m} error"] = fmt(at.loc[m, "err"])
                row[f"{m} / plain"] = fmt(at.loc[m, "ratio_to_plain"])
        if "p1-global" in at.index and "E_effective" in at:
            E, nu_ = at.loc["p1-global", "E_effective"], at.loc["p1-global", "nu_effective"]
            row["p1-global (E', nu')"] = f"{fmt(E)} Pa, {nu_:.3f}" if E == E else ""
        rows.append(row)
    return pd.DataFrame(rows).fillna("") if rows else None


def _display(df, cols):
    t = df[[c for c in cols if c in df]].head(MAX_ROWS).copy()
    for c in t.columns:
        t[c] = [fmt(v) if isinstance(v, float) else ("" if v is None else str(v)) for v in t[c]]
    return t


def heldout_summary(df):
    """Per body, mesh and nu: calibrate's choice and the geometric mean over the loads of
    its error / the best rule's (the rule chosen in hindsight per mesh), < 1: calibrate wins."""
    import pandas as pd

    need = {"body", "nu", "model", "ratio_to_best_rule"}
    if not need <= set(df.columns):
        return None
    cal = df[df["model"] == "calibrate"]
    if "load" in cal:  # the per-load rows (the geomean row repeats them)
        cal = cal[cal["load"] != "geomean"]
    rows = []
    for (body, nu), g in cal.groupby(["body", "nu"], sort=True):
        r = pd.to_numeric(g["ratio_to_best_rule"], errors="coerce")
        r = r[r > 0]
        row = {
            "body": body,
            "tets": fmt(g["n_tets"].iloc[0]) if "n_tets" in g else "",
            "nu": f"{nu:g}",
            "choice": str(g["choice"].iloc[0]) if "choice" in g else "",
            "best rule": str(g["best_rule"].iloc[0]) if "best_rule" in g else "",
            "loads": str(len(r)),
            "calibrate / best rule (geometric mean)": fmt(float(np.exp(np.log(r).mean())))
            if len(r)
            else "",
        }
        if "truth_error" in g and g["truth_error"].notna().any():  # P2 unrefined vs the truth
            row["truth's error (at most)"] = fmt(float(g["truth_error"].max()))
        rows.append(row)
    return pd.DataFrame(rows) if rows else None


HELDOUT_NOTE = (
    "Each held-out gmsh body, its own loads and clamps, an independent P2 truth; per body and "
    "nu the geometric mean over the loads of calibrate's error / the best rule's (below 1: "
    "calibrate predicts better). Every load and rule is in heldout.csv."
)
TETS_NOTE = (
    "Calibrated materials for linear tetrahedra (calibrate --model p1-global: one pair; "
    "--model p1: one per tetrahedron) against the same tetrahedra with the plain (E, nu), on "
    "the held-out gmsh bodies with their own loads and clamps, an independent P2 truth: per "
    "body and nu the geometric mean over the loads of each error. Every load is in tets.csv."
)


def _engines_note(df) -> str:
    return (
        engines_note(df)
        + engines_finding(df)
        + " Every load, step count and wall time is in engines.csv."
    )


# benchmarks with a summary table of their own: name -> (summary(df) or None, note(df))
SUMMARIES = {
    "engines": (engines_summary, _engines_note),
    "heldout": (heldout_summary, lambda df: HELDOUT_NOTE),
    "tets": (tets_summary, lambda df: TETS_NOTE),
}


def bench_table(name: str, df):
    """(table of display strings, note) of one benchmark's CSV: its summary where it has one
    (SUMMARIES), else its key columns."""
    if name in SUMMARIES:
        summary, note = SUMMARIES[name]
        t = summary(df)
        if t is not None:
            return t, note(df)
    cols = COLUMNS.get(name) or [c for c in df.columns if not c.endswith("_version")][:8]
    more = f" (first {MAX_ROWS} of {len(df)} rows)" if len(df) > MAX_ROWS else ""
    return _display(df, cols), f"Key columns of {name}.csv{more}; every column is in the CSV."


def provenance_line(df) -> str:
    """The code and machine of a bench CSV (its first row's provenance columns)."""
    first = df.iloc[0] if len(df) else {}
    return describe({k: (first[k] if k in df.columns else None) for k in FIELDS})
