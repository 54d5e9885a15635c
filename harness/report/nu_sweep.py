"""The nu-sweep map from a suite's summary rows. A body is the case name without its
``_nu<x>`` suffix.

- :func:`sweep_frame` / :func:`sweep_table`: per body, model class and Poisson ratio the
  class's row: its optimised row if it has one (the fitted constants; the springs
  class's validated fit), else its only row (``p1``, which has no constants).
- :func:`family_frame`: per body and nu the held-out error per load family (sag, tip,
  torsion, bridge) of each class's row and of each stiffness rule's unfitted row.
  Held-out loads never choose a row: a class is its fitted row whatever its held-out
  score, and the rules stand as rows of their own.
- :func:`finding`: one sentence per body and nu from that table: the row with the lowest
  held-out mean, by how much, or a tie when the gap is inside the fits' spread over
  their starts (``G_heldout_mean_spread``).
"""

from __future__ import annotations

import math
import re
import warnings

import numpy as np

from harness.report.markdown import markdown_table

COLUMNS = ("G_norm_final", "G_heldout", "freq_error_final", "k_spread", "dt_stable")
# central-force lattices: isotropic only here (2-D plane stress)
CAUCHY_NU = {2: 1.0 / 3.0, 3: 0.25}
FAMILIES = ("sag", "tip", "torsion", "bridge")  # the held-out families, in table order
# G_heldout_<x> columns that are no load
NOT_LOADS = ("initial", "mean", "mean_initial", "mean_spread")
RULE_CLASS = "springs"  # the rules' rows: this class's unfitted rows, one per stiffness rule


def _body(case) -> str:
    return re.sub(r"_nu[0-9.]+$", "", str(case))


def _scored(df):
    """The rows with a class, nu and G (no errors, no frequency-fitted rows), with
    ``body`` and ``fitted``; empty if the rows carry no ``model_class`` and ``nu``."""
    import pandas as pd

    need = {"case", "model_class", "nu", "G_norm_final"}
    if df.empty or not need <= set(df.columns):
        return pd.DataFrame()
    d = df.dropna(subset=["model_class", "nu", "G_norm_final"]).copy()
    if "status" in d:
        d = d[d["status"] != "error"]
    if "objective" in d:
        d = d[d["objective"].fillna("G") == "G"]
    if d.empty:
        return pd.DataFrame()
    d["body"] = [_body(c) for c in d["case"]]
    d["fitted"] = d["optimizer"].fillna("none") != "none" if "optimizer" in d else False
    return d


def _class_rows(d):
    """Each (body, model_class, nu)'s row: its last fitted row, else its last row."""
    return (
        d.sort_values("fitted", kind="stable")
        .groupby(["body", "model_class", "nu"], sort=False)
        .tail(1)
    )


def sweep_frame(df):
    """One line per (body, model_class, nu): COLUMNS of that row, sorted; empty if the
    rows carry no ``model_class`` and ``nu``."""
    import pandas as pd

    d = _scored(df)
    if d.empty:
        return pd.DataFrame()
    d = _class_rows(d)
    cols = ["body", "dim", "model_class", "nu"] + [c for c in COLUMNS if c in d]
    return (
        d[[c for c in cols if c in d]]
        .sort_values(["body", "model_class", "nu"])
        .reset_index(drop=True)
    )


def sweep_table(frame):
    """G_norm (fitted) and G_heldout per body and nu, one column pair per model class."""
    import pandas as pd

    if frame.empty:
        return pd.DataFrame()
    wide = frame.pivot_table(
        index=["body", "nu"],
        columns="model_class",
        values=[c for c in ("G_norm_final", "G_heldout") if c in frame],
    )
    wide.columns = [
        f"{cls}: {'G_norm' if v == 'G_norm_final' else 'G_heldout'}" for v, cls in wide.columns
    ]
    return wide[sorted(wide.columns)].reset_index()


def heldout_loads(columns) -> list[str]:
    """The held-out loads named by ``G_heldout_<load>`` columns (not _initial, _mean, ...)."""
    pre = "G_heldout_"
    return [c[len(pre) :] for c in columns if c.startswith(pre) and c[len(pre) :] not in NOT_LOADS]


def load_family(load: str) -> str:
    """A held-out load's family: its name without a trailing number (tip2 -> tip)."""
    return re.sub(r"\d+$", "", load) or load


def fill_heldout(d, loads, rtol: float = 1e-6):
    """``d`` with the missing G_heldout_<load> of a row derived from its G_<load> (not
    normalised) and the load's reference norm G_<load> / G_heldout_<load>, which every
    row of a case shares (same nodes, loads, weights and reference): taken only where the
    case's rows that carry both agree on it to ``rtol`` and on ``n_nodes``. A row whose
    stage reports G per load but no normalised held-out G (mt's fitted row) is then in
    the table like the others; ``heldout_derived`` marks it."""
    d = d.copy()
    d["heldout_derived"] = False
    for case, g in d.groupby("case", sort=False):
        if "n_nodes" in g and g["n_nodes"].nunique() > 1:
            continue
        for n in loads:
            raw, own = f"G_{n}", f"G_heldout_{n}"
            if raw not in g:
                continue
            both = g[g[raw].notna() & g[own].notna() & (g[own] > 0)]
            miss = g.index[g[own].isna() & g[raw].notna()]
            if both.empty or not len(miss):
                continue
            norm = (both[raw] / both[own]).to_numpy(float)
            if np.ptp(norm) > rtol * abs(norm).max():
                continue
            d.loc[miss, own] = d.loc[miss, raw] / norm.mean()
            d.loc[miss, "heldout_derived"] = True
    return d


