"""What ``springbench calibrate`` writes and prints: MODEL.vtu, MODEL.json and MODEL.csv
together (with held-out loads also MODEL-heldout.vtu and MODEL-heldout.png, the picture of
the fit: calibrate_picture.py), the table, and the verdict's sentences."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from harness.commands import calibrate_picture as picture
from harness.commands import calibrate_verdict as cv
from harness.commands.calibrate_case import prior_weight
from harness.commands.calibrate_run import tets_row
from harness.export.engine_loads import load_records, settle_recipe
from harness.export.model_json import export
from harness.optimize.select_counts import RECORDED
from harness.outputs import staged
from harness.report.findings import flags, heldout_error
from harness.stages.sms_measures import rank


def _choice(s, row) -> str:
    """The JSON's ``choice``: 'rule' (the rule's constants exported: --method rule, or no
    candidate beat the rule on validation), the validated candidate's name, or 'fit'
    (a fit whose capacity the user fixed)."""
    if row.get("optimizer", "none") == "none":
        return "rule"
    return str(row.get("choice", "fit"))


def _worst(*values) -> float:
    """The largest value, NaN if any is NaN (a load without an estimate: none overall)."""
    return math.nan if any(math.isnan(v) for v in values) else max(values)


def _accepted(row) -> bool | None:
    """The JSON's ``validation_accepted``: whether the validation loads let the fit be
    exported (None: no validated fit judged on validation loads)."""
    v = row.get("val_accepted")
    return None if v is None or (isinstance(v, float) and math.isnan(v)) else bool(v)


def _candidates(case) -> list[str] | None:
    """The JSON's ``candidates``: the names the validated fit chose among (``--engine``
    restricts them), None without a validated fit."""
    select = (case.section("optimizer") or {}).get("select")
    return list(select["candidates"]) if select else None


def _fit_counts(row) -> dict | None:
    """The JSON's ``fit_counts``: the counts the validated fit ran (the row's fit_<key>
    columns, harness/optimize/select_counts.py RECORDED), None without one."""
    if "fit_level" not in row:
        return None
    out = {key: row[f"fit_{key}"] for key in RECORDED}
    out["candidates"] = str(out["candidates"]).split()
    return {k: v.item() if hasattr(v, "item") else v for k, v in out.items()}


def rule_rows(rows) -> list[dict]:
    """The stiffness rules' rows: the unfitted rows a verdict or a choice compares with (never
    the plain tetrahedra's row, calibrate_run.TETS)."""
    return [r for r in rows if r.get("optimizer", "none") == "none" and r is not tets_row(rows)]


def positive(net) -> bool:
    """Whether every mass is positive (an explicit engine can run the network)."""
    return bool(np.all(np.asarray(net.masses) > 0))


# JSON key: the exported row's column
FROM_ROW = dict(
    G_norm="G_norm_final",
    G_norm_heldout="G_heldout",
    G_heldout_mean="G_heldout_mean",
    reference_error_fitted="ref_error_max",
    reference_error_heldout="ref_error_heldout",
    validation_skipped="val_skipped",
    G_heldout_mean_spread="G_heldout_mean_spread",
    G_val_mean="G_val_mean",
    mass_residual="mass_residual",
)
# MODEL.csv's columns, in order (those no row has are left out, dt_safe always written)
COLUMNS = (
    "model stiffness optimizer exported n_nodes n_springs G_initial G_final G_norm_initial "
    "G_norm_final G_fit_score G_fit_score_bound G_rank_score G_heldout G_heldout_mean "
    "G_heldout_mean_spread "
    "G_val_mean val_fit val_best_rule val_accepted "
    "choice ref_error_max ref_error_heldout status k_ratio dt_stable dt_safe seconds seed "
    "opt_stop opt_stops opt_prior training_dropped E_effective nu_effective ref_note note"
).split()


# the printed table's key columns (--wide: every column of MODEL.csv but opt_stops)
SHORT = {
    "model": "model",
    "choice": "choice",
    "exported": "out",
    "G_heldout_mean": "held-out",
    "G_norm_final": "fitted",
    "ref_error_heldout": "ref-error",
    "status": "status",
    "dt_safe": "dt_safe",
}


def table(df: pd.DataFrame, wide: bool = False) -> str:
    """The table calibrate prints: the key columns (within 100 characters a line: the model,
    the validation's choice, '*' on the exported row, its held-out and fitted errors, the
    FEM's own held-out error, the reference's status, the engine step), or every one."""
    if wide:
        return df.drop(columns=["opt_stops"], errors="ignore").to_string(index=False)
    short = df.reindex(columns=list(SHORT)).rename(columns=SHORT)
    short["out"] = np.where(df["exported"].astype(bool), "*", "")
    fitted = df.get("optimizer", pd.Series("none", index=df.index)).fillna("none")
    # a fit the validation did not choose: its optimiser
    choice = short["choice"].astype(object)
    short["choice"] = choice.where(choice.notna(), fitted.where(fitted != "none", ""))
    number = lambda v: "-" if pd.isna(v) else f"{v:.3g}"  # noqa: E731  (no sign column)
    floats = ("held-out", "fitted", "ref-error", "dt_safe")
    return short.to_string(index=False, formatters={c: number for c in floats}, na_rep="-")


