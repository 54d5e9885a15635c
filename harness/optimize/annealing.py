"""Simulated annealing of spring constants, Deussen, Kobbelt & Tücke 1995, Fig. 6.

Faithful to the figure: temperatures T_i = T_{i-1} r^i (over-exponential, i = 0, 1, ...),
per temperature proposals until more than ``nlimit`` were made or more than ``glimit``
were improvements; a proposal multiplies one random spring's constant (grouped mode: one
group's) by exp(factor * U(-1, 1)), clipped to the bounds; Metropolis acceptance of a
worse state with probability exp((G_current - G_new) / T). Differences from the figure,
deliberate: the temperature is relative, T = T0 * G(k0), so T0 is unit-free (the paper's
[1e-4, 1e-3] then means "a worsening of 0.01-0.1 % of the initial G is accepted with
probability 1/e"); the best state seen is kept (the figure's G_min is the current state);
budgets by steps and an optional convergence threshold end the run early (a wall-time cap,
``max_seconds``, only aborts it: harness/optimize/deadline.py).

G of a proposal comes from :class:`IncrementalG` (rank-1 updates, no factorisation) or,
for method "sa-refactor" and for grouped mode, from a full re-solve (:class:`RefactorG`).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

import numpy as np

from harness.errors import SpringbenchError
from harness.linalg.sparse import single_thread_blas
from harness.optimize.deadline import deadline as limit
from harness.optimize.incremental import IncrementalG
from harness.optimize.options import check_options as check_numbers
from harness.optimize.options import static_only
from harness.optimize.problem import FitProblem
from harness.optimize.refactor import RefactorG

DEFAULTS = dict(
    T0=1e-3,  # initial temperature, relative to G(k0)
    r=0.98,  # temperature reduction, T_i = T_{i-1} r^i
    temperatures=None,  # number of temperatures (None: 2 e, the paper's choice)
    nlimit=None,  # proposals per temperature (None: 2 e)
    glimit=None,  # improvements per temperature (None: e)
    factor=0.2,  # proposal spread: k *= exp(factor * U(-1, 1))
    tol=0.0,  # stop when a temperature improves G by < tol (relative) with no uphill move; 0: off
    max_steps=None,  # budget in proposals (None: unlimited)
    max_seconds=None,  # wall-time cap: passing it aborts the chain (None: none)
    chains=1,  # independent chains (seeds) in parallel processes; the best is kept
    engine="auto",  # "auto" | "dense" | "sparse" (incremental) | "refactor"
    # accepts between base renewals; "auto": dense 64, sparse flop balance 64..1024
    refactor_every="auto",
    # largest free block (dofs) for the dense-inverse engine under "auto" (bench sa: crossover
    # 1,000-1,800)
    dense_max=1200,
    batch=64,  # proposals whose K0^-1 b_e are solved together
)

CHUNK = 256  # proposals drawn from the RNG at a time (fixed: the stream is engine-independent)


def check_options(options: dict) -> dict:
    unknown = set(options) - set(DEFAULTS)
    if unknown:
        raise SpringbenchError(
            f"unknown simulated-annealing option(s) {sorted(unknown)}",
            field="optimizer.options",
            fix=f"use some of {sorted(DEFAULTS)}",
        )
    numbers = [k for k in DEFAULTS if k not in ("engine", "refactor_every")]
    check_numbers(
        {k: options[k] for k in numbers if k in options},
        dict.fromkeys(numbers, 0),
        "simulated-annealing",
    )
    if options.get("engine", "auto") not in ("auto", "dense", "sparse", "refactor"):
        raise SpringbenchError(
            f"unknown engine {options['engine']!r}",
            field="optimizer.options.engine",
            fix="auto, dense, sparse or refactor",
        )
    every = options.get("refactor_every", "auto")
    if every != "auto" and not (
        isinstance(every, int) and not isinstance(every, bool) and every > 0
    ):
        raise SpringbenchError(
            f"refactor_every = {every!r} is not a count of accepts",
            field="optimizer.options.refactor_every",
            fix='"auto" or a whole number of accepts > 0',
        )
    opts = {**DEFAULTS, **options}
    if not (0 < opts["r"] <= 1) or opts["T0"] < 0 or opts["factor"] <= 0:
        raise SpringbenchError(
            f"need 0 < r <= 1, T0 >= 0, factor > 0 (got r={opts['r']}, T0={opts['T0']}, "
            f"factor={opts['factor']})",
            field="optimizer.options",
            fix="e.g. T0 = 1e-3, r = 0.98, factor = 0.2",
        )
    return opts


def anneal(
    problem: FitProblem, options: dict, seed: int, status=None, refactor: bool = False
) -> dict:
    """One chain. Returns a dict of FitResult fields (k, G_initial, G_final, trace,
    seconds, n_steps, accepted, info)."""
    opts = check_options(options)
    static_only(problem, "sa")
    t_start = time.perf_counter()
    cap = limit(opts, "the annealing chain")
    e = problem.n_springs
    limits = _Limits(
        int(opts["temperatures"] if opts["temperatures"] is not None else 2 * e),
        int(opts["nlimit"] if opts["nlimit"] is not None else 2 * e),
        int(opts["glimit"] if opts["glimit"] is not None else e),
        opts["max_steps"],
    )
    eng = _engine(problem, opts, refactor)
    t_loop = time.perf_counter()
    draws = _Draws(np.random.default_rng(seed), problem.n_params, opts["factor"])
    G0 = eng.G()
    chain = _Chain(np.ones(problem.n_params), G0, G0, np.ones(problem.n_params))
    trace, stop, uphill = _cool(problem, eng, chain, draws, opts, limits, cap, status)
    loop_seconds = time.perf_counter() - t_loop
    k_best = problem.k_of(chain.best_x)
    G_final = problem.G(k_best)  # independent check: a full re-solve
    steps_per_s = chain.steps / max(loop_seconds, 1e-12)
    return dict(
        k=k_best,
        G_initial=G0,
        G_final=G_final,
        trace=np.array(trace, float),
        seconds=time.perf_counter() - t_start,
        n_steps=chain.steps,
        accepted=chain.accepted,
        info=dict(
            engine=eng.mode,
            stop=stop,
            temperatures_done=len(trace) - 1,
            temperatures=limits.temperatures,
            nlimit=limits.nlimit,
            glimit=limits.glimit,
            T_abs0=opts["T0"] * G0,
            uphill=uphill,
            acceptance=chain.accepted / max(chain.steps, 1),
            G_best_tracked=chain.best_G,
            seed=seed,
            rebases=eng.n_rebase,
            refactor_every=getattr(eng, "refactor_every", None),
            setup_seconds=t_loop - t_start,
            loop_seconds=loop_seconds,
            steps_per_s=steps_per_s,
            e_squared_hours=e * e / max(steps_per_s, 1e-12) / 3600,
        ),
    )


@dataclass(frozen=True)
class _Limits:
    """Fig. 6's counts: temperatures, proposals (nlimit) and improvements (glimit) per
    temperature, and the budget in proposals (None: unlimited)."""

    temperatures: int
    nlimit: int
    glimit: int
    max_steps: int | None


@dataclass
class _Chain:
    """The chain's state: the factors x of k0 and their G, the best seen, and the counts
    of proposals and accepts."""

    x: np.ndarray
    G: float
    best_G: float
    best_x: np.ndarray
    steps: int = 0
    accepted: int = 0


class _Draws:
    """The chain's random stream, drawn CHUNK proposals at a time (so it is the same for
    every engine): each proposal's parameter j, its multiplier exp(factor U(-1, 1)) and
    its Metropolis number U(0, 1)."""

    def __init__(self, rng, npar: int, factor: float):
        self.rng, self.npar, self.factor = rng, npar, factor
        self.i = CHUNK

    def next(self):
        """(j, multiplier, acceptance number) of the next proposal."""
        if self.i == CHUNK:
            self.par = self.rng.integers(self.npar, size=CHUNK)
            self.mult = np.exp(self.factor * self.rng.uniform(-1.0, 1.0, size=CHUNK))
            self.pacc = self.rng.random(CHUNK)
            self.i = 0
        i = self.i
        self.i += 1
        return int(self.par[i]), self.mult[i], self.pacc[i]

    def upcoming(self) -> np.ndarray:
        """The parameters of the drawn proposals still to come (the engine batches them)."""
        return self.par[self.i :]


def _engine(problem: FitProblem, opts: dict, refactor: bool):
    """G of a proposal: rank-1 updates (:class:`IncrementalG`), or full re-solves
    (:class:`RefactorG`) for sa-refactor, grouped mode or engine = "refactor"."""
    if refactor or problem.groups is not None or opts["engine"] == "refactor":
        return RefactorG(problem, problem.k0)
    return IncrementalG(
        problem,
        problem.k0,
        mode=opts["engine"],
        refactor_every=opts["refactor_every"],
        batch=int(opts["batch"]),
        dense_max=int(opts["dense_max"]),
    )


def _cool(problem, eng, chain: _Chain, draws: _Draws, opts: dict, limits: _Limits, cap, status):
    """The temperatures T_i = T_{i-1} r^i from T0 G(k0): (trace of (steps, G) after each,
    why the chain stopped, uphill moves taken)."""
    T = opts["T0"] * chain.G
    trace = [(0, chain.G)]
    uphill_total = 0
    for i in range(limits.temperatures):
        T *= opts["r"] ** i
        G_start = chain.G
        uphill, stop = _temperature(problem, eng, chain, draws, T, limits, cap)
        uphill_total += uphill
        trace.append((chain.steps, chain.G))
        if status is not None and i % 10 == 0:
            status(
                f"sa T#{i + 1} of {limits.temperatures} G={chain.G:.4g} best={chain.best_G:.4g} "
                f"steps={chain.steps}"
            )
        if stop:
            return trace, stop, uphill_total
        if opts["tol"] > 0 and uphill == 0 and (G_start - chain.G) <= opts["tol"] * G_start:
            return trace, "converged", uphill_total
    return trace, "temperatures", uphill_total


def _temperature(problem, eng, chain: _Chain, draws: _Draws, T: float, limits: _Limits, cap):
    """Proposals at temperature T until more than nlimit were made or more than glimit
    improved G, Metropolis acceptance of a worse one: (uphill moves, "max_steps" or None)."""
    lo, hi = problem.bounds
    grouped = problem.groups is not None
    good = kk = uphill = 0
    while True:
        j, mult, p = draws.next()
        xn = min(max(chain.x[j] * mult, lo), hi)
        if not grouped:
            eng.upcoming = draws.upcoming()
            Gn = eng.propose(j, problem.k0[j] * xn)
        else:
            xv = chain.x.copy()
            xv[j] = xn
            Gn = eng.propose_k(problem.k_of(xv))
        chain.steps += 1
        kk += 1
        if Gn < chain.G:
            take = True
            good += 1
        else:
            take = T > 0 and p < np.exp((chain.G - Gn) / T)
            uphill += int(take)
        if take:
            _accept(eng, chain, j, xn, Gn)
        else:
            eng.reject()
        if kk > limits.nlimit or good > limits.glimit:
            return uphill, None
        if limits.max_steps is not None and chain.steps >= limits.max_steps:
            return uphill, "max_steps"
        if (chain.steps & 15) == 0:
            cap.check()


def _accept(eng, chain: _Chain, j: int, xn: float, Gn: float) -> None:
    """The proposal becomes the chain's state (and its best, if it is)."""
    eng.accept()
    chain.x[j] = xn
    chain.G = Gn
    chain.accepted += 1
    if chain.G < chain.best_G:
        chain.best_G = chain.G
        chain.best_x = chain.x.copy()