def family_frame(df):
    """One line per (body, nu, model): the class rows (``kind`` "class", ``model`` the
    class, ``fit`` what fitted it: the springs class's ``select: <choice>``, else the
    optimiser) then the rule rows (``kind`` "rule", ``model`` "rule: <name>": the
    RULE_CLASS rows no optimiser touched), with one column per held-out family (the mean
    of its loads' own normalised G: tip of tip and tip2), ``G_heldout_mean`` (the mean
    over the loads; computed from them where the rows predate it),
    ``G_heldout_mean_spread``, ``G_norm_final`` and ``status``. Empty without sweep rows
    or held-out loads."""
    import pandas as pd

    d = _scored(df)
    loads = heldout_loads(d.columns) if not d.empty else []
    if not loads:
        return pd.DataFrame()
    d = fill_heldout(d, loads)
    fams = [f for f in FAMILIES if any(load_family(n) == f for n in loads)]
    fams += [f for f in dict.fromkeys(map(load_family, loads)) if f not in fams]
    classes = _class_rows(d).sort_index().assign(kind="class")  # in the rows' order
    classes["model"] = classes["model_class"]
    rules = d[(d["model_class"] == RULE_CLASS) & ~d["fitted"]].assign(kind="rule")
    if "stiffness" in rules:
        rules = rules.drop_duplicates(["body", "nu", "stiffness"])
        rules["model"] = "rule: " + rules["stiffness"].astype(str)
    else:
        rules = rules.iloc[:0]
    rows = pd.concat([classes, rules], ignore_index=True)
    fit = (
        rows["optimizer"].fillna("none").astype(str)
        if "optimizer" in rows
        else pd.Series("none", index=rows.index)
    )
    if "choice" in rows:
        fit = fit.where(rows["choice"].isna(), "select: " + rows["choice"].astype(str))
    rows["fit"] = fit.where(rows["kind"] == "class", "none")
    per = rows[[f"G_heldout_{n}" for n in loads]].to_numpy(float)
    for f in fams:
        rows[f] = _nanmean(per[:, [i for i, n in enumerate(loads) if load_family(n) == f]])
    mean = _nanmean(per)
    rows["G_heldout_mean"] = (
        rows["G_heldout_mean"].fillna(pd.Series(mean, index=rows.index))
        if "G_heldout_mean" in rows
        else mean
    )
    for c in ("G_heldout_mean_spread", "status", "dim"):
        if c not in rows:
            rows[c] = np.nan
    rows["_order"] = np.arange(len(rows))
    rows = rows.sort_values(["body", "nu", "_order"], kind="stable")
    cols = ["body", "dim", "nu", "kind", "model", "fit", *fams, "G_heldout_mean"]
    cols += ["G_heldout_mean_spread", "G_norm_final", "status", "heldout_derived"]
    return rows[cols].reset_index(drop=True)


def _nanmean(a):
    """Row means over the finite entries (NaN where none is)."""

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(a, axis=1)


def families_of(frame) -> list[str]:
    """The family columns of a :func:`family_frame`."""
    skip = {
        "body",
        "dim",
        "nu",
        "kind",
        "model",
        "fit",
        "G_heldout_mean",
        "G_heldout_mean_spread",
        "G_norm_final",
        "status",
        "heldout_derived",
    }
    return [c for c in frame.columns if c not in skip]


def _g(v: float) -> str:
    return f"{v:.3g}"


def _spread(row) -> float:
    s = row["G_heldout_mean_spread"]
    return float(s) if isinstance(s, (int, float)) and math.isfinite(s) else 0.0


def _merged(g) -> list[dict]:
    """The rows of ``g`` (sorted by G_heldout_mean) as dicts, rows of exactly equal
    held-out mean merged into one named by both ("springs = rule: lloyd": a validated
    fit that kept the rule is that rule)."""
    out = []
    for _, r in g.iterrows():
        r = dict(r, rule=r["kind"] == "rule")
        if out and r["G_heldout_mean"] == out[-1]["G_heldout_mean"]:
            last = out[-1]
            last.update(
                model=f"{last['model']} = {r['model']}",
                rule=last["rule"] or r["rule"],
                G_heldout_mean_spread=max(_spread(last), _spread(r)),
            )
        else:
            out.append(r)
    return out


