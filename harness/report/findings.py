"""What a result row says beyond its numbers, in one vocabulary for calibrate's verdict,
``springbench run``'s summary and the report page:

- ``ref-coarse``: the row's status: the FEM reference's own error is above a tenth of the
  model's (harness/scoring.py REF_COARSE_FRACTION) or it missed its tolerance, so part of
  the model's error is the reference's;
- ``memorised``: a fitted row whose held-out error is more than MEMORISED times its
  fitted G: the fit learned its training loads, not the body;
- ``fit-worse-than-rule``: a fitted row whose held-out error is above the best stiffness
  rule's on the same nodes and loads, by more than the spread over the fit's starts;
- ``not-installed``: the row's status: an engine it needs is not installed, so the row
  holds no numbers (never counted as ``ok``).

The held-out error is the mean of each held-out load's own normalised G
(``G_heldout_mean``) where a row has it, else the pooled ``G_heldout``.
"""

from __future__ import annotations

import math

from harness.engines import EXTRA

MEMORISED = 3.0  # held-out G above this multiple of the fitted G: memorised
LEGEND = {
    "ref-coarse": "the FEM reference's own error is above a tenth of the model's, or it "
    "missed its tolerance: "
    "part of the error shown is the reference's",
    "memorised": f"held-out G > {MEMORISED:g} x fitted G: the fit learned its training "
    "loads, not the body",
    "fit-worse-than-rule": "the fit's held-out error is above the best stiffness rule's on "
    "the same mesh and loads "
    "(beyond the spread over its starts): the rule predicts better",
    "not-installed": f"an engine the row needs is not installed: {EXTRA} installs the engines",
}
# row statuses in the order the page and the console count them
STATUSES = ("ok", "ref-coarse", "not-installed", "error")


def status_counts(status) -> str:
    """'12 ok, 3 not-installed': how many rows have each of STATUSES; "" for none."""
    import pandas as pd

    s = pd.Series(status, dtype=object).astype(str)
    return ", ".join(f"{int((s == n).sum())} {n}" for n in STATUSES if (s == n).any())


def not_installed_note(df) -> str:
    """The page's line for rows whose engine is not installed: how many, which engines,
    and the command that installs them."""
    rows = df[df["status"].astype(str) == "not-installed"]
    names = sorted(map(str, rows["engine"].dropna().unique())) if "engine" in rows else []
    which = f" ({', '.join(names)})" if names else ""
    return (
        f"{len(rows)} rows are not-installed: their engines{which} are not installed here, "
        f"so those rows hold no numbers; {EXTRA} installs them."
    )


def number(v) -> float:
    """v as a float; NaN when missing, empty or not a number."""
    try:
        v = float(v)
    except (TypeError, ValueError):
        return math.nan
    return v


def heldout_error(row) -> float:
    """The row's held-out error: G_heldout_mean, else the pooled G_heldout (NaN: none)."""
    v = number(row.get("G_heldout_mean"))
    return v if math.isfinite(v) else number(row.get("G_heldout"))


def fitted(row) -> bool:
    """Whether the row's constants were fitted (an optimiser ran), not a rule's."""
    opt = row.get("optimizer", "none")  # "none+k-ratio 10": a rule's constants, capped
    return (
        isinstance(opt, str)
        and opt.split("+")[0] not in ("", "none")
        and row.get("choice") != "rule"
    )


def best_rule(rules):
    """The rule row with the lowest held-out error (None: no rule has one)."""
    scored = [r for r in rules if math.isfinite(heldout_error(r))]
    return min(scored, key=heldout_error) if scored else None


def against_rule(row, rules) -> tuple:
    """(verdict, the best rule's row): "better", "tie" (within the spread over the fit's
    starts), "worse", or None when there is nothing to compare (no held-out error, no rule)."""
    rule = best_rule(rules)
    fit, other = heldout_error(row), heldout_error(rule) if rule is not None else math.nan
    if not (math.isfinite(fit) and math.isfinite(other)):
        return None, rule
    spread = number(row.get("G_heldout_mean_spread"))
    spread = spread if math.isfinite(spread) else 0.0
    if abs(fit - other) <= spread:
        return "tie", rule
    return ("better" if fit < other else "worse"), rule


def flags(row, rules=()) -> list[str]:
    """The LEGEND flags of one row; ``rules``: the rule rows of the same nodes and loads."""
    out = []
    if row.get("status") == "ref-coarse":
        out.append("ref-coarse")
    g_fit, g_held = number(row.get("G_norm_final")), heldout_error(row)
    if (
        fitted(row)
        and math.isfinite(g_fit)
        and math.isfinite(g_held)
        and g_held > MEMORISED * g_fit
    ):
        out.append("memorised")
    if fitted(row) and against_rule(row, rules)[0] == "worse":
        out.append("fit-worse-than-rule")
    return out


# -- one line per case: what `springbench run` prints and the page counts --------------------

