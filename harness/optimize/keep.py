"""The optimiser "none": the model's constants as the rule gave them (the unoptimised row)."""

from __future__ import annotations

import time

import numpy as np

from harness.errors import SpringbenchError
from harness.optimize.problem import FitProblem


def keep(problem: FitProblem, options: dict, seed: int = 0, status=None) -> dict:
    """k0 unchanged, with its G; it takes no options."""
    if options:
        raise SpringbenchError(
            f"method 'none' takes no options (got {sorted(options)})",
            field="optimizer.options",
            fix="remove [optimizer] options",
        )
    t0 = time.perf_counter()
    G = problem.G(problem.k0)
    return dict(
        k=problem.k0.copy(),
        G_initial=G,
        G_final=G,
        trace=np.array([(0, G)]),
        seconds=time.perf_counter() - t0,
        n_steps=0,
        accepted=0,
        info={},
    )
