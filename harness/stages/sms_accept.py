"""The validation loads' say on a validated fit (harness/stages/sms_select.py).

Leave-one-family-out validation chooses a fit's capacity on the training states; whether
the fit it chose is better than every stiffness rule on loads it never saw is a separate
question, and the validation loads answer it: clamped loads on other regions than the
held-out ones (calibrate's: the body force under the training states' clamps,
harness/case/default_loads.py), FEM-solved like every scored load, never fitted, never
held out. Each model's ``G_val_mean`` is the mean over them of each one's own normalised G.

The fit is exported only when its G_val_mean is below every solved rule's by more than
MARGIN (of the best rule's); else the rule they rank first is, the validation's own
choice 'rule' included. A rule a large mesh leaves unsolved under the clamps
(harness/stages/sms_rules.py) cannot be ranked and is not a candidate. Without validation
loads the leave-one-family-out choice stands. The held-out loads never choose anything.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import Mapping

from harness.optimize.select_table import MARGIN


@dataclass(frozen=True)
class Acceptance:
    """``fit``: the validated fit's G_val_mean (NaN: the validation chose the rule);
    ``rules``: {rule: G_val_mean} of every solved rule; ``best``: the rule they rank first
    (None: no validation loads); ``accepted``: whether the fit is exported."""

    fit: float
    rules: Mapping[str, float]
    best: str | None
    accepted: bool

    @property
    def columns(self) -> dict:
        """The validated row's columns: ``val_fit``, ``val_best_rule``,
        ``val_best_rule_score`` and ``val_accepted`` (none without validation loads)."""
        if self.best is None:
            return {}
        return {
            "val_fit": self.fit,
            "val_best_rule": self.best,
            "val_best_rule_score": self.rules[self.best],
            "val_accepted": self.accepted,
        }


def judge(fit: float, rules: Mapping[str, float]) -> Acceptance:
    """The verdict (module doc) on a fit with G_val_mean ``fit`` (NaN: no fit) against the
    rules' ``rules`` (NaN: a rule without validation loads or unsolved, left out)."""
    scored = {r: float(v) for r, v in rules.items() if v is not None and math.isfinite(v)}
    if not scored:
        return Acceptance(float(fit), MappingProxyType({}), None, math.isfinite(fit))
    best = min(scored, key=lambda r: (scored[r], r))
    ok = math.isfinite(fit) and fit < scored[best] * (1.0 - MARGIN)
    return Acceptance(float(fit), MappingProxyType(scored), best, bool(ok))