KEYS = ("model", "model_class", "optimizer", "objective", "stiffness")
NUMBERS = ("G_norm_final", "G_heldout", "G_heldout_mean", "G_heldout_mean_spread")


def _averaged(g):
    """The case's scored rows averaged over seeds: one dict per model (KEYS), with
    ``n_seeds``, the worst status and the first ``choice``."""
    import pandas as pd

    keys = [k for k in KEYS if k in g]
    out = []
    for _, r in g.groupby(keys, sort=False, dropna=False) if keys else [(None, g)]:
        row = {k: r[k].iloc[0] for k in keys}
        row.update(
            {c: float(pd.to_numeric(r[c], errors="coerce").mean()) for c in NUMBERS if c in r}
        )
        status = set(r["status"].astype(str)) if "status" in r else {"ok"}
        row["status"] = "ref-coarse" if "ref-coarse" in status else "ok"
        row["n_seeds"] = int(r["seed"].nunique()) if "seed" in r else 1
        if "choice" in r and r["choice"].notna().any():
            row["choice"] = str(r["choice"].dropna().iloc[0])
        out.append(row)
    return out


def label(row) -> str:
    """A short name of a row's model: "rule lloyd", "lbfgs", "springs+volume lbfgs",
    "lbfgs (chose rule)", or the stage's model name (MS, MT0, MT)."""
    opt = row.get("optimizer")
    if not isinstance(opt, str) or opt == "":
        return str(row.get("model", ""))
    if opt == "none":
        return f"rule {row.get('stiffness')}"
    cls = row.get("model_class")
    name = f"{cls} {opt}" if isinstance(cls, str) and cls != "springs" else opt
    return name + (f" (chose {row['choice']})" if isinstance(row.get("choice"), str) else "")


def is_rule(row) -> bool:
    """A spring network with a stiffness rule's constants (no optimiser), the rows fits are
    set against ("springs" rows only, where the rows carry a model class)."""
    cls = row.get("model_class")
    return row.get("optimizer") == "none" and (not isinstance(cls, str) or cls == "springs")


def case_lines(df):
    """One line per case: ``case``, ``model`` (its best fit on the fitted loads, the one a
    fitter would export; else its best rule; else the model with the lowest G), ``fitted``
    (normalised G on the fitted loads) and ``heldout`` (its held-out error), ``findings``
    (LEGEND's, "error" when a row failed; a case
    without G: its worst status) and ``n_seeds``."""
    import pandas as pd

    out = []
    for case, g in df.groupby("case", sort=False):
        status = set(g["status"].astype(str)) if "status" in g else {"ok"}
        line = {
            "case": case,
            "model": "",
            "fitted": math.nan,
            "heldout": math.nan,
            "findings": [],
            "n_seeds": 1,
        }
        scored = (
            g[g["G_norm_final"].notna() & g["status"].isin(("ok", "ref-coarse"))]
            if {"G_norm_final", "status"} <= set(g)
            else g.iloc[:0]
        )
        rows = _averaged(scored) if len(scored) else []
        # not G+freq
        fits = [r for r in rows if fitted(r) and str(r.get("objective", "G")) in ("G", "nan")]
        rules = [r for r in rows if is_rule(r)]
        pool = fits or rules or rows
        if pool:
            pick = min(pool, key=lambda r: number(r.get("G_norm_final")))
            line.update(
                model=label(pick),
                fitted=number(pick.get("G_norm_final")),
                heldout=heldout_error(pick),
                findings=flags(pick, rules),
                n_seeds=pick["n_seeds"],
            )
        elif "ref-coarse" in status:
            line["findings"] = ["ref-coarse"]
        if "not-installed" in status:
            line["findings"].append("not-installed")
        if "error" in status:
            line["findings"] = ["error"] + line["findings"]
        out.append(line)
    return pd.DataFrame(out, columns=["case", "model", "fitted", "heldout", "findings", "n_seeds"])


def _g(v) -> str:
    return "-" if not math.isfinite(v) else f"{v:.3g}"


def summary_text(name: str, lines) -> list[str]:
    """The aligned console table of :func:`case_lines` for one suite."""
    rows = [("case", "model", "G_norm fitted / held-out", "status")]
    for r in lines.itertuples(index=False):
        case = r.case + (f" ({r.n_seeds} seeds)" if r.n_seeds > 1 else "")
        g = "-" if not math.isfinite(r.fitted) else f"{_g(r.fitted)} / {_g(r.heldout)}"
        rows.append((case, r.model or "-", g, ", ".join(r.findings) or "ok"))
    width = [max(len(row[i]) for row in rows) for i in range(3)]
    return [f"{a:<{width[0]}}  {b:<{width[1]}}  {c:>{width[2]}}  {d}" for a, b, c, d in rows]


def legend(all_flags) -> list[str]:
    """The legend lines of the flags that occur."""
    seen = {f for fl in all_flags for f in fl}
    return [f"  {name}: {text}" for name, text in LEGEND.items() if name in seen]
