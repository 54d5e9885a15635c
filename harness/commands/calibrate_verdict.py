"""calibrate's verdict sentences and the JSON's validation records."""

from __future__ import annotations

import math

RULE_TIE = 0.02  # two rules' held-out errors closer than this (relative) are a tie, not a ranking


def pct(v) -> str:
    """A fraction as a percentage to 3 digits, "n/a" when missing or not finite."""
    return f"{100 * v:.3g} %" if v is not None and math.isfinite(v) else "n/a"


def validation_sentence(row, table) -> str:
    """What the validation chose, in one sentence, and what the validation loads said of it."""
    return " ".join(x for x in (_folds_sentence(row, table), _loads_sentence(row)) if x)


def _folds_sentence(row, table) -> str:
    """What leave-one-family-out validation chose, against the rule the fits start from."""
    if not table:  # no folds ran (a class of one fitted material, p1-global)
        return ""
    by = {r["model"]: r.get("score") for r in table}
    fams = row.get("val_families", "")
    start = row.get("start_rule") or row["stiffness"]
    ratios = {
        r["model"]: r["ratio"]
        for r in table
        if r.get("ratio") is not None and math.isfinite(r["ratio"])
    }
    said = f"Validation (each family of training states left out in turn: {fams})"
    level = row.get("fit_level")
    if isinstance(level, (int, float)) and level > 0:  # a large mesh: fewer fits
        said = (
            f"Validation at level {int(level)} of the fit's counts for a mesh this size "
            f"(JSON fit_counts; left out in turn: {fams})"
        )
    chose = row.get("val_fold_choice") or row["choice"]
    if chose == "rule":
        best = min((m for m in ratios if m != "rule"), key=ratios.get, default=None)
        near = f"; the best fit, {best}, {ratios[best]:.3g}x its errors" if best else ""
        return f"{said}: no fit beat the rule {start} (score {by.get('rule', math.nan):.3g}{near})."
    if chose in ratios:
        clamped = " and the clamped states" if "clamped" in str(fams).split() else ""
        return (
            f"{said} chose {chose}: {ratios[chose]:.3g}x the rule {start}'s errors (the "
            f"geometric mean over the free-traction families{clamped})."
        )
    return (
        f"{said} chose {chose}: score {by.get(chose, math.nan):.3g} against the rule "
        f"{start}'s {by.get('rule', math.nan):.3g}."
    )


def _loads_sentence(row) -> str:
    """What the validation loads (harness/stages/sms_accept.py) said: the fit exported, or
    the rule they rank first and why."""
    best = row.get("val_best_rule")
    if not isinstance(best, str) or not best:
        if row.get("choice") == "rule":
            return f"Its constants are exported (as --method rule --rule {row['stiffness']})."
        return ""
    rule = f"the best rule there, {best}, {pct(row.get('val_best_rule_score'))}"
    if row.get("val_accepted"):
        return (
            f"On the validation loads (side faces held, never fitted) the fit's error "
            f"{pct(row.get('val_fit'))} is below every rule's ({rule}): the fit is exported."
        )
    fit = row.get("val_fit", math.nan)
    why = (
        f"the fit's error {pct(fit)} is not below {rule}"
        if isinstance(fit, float) and math.isfinite(fit)
        else f"they rank {best} first ({pct(row.get('val_best_rule_score'))})"
    )
    return (
        f"On the validation loads (side faces held, never fitted) {why}: its constants "
        f"are exported (as --method rule --rule {best})."
    )


def records(rows):
    """The validation table as JSON records (NaN -> None), or None."""
    if rows is None:
        return None
    return [{k: (finite(v) if isinstance(v, float) else v) for k, v in r.items()} for r in rows]


def finite(v):
    """v as a float, None when missing or not finite (JSON has no NaN)."""
    return float(v) if v is not None and math.isfinite(v) else None


def verdict(exported: dict, rules: list) -> tuple:
    """(JSON ``verdict``, the best rule's row on held-out loads): "better", "tie" or
    "fit-worse-than-rule" for a fit; "rule" when a rule's constants are exported; None
    without held-out loads (harness/report/findings.py)."""
    from harness.report.findings import against_rule, best_rule, fitted

    if not fitted(exported):
        return ("rule" if best_rule(rules) is not None else None), best_rule(rules)
    v, rule = against_rule(exported, rules)
    return ({"worse": "fit-worse-than-rule"}.get(v, v)), rule


