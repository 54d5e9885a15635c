"""The engine table (the engines suite's summary.csv and the bench's engines.csv): each
engine's mean G_norm per body, mesh and nu as display strings, and its one-sentence finding.
Nothing is recomputed but means over the stored rows."""

from __future__ import annotations

from harness.engines import EXTRA
from harness.report.figures.engines import who
from harness.report.numbers import fmt


def _engine_status(df) -> str:
    """The column holding the engines' settled / diverged ... (the suite's engine_status,
    the bench CSV's status)."""
    return "engine_status" if "engine_status" in df.columns else "status"


def _cell(r, st: str) -> str:
    """One engine's cell: its mean G_norm, and why when it found no equilibrium or is not
    installed."""
    if r[st] == "not-installed" or r.get("status") == "not-installed":
        return "not installed"
    note = str(r.get("note") or "")
    if r[st] == "settled" and note.startswith("the mean over "):  # the loads it takes
        return f"{fmt(r['G_norm'])} ({note.removeprefix('the mean over ')})"
    return fmt(r["G_norm"]) if r[st] == "settled" else f"{fmt(r['G_norm']) or '-'} ({r[st]})"


def engines_summary(df):
    """Per body, mesh and nu: each engine's (and springbench export's) mean G_norm over the
    held-out loads; a cell says why when an engine found no equilibrium or is not
    installed."""
    import pandas as pd

    st = _engine_status(df)
    if not {"body", "nu", "engine", "model", "load", "G_norm", st} <= set(df.columns):
        return None
    m = df[df["load"] == "mean"].copy()
    m["who"] = m["engine"] + ": " + who(m["model"])
    rows = []
    for (body, tets, nu), g in m.groupby(["body", "n_tets", "nu"], sort=False, dropna=False):
        row = {"body": body, "tets": fmt(tets), "nu": f"{nu:g}" if nu == nu else "-"}
        for _, r in g.iterrows():
            row[r["who"]] = _cell(r, st)
        rows.append(row)
    return pd.DataFrame(rows).fillna("") if rows else None


def _span(g) -> str:
    """The range of mean G_norm of ``g`` in percent ("3-25 %", "4 %")."""
    lo, hi = f"{100 * g['G_norm'].min():.0f}", f"{100 * g['G_norm'].max():.0f}"
    return f"{lo} %" if lo == hi else f"{lo}-{hi} %"


def _by_nu(g) -> str:
    """How far ``g``'s models are from the FEM at the lowest and highest nu it has."""
    nus = g["nu"][g["nu"].notna()] if "nu" in g else g.iloc[:0]
    if nus.empty:
        return f"{_span(g)} from the FEM"
    lo, hi = float(nus.min()), float(nus.max())
    text = f"{_span(g[g['nu'] == lo])} from the FEM at nu = {lo:g}"
    return text if lo == hi else f"{text} and {_span(g[g['nu'] == hi])} at nu = {hi:g}"


def _not_installed(runs, st: str) -> list[str]:
    """The engines whose rows say their package is missing."""
    gone = runs[st] == "not-installed"
    if "status" in runs:
        gone |= runs["status"] == "not-installed"
    return sorted(map(str, runs.loc[gone, "engine"].dropna().unique()))


def _and(names) -> str:
    names = list(names)
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def engines_finding(df) -> str:
    """One sentence from the engine table: how far the engines' own models and
    springbench's exports are from the FEM (mean G_norm over the held-out loads) at the
    lowest and highest nu, which engines are not installed (and the extra that installs
    them), and how many engine runs settled."""
    st = _engine_status(df)
    if not {"load", "engine", "model", "G_norm", st} <= set(df.columns):
        return "The engine table has no engine runs."
    m = df[(df["load"] == "mean") & _has(df["G_norm"])]
    runs = df[df["load"] != "mean"]
    ours = m["model"].astype(str).str.startswith("springbench")
    own, exported = m[~ours], m[ours & ~_materials(m["model"])]
    parts = []
    if len(own):
        names = ", ".join(sorted(map(str, own["engine"].unique())))
        parts.append(f"the engines' own models ({names}) are {_by_nu(own)}")
    if len(exported):
        nus = exported["nu"].dropna().unique()
        every = " at every nu" if len(nus) > 1 else f" at nu = {nus[0]:g}" if len(nus) else ""
        engines = _and(sorted(map(str, exported["engine"].unique())))
        parts.append(f"springbench's spring exports ({engines}) are {_span(exported)}{every}")
    parts += material_findings(df)
    gone = _not_installed(runs, st)
    if gone:
        verb = "is" if len(gone) == 1 else "are"
        parts.append(f"{_and(gone)} {verb} not installed ({EXTRA} installs the engines)")
    ran = runs[~runs["engine"].isin(gone) & (runs[st] != "unsupported-load")]
    if len(ran):
        parts.append(f"{int((ran[st] == 'settled').sum())} of {len(ran)} engine runs settled")
    untaken = runs[runs[st] == "unsupported-load"]
    if len(untaken):
        names = sorted(map(str, untaken["engine"].unique()))
        verb = "takes" if len(names) == 1 else "take"
        parts.append(f"{_and(names)} {verb} the gravity loads only ({len(untaken)} not run)")
    if not (len(own) or len(exported)):
        parts.insert(0, "no engine run was scored against the FEM")
    text = "; ".join(parts)
    return text[:1].upper() + text[1:] + "."


