"""The engine table (the engines suite's summary.csv and the bench's engines.csv): each
engine's mean G_norm per body, mesh and nu as display strings, and its one-sentence finding.
Nothing is recomputed but means over the stored rows."""

from __future__ import annotations

from harness.report.figures.engines import who
from harness.report.numbers import fmt


def _engine_status(df) -> str:
    """The column holding the engines' settled / diverged ... (the suite's engine_status,
    the bench CSV's status)."""
    return "engine_status" if "engine_status" in df.columns else "status"


def engines_summary(df):
    """Per body, mesh and nu: each engine's (and springbench export's) mean G_norm over the
    held-out loads; a cell says why when an engine found no equilibrium."""
    import pandas as pd

    st = _engine_status(df)
    if not {"body", "nu", "engine", "model", "load", "G_norm", st} <= set(df.columns):
        return None
    m = df[df["load"] == "mean"].copy()
    m["who"] = m["engine"] + ": " + who(m["model"])
    rows = []
    for (body, tets, nu), g in m.groupby(["body", "n_tets", "nu"], sort=False):
        row = {"body": body, "tets": fmt(tets), "nu": f"{nu:g}"}
        for _, r in g.iterrows():
            row[r["who"]] = (
                fmt(r["G_norm"]) if r[st] == "settled" else f"{fmt(r['G_norm'])} ({r[st]})"
            )
        rows.append(row)
    return pd.DataFrame(rows).fillna("") if rows else None


def engines_finding(df) -> str:
    """One sentence from the engine table: how far the engines' own models and
    springbench's exports are from the FEM (mean G_norm over the held-out loads) at the
    lowest and highest nu, and how many engine runs settled."""
    st = _engine_status(df)
    m = df[(df["load"] == "mean") & df["G_norm"].notna()]
    runs = df[df["load"] != "mean"]
    own = m[~m["model"].astype(str).str.startswith("springbench")]
    ours = m[m["model"].astype(str).str.startswith("springbench")]
    lo, hi = float(m["nu"].min()), float(m["nu"].max())

    def span(g) -> str:
        return (
            f"{100 * g['G_norm'].min():.0f}-{100 * g['G_norm'].max():.0f} %"
            if len(g)
            else "not run"
        )

    engines = ", ".join(sorted(own["engine"].unique()))
    return (
        f"The engines' own models ({engines}) are {span(own[own['nu'] == lo])} from the FEM "
        f"at nu = {lo:g} and "
        f"{span(own[own['nu'] == hi])} at nu = {hi:g}; springbench's exports run in Newton "
        f"are {span(ours)} at "
        f"every nu; {int((runs[st] == 'settled').sum())} of {len(runs)} engine runs settled."
    )


ENGINES_NOTE = (
    "Each engine's deformable body against the FEM on gmsh bodies at two resolutions: the "
    "mean over "
    "the held-out loads (sag, tip, tip2, torsion, bridge) of the RMS displacement error relative "
    "to the FEM's (G_norm); springbench's exports (the best rule, the calibrated model) run in "
    "Newton. "
)


def engines_tables(df) -> list:
    """[(title, table, note)] of the engines suite."""
    t = engines_summary(df)
    if t is None:
        return []
    return [
        (
            "Each engine's deformable body against the FEM",
            t,
            ENGINES_NOTE
            + engines_finding(df)
            + " Every load, step count and wall time is in summary.csv.",
        )
    ]
