"""What a scored load needs of the reference (docs/design.md): training states the reference
cannot resolve to a third of the best rule's error on them are named for dropping, a
``ref-coarse`` row names its cause, and the tol verdict can leave the training states to the
G_ref rule. Hand-made numbers and stand-in references."""

from __future__ import annotations

import math
import types

import numpy as np
import pytest

from harness.scoring import (
    TRAINING_FRACTION,
    coarse_cause,
    dropped_line,
    load_ref_errors,
    ref_columns,
    ref_note,
    unresolved_training,
)
from reference.adaptive.adapt import Stop

RULES = {
    "lloyd": {"train-tip": 0.20, "train-z-y": 0.30, "shear": 0.10, "train-x": 0.05},
    "uniform": {"train-tip": 0.12, "train-z-y": 0.50, "shear": 0.40, "train-x": math.nan},
}


def test_unresolved_training_by_hand():
    """Above a third of the lowest rule error is dropped; at or below it, kept; a state with
    no estimate (NaN) or no finite rule error is kept; the order is fit_loads'."""
    assert TRAINING_FRACTION == 1 / 3
    ref = {"train-tip": 0.0401, "train-z-y": 0.0999, "shear": 0.0, "train-x": 0.0167}
    fit = ("shear", "train-z-y", "train-tip", "train-x")
    # train-tip: best 0.12 (uniform, not lloyd's 0.20) -> 0.0401 > 0.04: dropped;
    # train-z-y: best 0.30 -> 0.0999 <= 0.1 kept; train-x: best 0.05 (NaN ignored) -> dropped
    assert unresolved_training(ref, RULES, fit) == ("train-tip", "train-x")
    assert unresolved_training({**ref, "train-tip": 0.0399}, RULES, fit) == ("train-x",)  # < 1/3
    assert unresolved_training({**ref, "train-x": math.nan}, RULES, fit) == ("train-tip",)
    assert unresolved_training(ref, {"u": {"train-tip": math.nan}}, fit) == ()  # no rule error
    assert unresolved_training(ref, RULES, ("shear",)) == ()  # only the loads asked about
    line = dropped_line(("train-tip",), ref, RULES)
    assert "train-tip (FEM 4 %, best rule uniform 12 %)" in line and "a third" in line
    assert dropped_line((), ref, RULES) == ""


class _Ref:
    """A stand-in reference: u = (1, 0) at every point, estimate eps[load] * |u| there,
    the loads ``targets`` its tol applies to, and a Stop record."""

    def __init__(self, eps, targets, stop, tol=0.01):
        self.case = types.SimpleNamespace(reference=types.SimpleNamespace(tol=tol))
        self.targets, self.stop, self.met_tol = tuple(targets), stop, False
        values = dict(eps)

        class Est(dict):
            def __call__(self, points, load):
                return np.full(len(points), values[load])

        self.error_estimate = Est(values)

    def displacement(self, points, load):
        return np.tile([1.0, 0.0], (len(points), 1))


def _columns(ref, names, **kw):
    pts = np.array([[0.0, 0.0], [1.0, 0.0]])
    u = np.array([ref.displacement(pts, n) for n in names])
    return ref_columns(ref, pts, names, u, np.zeros(2, int), (1, 1, 1), **kw)


def test_ref_note_names_the_load_its_estimate_and_the_cap():
    stop = Stop("cap", 265_260, 300_000, 398_817)
    ref = _Ref(
        {"sag": 0.017, "tip": 0.004, "bridge": 0.021, "train-tip": 0.5},
        ["sag", "tip", "bridge"],
        stop,
    )
    note = ref_note(ref)
    assert note.startswith("FEM estimate above tol 1 %: bridge 2.1 %, sag 1.7 %;")
    assert "tip " not in note and "train-tip" not in note  # met, or not a target
    assert "dof cap: 265,260 dofs, the next level would have 398,817 (cap 300,000)" in note
    assert _columns(ref, ["sag"])["ref_note"] == note  # the reference's, whatever the row's loads
    met = _Ref({"sag": 0.009}, ["sag"], Stop("tol", 50_000, 300_000))
    assert ref_note(met) == "" and _columns(met, ["sag"])["ref_note"] == ""
    assert "no estimate" in ref_note(_Ref({"sag": math.nan}, ["sag"], Stop("single", 6_000, 0)))
    assert "ref_note" not in _columns(_Ref({"sag": 0.5}, ["sag"], None), ["sag"])  # no record


def test_tol_loads_leave_training_states_to_the_g_ref_rule():
    ref = _Ref({"train-tip": 0.02, "lin": 0.0, "sag": 0.0}, ["sag"], Stop("tol", 1, 2))
    assert _columns(ref, ["train-tip", "lin"])["ref_met_tol"] is False  # default: tol on all
    assert _columns(ref, ["train-tip", "lin"], tol_loads=("lin",))["ref_met_tol"] is True
    assert _columns(ref, ["train-tip", "lin"], tol_loads=())["ref_met_tol"] is True
    nan = _Ref({"train-tip": math.nan, "lin": 0.0}, ["lin"], Stop("single", 1, 2))
    assert _columns(nan, ["train-tip", "lin"], tol_loads=("lin",))["ref_met_tol"] is False


def test_coarse_cause_names_each_reason():
    row = dict(status="ref-coarse", ref_met_tol=False, ref_note="FEM estimate above tol 1 %: x")
    row.update(G_ref=0.02, G_norm_final=0.1, G_ref_heldout=0.004, G_heldout=0.2)
    assert (
        coarse_cause(row)
        == "FEM estimate above tol 1 %: x; G_ref 2 % above 1/10 of G_norm_final 10 %"
    )
    assert coarse_cause({**row, "status": "ok"}) == ""
    held = dict(status="ref-coarse", ref_met_tol=True, G_ref=0.001, G_norm_final=0.1)
    held.update(G_ref_heldout=0.03, G_heldout=0.2)
    assert coarse_cause(held) == "G_ref_heldout 3 % above 1/10 of G_heldout 20 %"


def test_load_ref_errors_are_each_loads_own_g_ref():
    ref = _Ref({"a": 0.01, "b": 0.2}, ["a"], None)
    pts = np.array([[0.0, 0.0], [1.0, 0.0]])
    u = np.array([ref.displacement(pts, n) for n in "ab"])
    out = load_ref_errors(ref, pts, ["a", "b"], u, np.zeros(2, int), (1, 1, 1))
    assert out == pytest.approx({"a": 0.01, "b": 0.2}, rel=1e-12)