def _materials(model_column):
    """Which rows are calibrated materials for the engines' tetrahedra (p1-global, p1)."""
    return model_column.astype(str).str.match(r"springbench (p1-global|p1):")


def material_findings(df) -> list[str]:
    """Per engine and calibrated material (p1-global, p1), per load: the geometric mean over
    the bodies, meshes and nu of its G_norm over the engine's own (E, nu) G_norm on the same
    case and load, and where it helps (< 1) and where it hurts (> 1)."""
    import numpy as np

    # a case names its body, mesh and nu (which may be missing from a partial table)
    keys = [k for k in ("case", "seed") if k in df.columns] or [
        k for k in ("body", "resolution", "n_tets", "nu") if k in df.columns
    ]
    runs = df[(df["load"] != "mean") & _has(df["G_norm"])].copy()
    runs["G_norm"] = runs["G_norm"].astype(float)
    own = runs[runs["model"] == "own (E, nu)"].set_index([*keys, "engine", "load"])["G_norm"]
    mats = runs[_materials(runs["model"])]
    out = []
    for (engine, label), g in mats.groupby(["engine", who(mats["model"])], sort=True):
        plain = own.reindex(_index(g, [*keys, "engine", "load"])).to_numpy()
        ok = np.isfinite(plain) & (plain > 0)
        if not ok.any():
            continue
        ratio = g["G_norm"].to_numpy()[ok] / plain[ok]
        per = g[ok].assign(r=np.log(ratio)).groupby("load", sort=False)["r"].mean().apply(np.exp)
        loads = ", ".join(f"{name} x{r:.2g}" for name, r in per.items())
        hurts = [name for name, r in per.items() if r > 1]
        tail = f"; it hurts on {_and(hurts)}" if hurts else "; it helps on every load"
        what = label.replace("springbench ", "")
        out.append(f"{what} in {engine} against its own (E, nu): {loads}{tail}")
    return out


def _index(g, keys):
    """The MultiIndex of ``g``'s ``keys`` columns."""
    import pandas as pd

    return pd.MultiIndex.from_frame(g[keys])


def _has(col):
    """Which entries of ``col`` are numbers."""
    import pandas as pd

    return pd.to_numeric(col, errors="coerce").notna()


def engines_note(df) -> str:
    """What the engine table holds, from its rows: the loads, the metric, which engines ran
    springbench's spring exports and whether its calibrated materials and the gravity-only
    engines are in it."""
    models = df["model"].astype(str) if "model" in df else df.iloc[:0, :0]
    springs = df.loc[models.str.startswith("springbench") & ~_materials(models), "engine"]
    runs = ", ".join(sorted(map(str, springs.dropna().unique()))) or "Newton"
    text = (
        "Each engine's deformable body against the FEM on gmsh bodies at two resolutions: the "
        "mean over the held-out loads (sag, tip, tip2, torsion, bridge) of the RMS "
        "displacement error relative to the FEM's (G_norm); springbench's exports (the best "
        f"rule, the calibrated springs) run in {runs}"
    )
    if _materials(models).any():
        text += (
            "; its calibrated materials (p1-global: one pair; p1: one per tetrahedron) in "
            "the engines' own tetrahedra"
        )
    gravity = sorted(set(map(str, df.get("engine", []))) & {"pybullet-fem", "drake-fem"})
    if gravity:
        text += f"; {_and(gravity)} on the gravity loads (sag, bridge)"
    return text + ". "


def engines_tables(df) -> list:
    """[(title, table, note)] of the engines suite."""
    t = engines_summary(df)
    if t is None:
        return []
    return [
        (
            "Each engine's deformable body against the FEM",
            t,
            engines_note(df)
            + engines_finding(df)
            + " Every load, step count and wall time is in summary.csv.",
        )
    ]
