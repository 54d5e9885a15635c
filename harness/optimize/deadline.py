"""The optimisers' wall-time cap (option ``max_seconds``; calibrate's ``--budget``): an
upper bound that aborts, never a stop. Fits stop by iteration counts and tolerances fixed
before the run, so the same input and seed give the same answer on any machine under any
load; a fit that passes its cap raises :class:`BudgetExceeded` (one line: the phase, how
long it ran, the fix) instead of returning the best point seen so far, which would be a
different answer on a slower or busier machine."""

from __future__ import annotations

import time

from harness.errors import SpringbenchError

FIX = "raise --budget (or max_seconds) or coarsen the mesh"


class BudgetExceeded(SpringbenchError):
    """A fit ran past its wall-time cap and was aborted."""


class Deadline:
    """The cap ``seconds`` (None: none) on the work of ``phase``, counted from creation.
    :meth:`check` is called between evaluations; ``phase`` may be renamed as the work
    moves on (the validated fit names the fit it is in), so the error says where."""

    def __init__(self, seconds, phase: str):
        self.seconds = None if seconds is None else float(seconds)
        self.phase = phase
        self.t0 = time.perf_counter()

    def check(self) -> None:
        """Raise :class:`BudgetExceeded` when more than ``seconds`` have passed."""
        if self.seconds is None:
            return
        ran = time.perf_counter() - self.t0
        if ran > self.seconds:
            raise BudgetExceeded(
                f"{self.phase} aborted after {ran:.3g} s, past its budget max_seconds = "
                f"{self.seconds:g} s; the fits stop by their iteration counts, the budget only "
                "aborts",
                field="optimizer.options.max_seconds",
                fix=FIX,
            )


def deadline(options: dict, phase: str, given: Deadline | None = None) -> Deadline:
    """``given`` (a cap shared by several fits) or the cap of ``options['max_seconds']``."""
    return given if given is not None else Deadline(options.get("max_seconds"), phase)
