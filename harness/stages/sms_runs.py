"""The sms stage's optimiser runs of a case (the [optimizer] method, each of ``compare``,
the ``frequency`` row) and the time each run took to reach the SA row's G."""

from __future__ import annotations

import math

import numpy as np

from harness.errors import CaseError
from harness.stages.sms_fit import case_file


def optimiser_runs(case, opt) -> list[dict]:
    """The optimiser runs of a case, in table order: [optimizer] method, then each name
    in ``compare`` (options from ``compare_options``), then the ``frequency`` row.
    Each is {method, options, objective, where (the case field of its options)[, modes,
    weight]}. Mistakes the schema cannot see (a repeated optimiser, options that are not
    a table, options with method = "none") are CaseErrors naming the file and field."""
    method = opt.get("method", "none")
    file = case_file(case)
    compare = list(opt.get("compare") or ())
    extra = dict(opt.get("compare_options") or {})
    if method in compare or len(set(compare)) != len(compare):
        raise CaseError(
            f"compare repeats '{method if method in compare else compare[0]}'",
            file=file,
            field="optimizer.compare",
            fix="name each optimiser once (method is run already)",
        )
    stray = sorted(set(extra) - set(compare))
    if stray:
        raise CaseError(
            f"options for '{stray[0]}', which compare does not list",
            file=file,
            field="optimizer.compare_options",
            fix=f"add '{stray[0]}' to compare or remove its options",
        )

    def options(value, where):
        if not isinstance(value or {}, dict):
            raise CaseError(
                f"expected a table of options, got {value!r}",
                file=file,
                field=where,
                fix="e.g. { maxiter = 100 }",
            )
        return dict(value or {})

    mine = options(opt.get("options"), "optimizer.options")
    if method == "none" and mine:  # would be silently ignored: no run takes them
        raise CaseError(
            f"options {sorted(mine)} but method = 'none' runs no optimiser",
            file=file,
            field="optimizer.options",
            fix="set [optimizer] method, or remove the options",
        )
    runs = (
        []
        if method == "none"
        else [dict(method=method, options=mine, objective="G", where="optimizer.options")]
    )
    if runs and opt.get("select"):  # the validated fit (harness/stages/sms_select.py)
        runs[0]["select"] = dict(opt["select"])
    runs += [
        dict(
            method=m,
            options=dict(extra.get(m) or {}),
            objective="G",
            where=f"optimizer.compare_options.{m}",
        )
        for m in compare
    ]
    fq = opt.get("frequency")
    if fq:
        where = "optimizer.frequency.options"
        runs.append(
            dict(
                method=fq["method"],
                options=options(fq.get("options"), where),
                objective="G+freq",
                modes=int(fq["modes"]),
                weight=float(fq["weight"]),
                where=where,
            )
        )
    return runs


def time_to_reach(rows, traces):
    """``evals_to_sa_G`` / ``seconds_to_sa_G``: when each other optimiser's trace first
    reaches the G_final of the case's SA row (seconds pro rata of its evaluations);
    NaN if it never does."""
    sa = next((r for r in rows if r["optimizer"] == "sa" and r.get("objective") == "G"), None)
    if sa is None:
        return
    by_model = {t["model"].iloc[0]: t for t in traces}
    for r in rows:
        if r["optimizer"] in ("none", "sa") or r.get("objective") != "G":
            continue
        t = by_model.get(f"{r['stiffness']}+{r['optimizer']}")
        if t is None:
            continue
        hit = np.flatnonzero(t["G"].to_numpy() <= sa["G_final"] * (1 + 1e-9))
        steps = float(t["step"].iloc[-1])
        r["evals_to_sa_G"] = float(t["step"].iloc[hit[0]]) if len(hit) else math.nan
        r["seconds_to_sa_G"] = (
            r["seconds"] * r["evals_to_sa_G"] / steps if len(hit) and steps > 0 else math.nan
        )
