"""Spring-constant optimisers: a registry name -> function(problem, options, seed, status)
returning the fields of :class:`FitResult`. A new optimiser is one function added here
and its name in the case file's vocabulary (``harness.case.sections.OPTIMIZER_METHODS``).

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

import time
from dataclasses import dataclass, field

import numpy as np

from harness.case.sections import OPTIMIZER_METHODS
from harness.errors import SpringbenchError
from harness.optimize.problem import FitProblem, LoadBlock, ModalTerm  # noqa: F401


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


def _sa(problem, options, seed, status=None):
    from harness.optimize.annealing import run_chains
    return run_chains(problem, options, seed, status)


def _sa_refactor(problem, options, seed, status=None):
    from harness.optimize.annealing import run_chains
    return run_chains(problem, options, seed, status, refactor=True)


def _lbfgs(problem, options, seed, status=None):
    from harness.optimize.gradient import lbfgs
    return lbfgs(problem, options, seed, status)


def _nelder_mead(problem, options, seed, status=None):
    from harness.optimize.gradient import nelder_mead
    return nelder_mead(problem, options, seed, status)


def _gauss_newton(problem, options, seed, status=None):
    from harness.optimize.gradient import gauss_newton
    return gauss_newton(problem, options, seed, status)


def _equilibrium_gap(problem, options, seed, status=None):
    from harness.optimize.equilibrium import equilibrium_gap
    return equilibrium_gap(problem, options, seed, status)


def _none(problem, options, seed, status=None):
    if options:
        raise SpringbenchError(f"method 'none' takes no options (got {sorted(options)})", field="optimizer.options",
                               fix="remove [optimizer] options")
    t0 = time.perf_counter()
    G = problem.G(problem.k0)
    return dict(k=problem.k0.copy(), G_initial=G, G_final=G, trace=np.array([(0, G)]),
                seconds=time.perf_counter() - t0, n_steps=0, accepted=0, info={})


OPTIMIZERS = {
    "sa": _sa,
    "sa-refactor": _sa_refactor,
    "lbfgs": _lbfgs,
    "nelder-mead": _nelder_mead,
    "gauss-newton": _gauss_newton,
    "equilibrium-gap": _equilibrium_gap,
    "none": _none,
}
if set(OPTIMIZERS) != set(OPTIMIZER_METHODS):
    raise ImportError(f"harness.optimize.OPTIMIZERS {sorted(OPTIMIZERS)} and the case schema's "
                      f"OPTIMIZER_METHODS {sorted(OPTIMIZER_METHODS)} differ: name a new optimiser in both")


def check_method_options(method: str, options: dict) -> dict:
    """``options`` of ``method`` over its defaults, checked without running it (for
    ``springbench validate``: unknown keys and unusable values are one-line errors)."""
    from harness.optimize import annealing, equilibrium, gradient
    from harness.optimize.options import check_options
    if method in ("sa", "sa-refactor"):
        return annealing.check_options(options)
    defaults = {"lbfgs": gradient.LBFGS_DEFAULTS, "nelder-mead": gradient.NM_DEFAULTS,
                "gauss-newton": gradient.GN_DEFAULTS, "equilibrium-gap": equilibrium.EG_DEFAULTS}.get(method)
    return dict(options) if defaults is None else check_options(options, defaults, method)


def optimize(problem: FitProblem, method: str, options: dict | None = None, seed: int = 0,
             status=None) -> FitResult:
    """Fit a model's constants to the reference.

    Parameters
    ----------
    problem : harness.optimize.problem.FitProblem
        The model, its loads and the reference displacements it is fitted to.
    method : str
        A name of ``OPTIMIZERS`` (the case files' ``[optimizer] method``).
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
        raise SpringbenchError(f"unknown optimizer method '{method}'", field="optimizer.method",
                               fix=f"use one of {sorted(OPTIMIZERS)}")
    from harness.linalg.sparse import single_thread_blas
    with single_thread_blas():  # threads oversubscribe the 2 shared cores; chains use processes
        out = OPTIMIZERS[method](problem, dict(options or {}), int(seed), status)
    info = {**out.pop("info"), "method": method, "seed": int(seed)}
    return FitResult(info=info, **out)