def finding(group) -> str:
    """The sentence of one (body, nu) of a :func:`family_frame`: the row with the lowest
    ``G_heldout_mean`` wins by its gap to the next; rows whose gap to the winner is
    inside the larger ``G_heldout_mean_spread`` of the two (a fit's spread over its
    starts; none for a rule) tie with it. A fitted winner is set against the best
    unfitted rule too."""
    body, nu = group["body"].iloc[0], float(group["nu"].iloc[0])
    head = f"{body}, nu = {nu:g}: "
    rows = _merged(
        group[group["G_heldout_mean"].notna()].sort_values("G_heldout_mean", kind="stable")
    )
    if not rows:
        return head + "no row was scored on held-out loads."
    w = rows[0]
    if len(rows) == 1:
        return (
            head
            + f"only {w['model']} was scored on held-out loads (mean G {_g(w['G_heldout_mean'])})."
        )
    tol = [max(_spread(w), _spread(r)) for r in rows[1:]]
    tied = [r for r, t in zip(rows[1:], tol) if r["G_heldout_mean"] - w["G_heldout_mean"] <= t]
    if tied:
        names = " and ".join(f"{r['model']} ({_g(r['G_heldout_mean'])})" for r in [w] + tied)
        return (
            head
            + f"tie on held-out loads between {names}: the gap is inside the fit's spread over its "
            f"starts ({_g(max(t for r, t in zip(rows[1:], tol) if r in tied))})."
        )
    r = rows[1]
    a, b = float(w["G_heldout_mean"]), float(r["G_heldout_mean"])
    text = (
        head
        + f"{w['model']} wins on held-out loads, mean G {_g(a)} against {_g(b)} for {r['model']} "
        f"(the next), {_g(b / a) if a > 0 else 'inf'}x lower"
    )
    rules = [x for x in rows if x["rule"]]
    if not w["rule"] and rules and rules[0] is not r:
        name = rules[0]["model"].split("rule: ", 1)[-1]
        text += f"; the best unfitted rule, {name}, {_g(rules[0]['G_heldout_mean'])}"
    return text + "."


def findings(frame) -> list[tuple[str, float, str]]:
    """(body, nu, sentence) for every body and nu of a :func:`family_frame`."""
    if frame.empty:
        return []
    return [(b, float(nu), finding(g)) for (b, nu), g in frame.groupby(["body", "nu"], sort=True)]


def markdown_section(df) -> list[str]:
    """The summary.md lines of the held-out families: per body and nu its finding and
    its table (held-out G per family, their mean, the spread, the fitted loads' G)."""
    frame = family_frame(df)
    if frame.empty:
        return []
    fams = families_of(frame)
    out = [
        "\n## Held-out loads per family against Poisson's ratio\n",
        "Per body and nu, the normalised G on each held-out load family ("
        + ", ".join(f"`{f}`" for f in fams)
        + "; each the mean of its loads' own normalised G, `tip` of tip and tip2), never "
        "fitted and never used to choose a row: a class is its fitted row (`springs`: the "
        "validated fit, `fit` its choice; `p1`: no constants), each stiffness rule is its own "
        "unfitted row (`rule: <name>`). `mean` is the mean over the held-out loads "
        "(`G_heldout_mean`), `spread` the fit's spread of it over its starts "
        "(`G_heldout_mean_spread`): gaps inside it are ties. `fitted G`: the fitted loads' "
        "`G_norm_final`. `fig-nu-sweep-families.png` plots the table.\n",
    ]
    for body, b in frame.groupby("body", sort=True):
        out.append(f"\n### {body}\n")
        cols = [f for f in fams if b[f].notna().any()]  # a 2-D body has no torsion
        for _, g in b.groupby("nu", sort=True):
            t = g[
                (
                    ["model", "fit", *cols, "G_heldout_mean", "G_heldout_mean_spread"]
                    + ["G_norm_final", "status"]
                )
            ].copy()
            t["model"] = [m + (" *" if x else "") for m, x in zip(t["model"], g["heldout_derived"])]
            t = t.rename(
                columns={
                    "G_heldout_mean": "mean",
                    "G_heldout_mean_spread": "spread",
                    "G_norm_final": "fitted G",
                }
            )
            head, text = finding(g).split(": ", 1)
            out += [f"\n**{head}:** {text}\n", markdown_table(t)]
            if g["heldout_derived"].any():
                out.append(
                    "`*`: the row's stage reports G per load but no normalised held-out G: "
                    "derived from its "
                    "G_<load> and the load's reference norm, which every row of the case shares.\n"
                )
    return out


def skipped_lines(df) -> list[str]:
    """One Markdown line per (body, model class) the sweep skipped, with its reason (a
    2-D body has no Bourguignon & Cani element: status "skip", ``note``)."""
    if df.empty or not {"case", "model_class", "status"} <= set(df.columns):
        return []
    d = df[df["status"] == "skip"]
    out = {}
    for case, cls, note in zip(
        d["case"], d["model_class"], d["note"] if "note" in d else [""] * len(d)
    ):
        out.setdefault((_body(case), str(cls)), str(note) if isinstance(note, str) else "")
    return [
        f"- `{cls}` on `{body}`: skipped ({note or 'no reason given'})"
        for (body, cls), note in sorted(out.items())
    ]
