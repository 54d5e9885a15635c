"""The sms stage's rows (harness/stages/sms.py): a stiffness rule's unoptimised row, the
reference's columns and ``status`` of every scored row (one G_ref for all: every network
shares the nodes, loads and weights), and the columns of each row's network (natural
frequencies against the FEM's, ``k_spread``, ``dt_stable``)."""

from __future__ import annotations

import math
import time

from harness import scoring
from harness.stages import sms_measures as measures
from harness.stages.rows import RuleColumns

UNSOLVED = (
    "not solved under the clamps: it cannot rank first (half its free-traction score above "
    "the best rule's G_fit_score, or a higher G_rank_score; large meshes, "
    "harness/stages/sms_rules.py)"
)


def rule_row(scorer, common: dict, label: str, rule: str, net, res, seconds: float, why: str):
    """The row of stiffness rule ``rule``: its network ``net`` scored with its statics
    ``res``, saved; ``seconds``: its build's; ``why``: the reason a case has no reference."""
    t1 = time.perf_counter()
    res, sc, sh = scorer.evaluate(net, res)
    scorer.write(net, res, rule)
    seconds = seconds + res.seconds + time.perf_counter() - t1
    constants = scorer.cls.constants(net)
    if sc is None:
        cols = RuleColumns.unscored(label, rule, seconds, f"no reference ({why})")
        return cols.row(common, constants)
    scored = {**measures.scored_columns(scorer.case, sc, sh), **scorer.validated(net, res)}
    return RuleColumns.scored(label, rule, seconds, sc).row(common, constants, scored)


def unsolved_row(scorer, common: dict, label: str, rule: str, net, bound: float, seconds: float):
    """The row of a rule left unsolved under the clamps (harness/stages/sms_rules.py): its
    G_fit_score's lower bound ``bound``; its network saved alone."""
    scorer.write(net, None, rule)
    return RuleColumns.unsolved(label, rule, seconds, bound, UNSOLVED).row(common)


def add_ref_columns(rows: list, ref, base, scorer) -> None:
    """G_ref, ref_error_max, ref_met_tol (with held-out loads also G_ref_heldout and
    ref_error_heldout) and ``status`` (harness.scoring.ref_status) of every scored row."""
    refcols, heldcols, held_met = _ref_columns(ref, base, scorer)
    held = scorer.held
    for row in rows:
        if "G_norm_final" not in row:
            continue
        row.update(refcols, **heldcols)
        row["status"] = scoring.ref_status(
            row["G_ref"], row["G_norm_final"], refcols.get("ref_met_tol")
        )
        if held and scoring.ref_status(row["G_ref_heldout"], row["G_heldout"], held_met) != "ok":
            row["status"] = "ref-coarse"  # the held-out score is the reference's error too


def _ref_columns(ref, base, scorer) -> tuple[dict, dict, bool | None]:
    """(the fitted loads' reference columns, the held-out loads', whether the held-out
    loads met the reference's tol): with held-out loads, theirs decide ``ref_met_tol``."""
    names, u_ref, fit, held = scorer.names, scorer.u_ref, scorer.fit, scorer.held
    refcols = scoring.ref_columns(
        ref,
        base.points,
        [names[i] for i in fit],
        u_ref[fit],
        base.classes,
        scorer.weights,
        tol_loads=() if held else None,
    )
    if not held:
        return refcols, {}, None
    hc = scoring.ref_columns(
        ref, base.points, [names[i] for i in held], u_ref[held], base.classes, scorer.weights
    )
    held_met = hc.get("ref_met_tol")
    refcols["ref_met_tol"] = held_met if held_met is not None else refcols.get("ref_met_tol")
    return (
        refcols,
        {"G_ref_heldout": hc["G_ref"], "ref_error_heldout": hc["ref_error_max"]},
        held_met,
    )


def beside_rows(rows: list, nets: dict, shown: dict, freqs: dict, m: int, p1: bool) -> tuple:
    """(networks, validation tables, held-out displacements) beside the rows, each row's by
    its private ``_tag`` (dropped, as ``_validation``); each row gets its network's engine
    columns (``p1``: no spring constants) and frequency columns."""
    networks, validations, heldout = [], [], []
    for row in rows:
        tag = row.pop("_tag", row["stiffness"])
        networks.append(nets.get(tag))
        heldout.append(shown.get(tag))
        validations.append(tuple(row.pop("_validation", ())))
        if tag in nets:
            row.update(measures.engine_columns(nets[tag], p1))
        row.update(frequency_columns(row, freqs, tag, m))
    return networks, validations, heldout


def frequency_columns(row: dict, freqs: dict, tag: str, m: int) -> dict:
    """f1_ratio and the RMS relative errors of the first m natural frequencies of the
    row's network (``freq_error_final``), of its start rule's (``freq_error_initial``) and
    of the modes its fit did not see (``freq_error_heldout``) against the FEM's."""
    if tag not in freqs or "fem" not in freqs or not freqs["fem"][0] > 0:
        return {}
    f, fem = freqs[tag], freqs["fem"]
    start = row["stiffness"]  # the rule (an optimised row's start)
    out = {
        "f1_ratio": float(f[0] / fem[0]),
        "freq_error_final": measures.freq_error(f, fem, m),
        "freq_error_initial": measures.freq_error(freqs[start], fem, m)
        if start in freqs
        else math.nan,
    }
    # modes the fit saw; the others are held out
    fitted = int(row.get("freq_modes", 0) or 0)
    if len(fem) > fitted:
        out["freq_error_heldout"] = measures.freq_error(f[fitted:], fem[fitted:], m - fitted)
    return out
