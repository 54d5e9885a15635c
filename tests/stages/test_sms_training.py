"""The sms stage fits only the training states its reference resolves: a state whose FEM
error (at the model's nodes) is above a third of the best rule's error on it is dropped
from the case, its displacements and the rules' statics, and named; the held-out loads
stay. Stand-in reference and statics with numbers worked out by hand here."""

from __future__ import annotations

import types
from dataclasses import dataclass

import numpy as np

from harness.mechanics.statics import StaticsResult
from harness.stages.sms_training import resolved

NAMES = ("train-a", "train-b", "sag")
PTS = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
U_REF = np.stack([np.tile([1.0, 0.0], (3, 1)) * s for s in (1.0, 2.0, 3.0)])  # (3, 3, 2)


class _Ref:
    """Estimated error: eps[load] x |u_ref| at every point (so each load's G_ref is eps)."""

    def __init__(self, eps):
        self.eps = eps

    def error_estimate(self, points, load):
        return np.full(len(points), self.eps[load] * (1.0 + NAMES.index(load)))


@dataclass(frozen=True)
class _Case:
    """What the drop reads of a case: its loads and the held-out names."""

    loads: tuple
    heldout: tuple

    @property
    def fit_loads(self):
        return tuple(l.name for l in self.loads if l.name not in self.heldout)


def _statics(scale):
    """A rule whose displacement is (1 + scale[load]) u_ref: its own normalised G on a load
    is |scale| (uniform weights: sqrt(sum |s u|^2) / sqrt(sum |u|^2))."""
    u = np.stack([U_REF[i] * (1.0 + scale[n]) for i, n in enumerate(NAMES)])
    return StaticsResult(NAMES, u, -u, np.ones(3))


def _run(eps, rules):
    case = _Case(tuple(types.SimpleNamespace(name=n) for n in NAMES), ("sag",))
    solved = {r: _statics(s) for r, s in rules.items()}
    return resolved(case, _Ref(eps), PTS, np.zeros(3, int), (1, 1, 1), NAMES, U_REF, solved)


RULES = {
    "r1": {"train-a": 0.20, "train-b": 0.30, "sag": 0.5},
    "r2": {"train-a": 0.10, "train-b": 0.6, "sag": 0.1},
}


def test_a_state_above_a_third_of_the_best_rule_is_dropped():
    """train-a: best rule r2 0.10, FEM 0.034 > 0.1/3 -> dropped; train-b: best 0.30, FEM 0.02
    kept; sag (held out) never judged. Everything after the drop is over the kept loads."""
    out = _run({"train-a": 0.034, "train-b": 0.02, "sag": 0.5}, RULES)
    assert out.dropped == ("train-a",)
    assert out.names == ("train-b", "sag") and out.case.fit_loads == ("train-b",)
    np.testing.assert_array_equal(out.u_ref, U_REF[1:])
    for rule, res in out.solved.items():
        assert res.names == out.names
        np.testing.assert_allclose(
            res.u,
            U_REF[1:] * (1 + np.array([RULES[rule]["train-b"], RULES[rule]["sag"]]))[:, None, None],
        )
    assert "train-a (FEM 3.4 %, best rule r2 10 %)" in out.line


def test_a_resolved_state_all_dropped_or_no_estimate_keeps_the_case():
    kept = _run({"train-a": 0.033, "train-b": 0.02, "sag": 0.5}, RULES)
    assert kept.dropped == () and kept.names == NAMES and kept.line == ""
    every = _run({"train-a": 0.5, "train-b": 0.5, "sag": 0.0}, RULES)  # nothing left to fit
    assert every.dropped == () and every.case.fit_loads == ("train-a", "train-b")
    nan = _run({"train-a": np.nan, "train-b": 0.02, "sag": 0.0}, RULES)
    assert nan.dropped == ()
