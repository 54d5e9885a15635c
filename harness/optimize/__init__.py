"""Spring-constant optimisers: functions(problem, options, seed, status) returning the
fields of :class:`FitResult`, registered by name in ``harness.registry.OPTIMIZERS`` (the
case files' ``[optimizer] method`` reads its names there). A new optimiser is one module
and one line in the registry.

- "sa": simulated annealing as in Deussen 1995 Fig. 6, with incremental (rank-1) G.
- "sa-refactor": the same chain, every proposal re-factorised (the paper's cost; baseline).
- "lbfgs": adjoint gradient, L-BFGS-B over log k with bounds (the default for large nets).
- "nelder-mead": derivative-free, for grouped mode with few parameters.
- "gauss-newton": Levenberg-Marquardt with CG on the normal equations (adjoint products);
  far faster than L-BFGS-B on large networks (see bench fit).
- "equilibrium-gap": the equation-error estimate (one sparse linear least squares, see
  equilibrium.py); also the ``init = "equilibrium-gap"`` start of lbfgs / gauss-newton.
- "none": keep k0 (the unoptimised row).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from harness.errors import SpringbenchError
from harness.linalg.sparse import single_thread_blas
from harness.optimize import annealing, equilibrium
from harness.optimize.options import check_options
from harness.optimize.problem import FitProblem, LoadBlock, ModalTerm  # noqa: F401
from harness.registry import OPTIMIZERS


@dataclass(frozen=True)
class FitResult:
    """k (e,) the best constants found; G before/after (G_final by a full re-solve);
    trace (m, 2) of (step, G); wall seconds; proposals/evaluations; accepted steps."""

    k: np.ndarray
    G_initial: float
    G_final: float
    trace: np.ndarray
    seconds: float
    n_steps: int
    accepted: int
    info: dict = field(default_factory=dict)


def check_method_options(method: str, options: dict) -> dict:
    """``options`` of ``method`` over its defaults, checked without running it (for
    ``springbench validate``: unknown keys and unusable values are one-line errors)."""
    # slow to import (tests/test_imports.py LAZY)
    from harness.optimize import gauss_newton, gradient

    if method in ("sa", "sa-refactor"):
        return annealing.check_options(options)
    defaults = {
        "lbfgs": gradient.LBFGS_DEFAULTS,
        "nelder-mead": gradient.NM_DEFAULTS,
        "gauss-newton": gauss_newton.GN_DEFAULTS,
        "equilibrium-gap": equilibrium.EG_DEFAULTS,
    }.get(method)
    return dict(options) if defaults is None else check_options(options, defaults, method)


def optimize(
    problem: FitProblem, method: str, options: dict | None = None, seed: int = 0, status=None
) -> FitResult:
    """Fit a model's constants to the reference.

    Parameters
    ----------
    problem : harness.optimize.problem.FitProblem
        The model, its loads and the reference displacements it is fitted to.
    method : str
        A name of ``harness.registry.OPTIMIZERS`` (the case files' ``[optimizer] method``).
    options : dict, optional
        The method's options (checked: unknown keys are one-line errors).
    seed : int
        The only source of the fit's randomness.
    status : callable, optional
        Called with short progress messages.

    Returns
    -------
    FitResult
        The constants found, G before and after, the trace, wall seconds, and ``info``
        (method, seed, why it stopped, evaluations).
    """
    if method not in OPTIMIZERS:
        raise SpringbenchError(
            f"unknown optimizer method '{method}'",
            field="optimizer.method",
            fix=f"use one of {sorted(OPTIMIZERS)}",
        )
    with single_thread_blas():  # threads oversubscribe the 2 shared cores; chains use processes
        out = OPTIMIZERS.load(method)(problem, dict(options or {}), int(seed), status)
    info = {**out.pop("info"), "method": method, "seed": int(seed)}
    return FitResult(info=info, **out)
