"""Training states the reference resolves: the sms stage fits only the training states on
which the FEM's own estimated error is at most a third of the best stiffness rule's
(harness/scoring.py ``unresolved_training``); the others are dropped from the case before
any fit, named in a printed line and in the rows' ``training_dropped`` column. A fit that
chased the FEM's discretisation error on a state would learn the FEM's mistake; the
held-out loads are never dropped (the reference refines until they meet its tol).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from harness import scoring
from harness.mechanics.statics import StaticsResult


@dataclass(frozen=True)
class Training:
    """The case with the unresolved training states removed (``case``), its load names,
    the reference displacements and the rules' statics over them, and the states dropped
    (``dropped``, in the case's order) with the line that says why (``line``, "" if none)."""

    case: object
    names: tuple[str, ...]
    u_ref: np.ndarray
    solved: dict
    dropped: tuple[str, ...] = ()
    line: str = ""


def _only(res: StaticsResult, names) -> StaticsResult:
    """``res`` over the loads ``names`` alone."""
    at = [res.names.index(n) for n in names]
    seconds = None if res.load_seconds is None else res.load_seconds[at]
    return StaticsResult(tuple(names), res.u[at], res.forces[at], seconds)


def rule_errors(solved: dict, u_ref, names, fit_names, classes, weights) -> dict:
    """{rule: {training state: the rule's own normalised G on it}} of the solved rules."""
    at = [names.index(n) for n in fit_names]
    out = {}
    for rule, res in solved.items():
        u = res.u[[res.names.index(n) for n in fit_names]]
        out[rule] = dict(scoring.g_arrays(u_ref[at], u, classes, weights, fit_names).per_load_norm)
    return out


def resolved(case, ref, points, classes, weights, names, u_ref, solved) -> Training:
    """:class:`Training` of ``case``: its training states judged by the reference's error
    at the model's nodes (``points``) against the best rule's (``solved`` {rule: statics
    over every load}). Every state is kept when all of them would go (nothing left to fit:
    the rows' G_ref says the FEM is coarse) or the reference has no estimate."""
    fit_names = list(case.fit_loads)
    at = [names.index(n) for n in fit_names]
    ref_errors = scoring.load_ref_errors(ref, points, fit_names, u_ref[at], classes, weights)
    errors = rule_errors(solved, u_ref, names, fit_names, classes, weights)
    dropped = scoring.unresolved_training(ref_errors, errors, fit_names)
    if not dropped or len(dropped) == len(fit_names):
        return Training(case, names, u_ref, solved)
    kept = tuple(n for n in names if n not in dropped)
    loads = tuple(l for l in case.loads if l.name not in dropped)
    keep = [names.index(n) for n in kept]
    return Training(
        dataclasses.replace(case, loads=loads),
        kept,
        u_ref[keep],
        {r: _only(res, kept) for r, res in solved.items()},
        dropped,
        scoring.dropped_line(dropped, ref_errors, errors),
    )