def _chain_worker(args):
    problem, options, seed, refactor = args
    return anneal(problem, options, seed, None, refactor)


def chain_seeds(seed: int, chains: int) -> list[int]:
    """Chain 0 uses ``seed`` itself (so chains=1 and chains=2 share their first chain)."""
    extra = np.random.SeedSequence([seed, 1]).generate_state(max(chains - 1, 0))
    return [int(seed)] + [int(s) for s in extra]


def run_chains(
    problem: FitProblem, options: dict, seed: int, status=None, refactor: bool = False
) -> dict:
    """``chains`` independent chains; with more than one, each runs in its own process
    with single-threaded BLAS (env vars set before numpy loads there). Best G wins."""
    opts = check_options(options)
    chains = int(opts.get("chains") or 1)
    seeds = chain_seeds(seed, chains)
    if chains == 1:
        with single_thread_blas():
            return anneal(problem, options, seed, status, refactor)
    import multiprocessing as mp

    ctx = mp.get_context("spawn")
    saved = {
        v: os.environ.get(v) for v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
    }
    os.environ.update({v: "1" for v in saved})
    try:
        with ctx.Pool(min(chains, os.cpu_count() or 1)) as pool:
            results = pool.map(_chain_worker, [(problem, options, s, refactor) for s in seeds])
    finally:
        for v, old in saved.items():
            if old is None:
                os.environ.pop(v, None)
            else:
                os.environ[v] = old
    best = min(results, key=lambda r: r["G_final"])
    best["info"] = {
        **best["info"],
        "chains": chains,
        "chain_seeds": seeds,
        "chain_G_final": [r["G_final"] for r in results],
    }
    return best


def sa(problem: FitProblem, options: dict, seed: int = 0, status=None) -> dict:
    """Deussen 1995 Fig. 6 annealing with incremental (rank-1) G (registry name "sa")."""
    return run_chains(problem, options, seed, status)


def sa_refactor(problem: FitProblem, options: dict, seed: int = 0, status=None) -> dict:
    """The same chains, every proposal re-factorised: the paper's cost (the baseline)."""
    return run_chains(problem, options, seed, status, refactor=True)
