"""Checks shared by the optimisers: their option tables and the static-only methods."""

from __future__ import annotations

import math

import numpy as np

from harness.errors import SpringbenchError
from harness.optimize.problem import FitProblem


def check_options(options: dict, defaults: dict, method: str) -> dict:
    """``options`` over ``defaults``. Unknown keys, and values that do not fit the
    default (a string for a string; else a finite number >= 0: every numeric option of
    these fits is a count, a tolerance, a weight or a budget), are one-line errors, not
    tracebacks from deep inside scipy."""
    unknown = set(options) - set(defaults)
    if unknown:
        raise SpringbenchError(
            f"unknown {method} option(s) {sorted(unknown)}",
            field="optimizer.options",
            fix=f"use some of {sorted(defaults)}",
        )
    for key, v in options.items():
        if key == "x0" and (v is None or isinstance(v, np.ndarray)):  # a start point, set in code
            continue
        if isinstance(defaults[key], str):
            if not isinstance(v, str):
                raise SpringbenchError(
                    f"{method} option {key} = {v!r} is not a string",
                    field=f"optimizer.options.{key}",
                    fix=f"e.g. {key} = {defaults[key]!r}",
                )
        elif not (
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= 0
        ):
            raise SpringbenchError(
                f"{method} option {key} = {v!r} is not a number >= 0",
                field=f"optimizer.options.{key}",
                fix="a count, tolerance or budget"
                + (f", e.g. {defaults[key]!r}" if defaults[key] else ""),
            )
    return {**defaults, **options}


def static_only(problem: FitProblem, method: str):
    """Refuse a frequency term for a method that fits static displacements only."""
    if problem.modal is not None and problem.modal.weight > 0:
        raise SpringbenchError(
            f"method '{method}' fits static displacements only; the frequency term needs 'lbfgs'",
            field="optimizer.method",
            fix="use method = 'lbfgs' or set the frequency weight to 0",
        )
