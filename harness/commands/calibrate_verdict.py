"""calibrate's verdict sentences and the JSON's validation records."""

from __future__ import annotations

import math


def pct(v) -> str:
    """A fraction as a percentage to 3 digits, "n/a" when missing or not finite."""
    return f"{100 * v:.3g} %" if v is not None and math.isfinite(v) else "n/a"


def validation_sentence(row, table) -> str:
    """What the validation chose, in one sentence."""
    by = {r["model"]: r.get("score") for r in table}
    fams = row.get("val_families", "")
    skipped = row.get("val_skipped", math.nan)
    if isinstance(skipped, float) and math.isfinite(skipped):
        from harness.stages.sms_select import VALIDATION_BUDGET
        return (f"Validation skipped: its fits could not take enough steps on this mesh within "
                f"{VALIDATION_BUDGET:g}x --budget, so the rule {row['stiffness']} is exported (as --method rule --rule "
                f"{row['stiffness']}); --budget {math.ceil(skipped)} lets it run.")
    if row.get("choice") == "rule":
        return (f"Validation (each family of training states left out in turn: {fams}): no fit beat the rule "
                f"{row['stiffness']} (score {by.get('rule', math.nan):.3g}), so its constants are exported "
                f"(as --method rule --rule {row['stiffness']}).")
    return (f"Validation (each family of training states left out in turn: {fams}) chose {row['choice']}: "
            f"score {by.get(row['choice'], math.nan):.3g} against the rule {row['stiffness']}'s "
            f"{by.get('rule', math.nan):.3g}.")


def records(rows):
    """The validation table as JSON records (NaN -> None), or None."""
    if rows is None:
        return None
    return [{k: (finite(v) if isinstance(v, float) else v) for k, v in r.items()} for r in rows]


def finite(v):
    """v as a float, None when missing or not finite (JSON has no NaN)."""
    return float(v) if v is not None and math.isfinite(v) else None


def heldout_sentence(exported: dict, rules: list) -> str:
    """The fit's held-out mean error against the best rule's on the same loads: better,
    worse, or a tie within the spread over starts."""
    rule = min(rules, key=lambda r: r.get("G_heldout_mean", math.inf))
    fit, other = exported.get("G_heldout_mean", math.nan), rule.get("G_heldout_mean", math.nan)
    spread = exported.get("G_heldout_mean_spread", 0.0) or 0.0
    verdict = ("a tie within the spread over starts" if abs(fit - other) <= spread else
               "the fit is better" if fit < other else
               f"the fit is worse than that rule on held-out loads: export the rule instead "
               f"(--method rule --rule {rule['stiffness']})")
    return (f"Held-out loads, mean of each load's error: {pct(fit)} (spread over starts {pct(spread)}) against "
            f"the best rule's {pct(other)} ({rule['stiffness']}): {verdict}.")