def metadata(s, rows, exported, net, case) -> dict:
    """The JSON's keys beyond the network's own: material, loads, errors, choice, verdict,
    the optimiser's stops and the engines' load records."""
    if "choice" in exported:
        weight = exported.get("opt_prior", math.nan)
    else:
        weight = prior_weight(s) if s.method == "lbfgs" else math.nan
    dropped = str(exported.get("training_dropped") or "").split()
    meta = dict(
        E=s.E,
        nu=s.nu,
        density=s.density,
        damping_ratio=s.damping_ratio,
        loads_fitted=[n for n in case.fit_loads if n not in dropped],
        loads_heldout=list(case.heldout),
        training_dropped=dropped,
        **{key: exported.get(col, math.nan) for key, col in FROM_ROW.items()},
        G_heldout_loads={n: cv.finite(exported.get(f"G_heldout_{n}")) for n in case.heldout},
        loads_validation=list(case.validation),
        G_val_loads={n: cv.finite(exported.get(f"G_{n}")) for n in case.validation},
        validation_accepted=_accepted(exported),
        reference_error=_worst(
            exported.get("ref_error_max", math.nan), exported.get("ref_error_heldout", 0.0)
        ),
        choice=_choice(s, exported),
        validation=cv.records(exported.pop("_validation", None)),
        masses=s.masses,
        prior_weight=weight,
        engine=s.engine,
        fit_counts=_fit_counts(exported),
    )
    # what the validation chose among: the counts' candidates on a large mesh
    meta["candidates"] = (meta["fit_counts"] or {}).get("candidates") or _candidates(case)
    rules = rule_rows(rows)
    said, rule = cv.verdict(exported, rules) if case.heldout else (None, None)
    best = None
    if rule is not None:
        best = {"rule": rule["stiffness"], "G_heldout_mean": cv.finite(heldout_error(rule))}
    stop, stops = exported.get("opt_stop"), exported.get("opt_stops") or exported.get("opt_stop")
    meta.update(
        status=str(exported.get("status", "ok")),
        verdict=said,
        flags=flags(exported, rules) if case.heldout else [],
        best_rule_heldout=best,
        G_heldout_mean_tets=cv.finite((tets_row(rows) or {}).get("G_heldout_mean")),
        opt_stop=stop if isinstance(stop, str) else None,
        opt_stops=stops.split(" | ") if isinstance(stops, str) else [],
    )
    meta.update(
        load_records(net, case), settle_damping=settle_recipe(net, case) if positive(net) else None
    )
    return meta


def _material(data) -> str:
    """The tetrahedra's material as printed: the pair they share, else the range of each."""
    if data["E_effective"] is not None:
        return f"E {data['E_effective']:.4g} Pa, nu {data['nu_effective']:.4g}"
    E, nu = ([v for v in data[k] if v is not None] or [math.nan] for k in ("tet_E", "tet_nu"))
    return f"E {min(E):.4g}..{max(E):.4g} Pa, nu {min(nu):.4g}..{max(nu):.4g} per tetrahedron"


def write(s, rows, net, case):
    """Write MODEL.vtu/.json/.csv (and the picture of the fit) and print the table and the
    verdict."""
    exported = next(r for r in rows if r["exported"])
    heldout = exported.pop("_heldout", None)
    meta = metadata(s, rows, exported, net, case)
    rules = rule_rows(rows)
    cols = [c for c in COLUMNS if any(c in r for r in rows) or c == "dt_safe"]
    out = s.out  # the files appear together or not at all (disk full: none)
    files = [out, out.with_suffix(".json"), out.with_suffix(".csv")]
    files += picture.paths(out) if heldout is not None else []
    with staged(files, "--out") as (vtu, _, csv, *pic):
        data = export(net, vtu, meta)  # the VTU and its .json beside it
        shown = picture.write(*pic, net, case, heldout) if pic else None
        # one step in the table, the JSON's
        exported.update(dt_stable=data["dt_stable"], dt_safe=data.get("dt_safe"))
        df = pd.DataFrame(rows).reindex(columns=cols)
        df.to_csv(csv, index=False)
    print(table(df, s.wide))
    print(cv.heldout_sentence(exported, rules, case.heldout))
    if case.heldout and tets_row(rows) is not None:
        print(cv.tets_sentence(tets_row(rows), case.dim))
    print(cv.fitted_sentence(exported, min(rules, key=rank)))
    print(cv.reference_sentence(exported, meta, bool(case.heldout), s.max_refine))
    if cv.dropped_sentence(exported):
        print(cv.dropped_sentence(exported))
    if "choice" in exported:
        print(cv.validation_sentence(exported, meta["validation"] or []))
    if data["dt_stable"] is not None:
        step = (
            f"dt_stable {data['dt_stable']:.3g} s (float32 {data['dt_stable_float32']:.3g} s, "
            f"safe {data['dt_safe']:.3g} s)"
        )
    else:
        step = data.get("warning", "")
    k = data["spring_stiffness"]
    stiff = f"{net.n_springs} springs, masses {s.masses}, k {min(k):.3g}..{max(k):.3g} N/m"
    if "tet_E" in data:  # the engines' tetrahedra's material (model classes p1-global, p1)
        stiff = f"masses {s.masses}, " + _material(data)
    print(
        f"-> {s.out} (+ .json, .csv): {net.n_nodes} nodes, {stiff}, {step}"
        + (picture.sentence(out, shown) if shown is not None else "")
    )
