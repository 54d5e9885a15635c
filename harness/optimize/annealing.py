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
    grouped = problem.groups is not None
    npar = problem.n_params
    e = problem.n_springs
    temperatures = int(opts["temperatures"] if opts["temperatures"] is not None else 2 * e)
    nlimit = int(opts["nlimit"] if opts["nlimit"] is not None else 2 * e)
    glimit = int(opts["glimit"] if opts["glimit"] is not None else e)
    max_steps = opts["max_steps"]
    lo, hi = problem.bounds
    use_refactor = refactor or grouped or opts["engine"] == "refactor"
    if use_refactor:
        eng = RefactorG(problem, problem.k0)
    else:
        eng = IncrementalG(
            problem,
            problem.k0,
            mode=opts["engine"],
            refactor_every=opts["refactor_every"],
            batch=int(opts["batch"]),
            dense_max=int(opts["dense_max"]),
        )
    t_loop = time.perf_counter()
    x = np.ones(npar)  # factors of k0 per parameter
    rng = np.random.default_rng(seed)
    G0 = eng.G()
    Gcur = G0
    best_G, best_x = G0, x.copy()
    T = opts["T0"] * G0
    trace = [(0, G0)]
    steps = accepted = uphill_total = 0
    chunk_i = CHUNK
    stop = None
    for i in range(temperatures):
        T *= opts["r"] ** i
        good = kk = uphill = 0
        G_start = Gcur
        while True:
            if chunk_i == CHUNK:
                par = rng.integers(npar, size=CHUNK)
                mult = np.exp(opts["factor"] * rng.uniform(-1.0, 1.0, size=CHUNK))
                pacc = rng.random(CHUNK)
                chunk_i = 0
            j = int(par[chunk_i])
            xn = min(max(x[j] * mult[chunk_i], lo), hi)
            p = pacc[chunk_i]
            chunk_i += 1
            if not grouped:
                eng.upcoming = par[chunk_i:]
                Gn = eng.propose(j, problem.k0[j] * xn)
            else:
                xv = x.copy()
                xv[j] = xn
                Gn = eng.propose_k(problem.k_of(xv))
            steps += 1
            kk += 1
            if Gn < Gcur:
                take = True
                good += 1
            else:
                take = T > 0 and p < np.exp((Gcur - Gn) / T)
                uphill += int(take)
            if take:
                eng.accept()
                x[j] = xn
                Gcur = Gn
                accepted += 1
                if Gcur < best_G:
                    best_G = Gcur
                    best_x = x.copy()
            else:
                eng.reject()
            if kk > nlimit or good > glimit:
                break
            if max_steps is not None and steps >= max_steps:
                stop = "max_steps"
                break
            if (steps & 15) == 0:
                cap.check()
        uphill_total += uphill
        trace.append((steps, Gcur))
        if status is not None and i % 10 == 0:
            status(f"sa T#{i + 1} of {temperatures} G={Gcur:.4g} best={best_G:.4g} steps={steps}")
        if stop:
            break
        if opts["tol"] > 0 and uphill == 0 and (G_start - Gcur) <= opts["tol"] * G_start:
            stop = "converged"
            break
    else:
        stop = "temperatures"
    loop_seconds = time.perf_counter() - t_loop
    k_best = problem.k_of(best_x)
    G_final = problem.G(k_best)  # independent check: a full re-solve
    seconds = time.perf_counter() - t_start
    return dict(
        k=k_best,
        G_initial=G0,
        G_final=G_final,
        trace=np.array(trace, float),
        seconds=seconds,
        n_steps=steps,
        accepted=accepted,
        info=dict(
            engine=eng.mode,
            stop=stop,
            temperatures_done=len(trace) - 1,
            temperatures=temperatures,
            nlimit=nlimit,
            glimit=glimit,
            T_abs0=opts["T0"] * G0,
            uphill=uphill_total,
            acceptance=accepted / max(steps, 1),
            G_best_tracked=best_G,
            seed=seed,
            rebases=eng.n_rebase,
            refactor_every=getattr(eng, "refactor_every", None),
            setup_seconds=t_loop - t_start,
            loop_seconds=loop_seconds,
            steps_per_s=steps / max(loop_seconds, 1e-12),
            e_squared_hours=e * e / max(steps / max(loop_seconds, 1e-12), 1e-12) / 3600,
        ),
    )


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