def heldout_sentence(exported: dict, rules: list, names) -> str:
    """Held-out against held-out, in one sentence: the exported constants' error on the
    loads no fit saw beside the best rule's on the same loads, and what to do about it."""
    from harness.report.findings import fitted, heldout_error

    v, rule = verdict(exported, rules)
    if v is None:
        return (
            "No held-out loads (--heldout none): the errors below are on the loads the "
            "constants were fitted to, which says how well they fit, not how well they predict."
        )
    fit, other = heldout_error(exported), heldout_error(rule)
    head = (
        f"Held-out loads ({', '.join(names)}; never fitted), mean RMS error of each relative "
        "to the FEM: "
    )
    if not fitted(exported):
        mine = exported["stiffness"]
        tail = (
            "it is the best of the rules there"
            if mine == rule["stiffness"]
            else f"a tie (within {RULE_TIE:.0%})"
            if abs(fit - other) <= RULE_TIE * other
            else f"--method rule --rule {rule['stiffness']} exports that one"
        )
        best = f"the best rule ({rule['stiffness']}) {pct(other)}"
        return f"{head}the exported rule ({mine}) {pct(fit)}, {best}: {tail}."
    spread = exported.get("G_heldout_mean_spread")
    spread = (
        f" (spread over starts {pct(spread)})"
        if spread is not None and math.isfinite(spread)
        else ""
    )
    tail = {
        "tie": "a tie within the spread over starts: either predicts as well",
        "better": f"the fit is better, x{fit / other:.2f} the rule's error"
        if other > 0
        else "the fit is better",
        "fit-worse-than-rule": "fit worse than the rule on held-out loads: export the rule "
        f"instead (--method rule --rule {rule['stiffness']})",
    }[v]
    best = f"the best rule ({rule['stiffness']}) {pct(other)}"
    return f"{head}the fit {pct(fit)}{spread}, {best}: {tail}.{memorised(exported, rules)}"


def memorised(exported: dict, rules: list) -> str:
    """ " Memorised: ..." when the fit's held-out error is above MEMORISED times its fitted one
    (the flag `springbench run` gives such a row, harness/report/findings.py); "" else."""
    from harness.report.findings import MEMORISED, flags, heldout_error

    if "memorised" not in flags(exported, rules):
        return ""
    ratio = heldout_error(exported) / float(exported["G_norm_final"])
    return (
        f" Memorised: its held-out error is {ratio:.1f}x its fitted one (above {MEMORISED:g}x), "
        "so the training states do not show how it predicts; judge it by the held-out loads."
    )


def tets_sentence(tets: dict, dim: int = 3) -> str:
    """The plain linear tetrahedra's (2-D: triangles') held-out error
    (calibrate_run.plain_tets_row), in one sentence: what the engine's own elements with the
    user's material would do."""
    return (
        f"Your engine's own linear {'triangles' if dim == 2 else 'tetrahedra'} with (E, nu) "
        f"at this mesh: "
        f"{pct(tets.get('G_heldout_mean'))} held-out error (not a candidate; --model "
        "p1-global / p1 fits their material)."
    )


def fitted_sentence(exported: dict, best: dict) -> str:
    """The fitted loads' error beside the best rule's there (the rule the fit started from)."""
    return (
        f"Fitted loads: RMS displacement error {pct(exported.get('G_norm_final'))} of the FEM "
        f"(the best stiffness rule there, {best['stiffness']}, {pct(best.get('G_norm_final'))})."
    )


def reference_sentence(exported: dict, meta: dict, heldout: bool, max_refine: int) -> str:
    """The FEM reference's status (ok / ref-coarse), its own error, where it is coarse and
    what that means."""
    from harness.scoring import ref_status
    from reference.adaptive.adapt import UNTIL_TOL

    status = meta["status"]
    fem, fem_held = meta["reference_error"], meta["reference_error_heldout"]
    if fem is None or not math.isfinite(fem):
        return (
            f"Reference status {status}, but FEM error not estimated (--max-refine 0, or no "
            "coarser mesh of the body could be made), so the errors above may be partly the FEM's."
        )
    if heldout and math.isfinite(fem_held) and fem_held < fem:
        fitted_error = pct(meta["reference_error_fitted"])
        est = f"FEM error <= {pct(fem_held)} on held-out loads, {fitted_error} on fitted ones"
    else:
        est = f"FEM error <= {pct(fem)}"
    coarse = [
        name
        for name, g_ref, g, met in (
            (
                "fitted",
                exported.get("G_ref", math.nan),
                exported.get("G_norm_final", math.nan),
                exported.get("ref_met_tol"),
            ),
            (
                "held-out",
                exported.get("G_ref_heldout", math.nan),
                exported.get("G_heldout", math.nan),
                None,
            ),
        )
        if (name == "fitted" or heldout) and ref_status(g_ref, g, met) != "ok"
    ]
    where = f" on the {' and '.join(coarse)} loads" if coarse else ""
    if status == "ok":
        return (
            f"Reference ok ({est}): the FEM's own error is under a tenth of the model's, so "
            "the errors "
            f"above are the model's."
        )
    note = exported.get("ref_note") or ""
    fix = (
        "a finer mesh of the body makes it finer"
        if max_refine >= UNTIL_TOL
        else f"--max-refine {max_refine + 1} (or a finer mesh) makes it finer"
    )
    return (
        f"Reference ref-coarse ({est}): the FEM's own error{where} is above a tenth of the "
        "model's or missed its tolerance, so part of those errors is the FEM's"
        + (f" ({note})" if note else "")
        + f"; {fix}."
    )


def dropped_sentence(exported: dict) -> str:
    """The training states the fit left out because the FEM could not resolve them ("" if
    none)."""
    from harness.scoring import fraction_words

    dropped = str(exported.get("training_dropped") or "").split()
    if not dropped:
        return ""
    return (
        f"Training states left out of the fit ({', '.join(dropped)}): the FEM's error on them "
        f"is above {fraction_words()} of the best rule's, so a fit would learn the FEM's error."
    )
