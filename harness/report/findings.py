"""What a result row says beyond its numbers, in one vocabulary for calibrate's verdict,
``springbench run``'s summary and the report page:

- ``ref-coarse``: the row's status: the FEM reference's own error is above a tenth of the
  model's (harness/scoring.py REF_COARSE_FRACTION) or it missed its tolerance, so part of
  the model's error is the reference's;
- ``memorised``: a fitted row whose pooled held-out G is more than MEMORISED times its
  fitted G: the fit learned its training loads, not the body;
- ``fit-worse-than-rule``: a fitted row whose held-out error is above the best stiffness
  rule's on the same nodes and loads, by more than the spread over the fit's starts.

The held-out error is the mean of each held-out load's own normalised G
(``G_heldout_mean``) where a row has it, else the pooled ``G_heldout``.
"""

from __future__ import annotations

import math

MEMORISED = 3.0     # held-out G above this multiple of the fitted G: memorised
LEGEND = {
    "ref-coarse": "the FEM reference's own error is above a tenth of the model's, or it missed its tolerance: "
                  "part of the error shown is the reference's",
    "memorised": f"held-out G > {MEMORISED:g} x fitted G: the fit learned its training loads, not the body",
    "fit-worse-than-rule": "the fit's held-out error is above the best stiffness rule's on the same mesh and loads "
                           "(beyond the spread over its starts): the rule predicts better",
}


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
    opt = row.get("optimizer", "none")
    return isinstance(opt, str) and opt not in ("", "none") and row.get("choice") != "rule"


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
    g_fit, g_held = number(row.get("G_norm_final")), number(row.get("G_heldout"))
    if fitted(row) and math.isfinite(g_fit) and math.isfinite(g_held) and g_held > MEMORISED * g_fit:
        out.append("memorised")
    if fitted(row) and against_rule(row, rules)[0] == "worse":
        out.append("fit-worse-than-rule")
    return out
