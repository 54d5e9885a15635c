"""Model capacity chosen by validation on the training states only (docs/design.md,
"Fitted and held-out loads").

A fit has choices the data must make: how many constants it may move (one scale for all
springs, a few groups, a few coefficients of the springs' geometric features, every
spring with a pull towards the rule, springs plus a volume term per element) and how hard
the pull is. Leave-one-family-out validation makes them: every candidate is fitted
without one fold of the training states and scored on it; the folds are the free-traction
families (constant, bending, torsion, shear-gradient, gravity: harness/case/linear_states.py)
and the clamped training states together. A candidate's ``free`` error is the mean over
its free-traction folds, its ``clamped`` the clamped fold's; the rule itself (no fit) is
scored the same way. The criterion (:func:`choose`):

- 'ratio' (the default): a candidate's ``ratio`` is the geometric mean of its free and
  clamped errors each divided by the rule's, so a fit 1.6x better on the free-traction
  states and 1.6x worse under the clamps ties with the rule, as it would in a geometric
  mean of error ratios over loads users run; the lowest ratio below 1 - MARGIN wins.
  Free-traction states alone cannot reveal that a fit got worse under a clamp, as
  springs at high nu do, so the clamped fold weighs as much as all free families; the
  clamped states hold faces at several places (harness/case/default_loads.py: the ends
  and the sides), since a fit that is better under one clamp can be worse under another.
- 'score': the lowest ``score`` (the arithmetic mean of free and clamped) that beats the
  rule's by more than MARGIN and is no worse than the rule's on the clamped fold.

Else the rule is the choice. The chosen candidate is refitted on all training states. The
held-out loads never choose anything: they are not in the problem given here. Nothing is
chosen by the clock: the validation always runs, every fit stops by iteration counts and
tolerances fixed before the run, and a wall-time cap only aborts (:func:`select`).

Every training state counts alike: each load's misfit is divided by its own reference
norm (``balanced``), so the fit and the scores see the relative error of each state, not
the states with the largest displacements.

Cost. The validation's fits solve subsets of the training states dozens of times; their
load sets (the free-traction states' minimal constraints, each clamped face) share one
factorisation per evaluation where that saves flops (FitProblem ``shared``,
harness/linalg/shared.py: the same solutions to rounding). The final fit, whose constants
are exported, factorises each load set on its own, as every other fit does. The fits run
side by side in forked workers as the CPUs and the free memory allow, a final fit of one
start with its load groups spread over them (harness/forkpool.py, harness/optimize/
evaluation.py: the same numbers as in the caller alone).

The problem holds the springs' columns first and, for the volume candidates, the volume
terms' columns after them (harness/models/volume.py: K = [B C] diag([k, kv]) [B C]^T): one
per element ('+volume') and one per node ('+node-volume', the averaged nodal dilatation,
which does not lock under a clamp); the volume candidates fit one kv shared by the terms.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import numpy as np

from harness import forkpool
from harness.case.sections import SELECT_CANDIDATES
from harness.linalg.sparse import single_thread_blas
from harness.optimize import select_counts
from harness.optimize.deadline import Deadline
from harness.optimize.deadline import deadline as limit
from harness.optimize.evaluation import spread, value_and_grad
from harness.optimize.few import few_fit
from harness.optimize.permatrix import per_matrix
from harness.optimize.problem import FitProblem
from harness.optimize.select_table import (  # noqa: F401 (the table's names, here as well)
    CLAMPED,
    MARGIN,
    choose,
    make_folds,
    ratio_to_rule,
    rule_row,
    scored,
    summary,
    training_score,
    two_folds,
)


@dataclass(frozen=True)
class Candidate:
    """One model capacity: ``groups`` 'one' (one scale for all springs), 'direction'
    (one per spring direction class and length tercile), 'spring' (per spring, pulled
    towards the rule with weight ``prior``), 'features' (log k = log k_rule + c0 + sum_j
    c_j phi_j, the learned rule's geometric features phi_j of each spring: a handful of
    coefficients fitted on this mesh); ``volume``: '' (springs only), 'element' or 'node':
    that volume term's columns join, with one shared kv (its own parameter)."""

    name: str
    groups: str
    prior: float = 0.0
    volume: str = ""


CANDIDATES = (
    Candidate("scale", "one"),
    Candidate("groups", "direction"),
    Candidate("springs-prior10", "spring", 10.0),
    Candidate("springs-prior1", "spring", 1.0),
    Candidate("springs-prior0.1", "spring", 0.1),
    Candidate("scale+volume", "one", volume="element"),
    Candidate("springs-prior1+volume", "spring", 1.0, volume="element"),
    Candidate("springs-prior0.1+volume", "spring", 0.1, volume="element"),
    Candidate("features", "features"),
    Candidate("features+volume", "features", volume="element"),
    Candidate("scale+node-volume", "one", volume="node"),
    Candidate("springs-prior1+node-volume", "spring", 1.0, volume="node"),
    Candidate("springs-prior0.1+node-volume", "spring", 0.1, volume="node"),
)


if tuple(c.name for c in CANDIDATES) != SELECT_CANDIDATES:
    raise ImportError(
        "harness.optimize.select.CANDIDATES and the case schema's SELECT_CANDIDATES differ: "
        "name a new candidate in both"
    )


@dataclass(frozen=True)
class Selection:
    """The choice ('rule' or a candidate's name); its constants over the problem's columns
    (spring-only choices: the springs' columns only) from each start of the final fit
    (``starts``, the exported one first: the lowest training objective); the validation
    table: one row per model (the rule first) with its score on each left-out family and
    the score that chose (``score``); ``stops``: the optimiser's stop message of each start
    (as ``starts``; none for the rule); ``seconds``: the wall time of the ``validation`` and
    of the ``final`` fit (reported, never used for a choice)."""

    choice: str
    starts: tuple
    table: tuple
    families: tuple
    stops: tuple = ()
    seconds: dict = dataclasses.field(default_factory=dict)

    @property
    def k(self) -> np.ndarray:
        return self.starts[0]

    @property
    def volume(self) -> str:
        """The chosen model's volume term: '' (none), 'element' or 'node'."""
        return (
            ""
            if self.choice == "rule"
            else next(c for c in CANDIDATES if c.name == self.choice).volume
        )


def balanced(problem: FitProblem, families=None) -> FitProblem:
    """Each block's weights divided by its reference's weighted norm squared: G^2 becomes
    the sum of the loads' own normalised G^2; with ``families``, the clamped states weigh as
    much together as the free-traction states together (the total weight unchanged)."""
    n = len(problem.blocks)
    side = [f == CLAMPED for f in families] if families is not None else [False] * n
    n_c = sum(side)
    part = [(n / (2 * n_c) if c else n / (2 * (n - n_c))) if 0 < n_c < n else 1.0 for c in side]
    blocks = []
    for b, a in zip(problem.blocks, part):
        r2 = float(b.u_ref @ (b.w * b.u_ref)) + b.const
        s = a / r2 if r2 > 0 else a
        blocks.append(dataclasses.replace(b, w=b.w * s, const=b.const * s))
    return dataclasses.replace(problem, blocks=tuple(blocks))


def subset(problem: FitProblem, keep) -> FitProblem:
    """The problem on the blocks ``keep`` (indices), nothing cached."""
    keep = list(keep)
    coords = None if problem.coords is None else tuple(problem.coords[i] for i in keep)
    return FitProblem(
        tuple(problem.blocks[i] for i in keep),
        problem.k0,
        problem.groups,
        problem.bounds,
        problem.modal,
        coords,
        problem.shared,
    )


def columns(
    problem: FitProblem,
    n_springs: int,
    cand: Candidate,
    kv0: float,
    groups: np.ndarray,
    volumes: dict | None = None,
) -> FitProblem:
    """The candidate's problem: its columns (springs, + its volume term's), start and
    parameter groups. ``volumes``: {'element' or 'node': (first, stop)}, where each volume
    term's columns sit in the problem (default: every column after the springs is an
    element's)."""
    volumes = volumes or {"element": (n_springs, problem.n_springs)}
    keep = np.arange(n_springs)
    if cand.volume:
        keep = np.concatenate([keep, np.arange(*volumes[cand.volume])])
    e = len(keep)

    def cut(B):  # kept per matrix: blocks (and networks) that share a B keep sharing one
        if B is None or e == problem.n_springs:
            return B
        return per_matrix(B, f"columns:{cand.volume or 'springs'}", lambda: B[:, keep].tocsc())

    blocks = tuple(
        dataclasses.replace(b, B=cut(b.B), network=cut(b.network)) for b in problem.blocks
    )
    k0 = problem.k0[keep].copy()
    if cand.volume:
        k0[n_springs:] = kv0
    g = {"one": np.zeros(n_springs, int), "direction": groups, "spring": None, "features": None}[
        cand.groups
    ]
    if cand.volume:
        top = (int(g.max()) + 1) if g is not None else n_springs
        springs = g if g is not None else np.arange(n_springs)
        g = np.concatenate([springs, np.full(e - n_springs, top)])
    return FitProblem(blocks, k0, g, problem.bounds, None, problem.coords, problem.shared)


def fit(
    problem: FitProblem, cand: Candidate, options: dict, x0=None, features=None, deadline=None
) -> np.ndarray:
    """The candidate's constants fitted on ``problem`` (as :func:`fit_result`), from
    the rule (x0 None) or from log(k/k0) = x0 per parameter; ``deadline``: a cap that
    aborts (harness/optimize/deadline.py; None: the options' max_seconds)."""
    return fit_result(problem, cand, options, x0, features, deadline)["k"]


def basis(problem: FitProblem, n_springs: int, features: np.ndarray) -> np.ndarray:
    """(columns, p) M of a 'features' candidate: log(k/k0) = M x over its columns; x =
    (c0, c_1..c_q[, the volume columns' common log factor])."""
    e = problem.n_springs
    M = np.zeros((e, 1 + features.shape[1] + (e > n_springs)))
    M[:n_springs, 0] = 1.0
    M[:n_springs, 1 : 1 + features.shape[1]] = features
    if e > n_springs:
        M[n_springs:, -1] = 1.0
    return M


def features_fit(problem: FitProblem, M: np.ndarray, options: dict, x0=None, deadline=None) -> dict:
    """k = k0 exp(M x) with x fitted by L-BFGS-B on G^2 / G0^2 (adjoint gradient; a few
    parameters: no prior), from x0 (None: 0, the rule); ``options``: maxiter (default
    200), the stop; max_seconds (or ``deadline``, a cap shared with other fits) aborts."""
    from scipy.optimize import minimize

    cap = limit(options, "the features fit", deadline)
    G0sq = value_and_grad(problem, problem.k0, grad=False)[0]
    best = [math.inf, None]

    def phi(x):
        cap.check()
        k = problem.k0 * np.exp(np.clip(M @ x, -30, 30))
        G2, g = value_and_grad(problem, k)
        if G2 / G0sq < best[0]:
            best[:] = [G2 / G0sq, np.array(x)]
        return G2 / G0sq, M.T @ (g * k) / G0sq

    from harness.optimize.gradient import scipy_stop

    x = np.zeros(M.shape[1]) if x0 is None else np.asarray(x0, float)
    bounds, opts = [(-7.0, 7.0)] * len(x), {"maxiter": int(options.get("maxiter") or 200)}
    stop = scipy_stop(minimize(phi, x, jac=True, method="L-BFGS-B", bounds=bounds, options=opts))
    return {
        "k": problem.k0 * np.exp(np.clip(M @ best[1], -30, 30)),
        "info": {"phi": float(best[0]), "stop": stop},
    }


def fit_result(
    problem: FitProblem, cand: Candidate, options: dict, x0=None, features=None, deadline=None
) -> dict:
    """lbfgs's result fields (harness/optimize/gradient.py) of the candidate's fit
    ('features' candidates: :func:`features_fit`, ``features`` the (springs, q) features;
    'one': harness/optimize/few.py, its maxiter counting evaluations); ``deadline`` as
    :func:`fit`'s."""
    from harness.optimize.gradient import lbfgs

    if cand.groups == "one":
        return few_fit(problem, options, x0, deadline)
    if cand.groups == "features":
        M = basis(problem, len(features), features)
        return features_fit(problem, M, options, x0, deadline)
    opts = dict(options)
    if cand.groups == "spring":
        opts["prior"] = cand.prior
    if x0 is not None:
        opts["x0"] = np.asarray(x0, float)
    return lbfgs(problem, opts, deadline=deadline)


def best_scale(problem: FitProblem) -> float:
    """The factor s minimising G^2 of s k0 (u scales as 1 / s): 1 / s = sum <u_ref, u0>_w /
    sum <u0, u0>_w over the blocks."""
    num = den = 0.0
    for b, u in zip(problem.blocks, problem.solve(problem.k0)):
        num += float(b.u_ref @ (b.w * u))
        den += float(u @ (b.w * u))
    return den / num if num > 0 else 1.0


def starts(problem: FitProblem, n: int, seed: int = 0, M: np.ndarray | None = None) -> list:
    """Start points (log(k/k0) per parameter; with a 'features' basis M its coefficients):
    the rule itself, its best global scale, then perturbations of the rule by factors
    exp(0.2 N(0, 1)) (seeded; M: of each coefficient)."""
    if M is None:
        npar, scale = problem.n_params, np.ones(problem.n_params)
    else:
        npar = M.shape[1]
        scale = np.linalg.lstsq(M, np.ones(len(M)), rcond=None)[0]  # M scale = 1: the global factor
    out = [np.zeros(npar)] + ([math.log(best_scale(problem)) * scale] if n > 1 else [])
    rng = np.random.default_rng(seed)
    out += [0.2 * rng.standard_normal(npar) for _ in range(max(n - 2, 0))]
    return out[:n]


def per_load(problem: FitProblem, k: np.ndarray) -> np.ndarray:
    """Each block's own normalised G at k (balanced problems: sqrt of its G^2)."""
    out = []
    for b, u in zip(problem.blocks, problem.solve(k)):
        d = b.u_ref - u
        r2 = float(b.u_ref @ (b.w * b.u_ref)) + b.const
        out.append(math.sqrt((float(d @ (b.w * d)) + b.const) / r2))
    return np.array(out)


def select(
    problem: FitProblem,
    n_springs: int,
    families,
    kv0: float,
    groups: np.ndarray,
    candidates=CANDIDATES,
    options: dict | None = None,
    final: dict | None = None,
    n_starts: int = 3,
    seed: int = 0,
    status=lambda msg: None,
    features: np.ndarray | None = None,
    rule_scores=None,
    volumes: dict | None = None,
    criterion: str = "ratio",
    max_seconds: float | None = None,
    workers: int | None = None,
    folds: str = "families",
    shared_final: bool = False,
) -> Selection:
    """Leave-one-family-out choice among ``candidates`` and the rule (module doc, :func:`choose`).
    ``problem``: the training states, columns [springs | volume terms] (k0 the rule's
    springs, anything positive for the volume terms; ``volumes`` says where each term's
    columns are, as :func:`columns`); ``families`` (one per block);
    ``options``: the validation fits' L-BFGS-B options, ``final``: the final fit's, from
    ``n_starts`` starts (seeded by ``seed``); ``features`` (springs, q): the learned rule's
    geometric features of the springs, which 'features' candidates need (None: skipped);
    ``rule_scores``: each block's own normalised G at the rule, when the caller has solved
    them (else solved here); ``criterion``: how a candidate must beat the rule; ``workers``:
    processes for the fits (None: as many as the tasks, the CPUs and the free memory over
    the largest predicted factorisation allow, harness/forkpool.py; the answer is
    the same bit for bit with any number); ``folds`` and ``shared_final``: as a level of
    harness/optimize/select_counts.py (its Counts) says.

    The validation always runs, and every fit stops by its options' maxiter and tolerances,
    counts given before the run: the choice and the constants depend on the input and the
    seed alone. ``max_seconds`` caps the wall time of the whole call (validation and final
    fit) and only aborts (harness/optimize/deadline.py); the options must not hold one."""
    if "max_seconds" in {**(options or {}), **(final or {})}:
        raise ValueError("select caps its fits together: pass max_seconds=, not in the options")
    t0, problem = time.perf_counter(), balanced(problem, families)
    candidates = [c for c in candidates if c.groups != "features" or features is not None]
    folds = two_folds(families) if folds == "two" else make_folds(families)
    _RUN.update(
        problem=problem,
        cands={
            c.name: (c, columns(problem, n_springs, c, kv0, groups, volumes)) for c in candidates
        },
        families=list(families),
        folds=folds,
        options=dict(options or {"maxiter": 40}),
        final=dict(final or options or {"maxiter": 40}),
        features=features,
        cap=Deadline(max_seconds, "the validated fit"),
        n_springs=n_springs,
        shared_final=shared_final,
    )
    for _, cp in _RUN["cands"].values():
        cp.prepare()  # before the pool forks: its workers share the networks' maps
    workers = workers or _workers(problem, len(candidates), folds, n_starts)
    _RUN["spread"] = workers if n_starts == 1 else 1  # one start: its load groups in workers
    try:
        with single_thread_blas():
            with forkpool.pool(workers) as ex:
                rule = columns(problem, n_springs, Candidate("rule", "one"), kv0, groups, volumes)
                scores = per_load(rule, rule.k0) if rule_scores is None else rule_scores
                table = [rule_row(scores, folds)]
                table += validate(ex, [c.name for c in candidates], status)
                best = choose(scored(table, tuple(folds)), criterion)
                seconds = {"validation": time.perf_counter() - t0, "final": 0.0}
                if best["model"] == "rule":
                    k = (problem.k0[:n_springs].copy(),)
                    return Selection("rule", k, tuple(table), tuple(folds), seconds=seconds)
                fits = final_fit(ex, best["model"], n_starts, seed, status) if n_starts > 1 else []
            fits = fits or final_fit(None, best["model"], 1, seed, status)  # its groups spread
    finally:
        _RUN.clear()
    seconds["final"] = time.perf_counter() - t0 - seconds["validation"]
    return _fitted(best["model"], fits, table, folds, seconds)


def _workers(problem: FitProblem, n_candidates: int, folds: dict, n_starts: int) -> int:
    """The fits' processes: as the tasks, the CPUs and the free memory over the largest
    predicted factorisation of an evaluation allow (each fit holds one)."""
    n = n_candidates * len(folds) if len(folds) > 1 else 0
    peak = max(select_counts.gbytes(problem, shared) for shared in (False, True))
    return forkpool.available_workers(max(n, n_starts), problem.n_springs, peak)


def _fitted(name: str, fits: list, table: list, folds: dict, seconds: dict) -> Selection:
    """The choice of candidate ``name``: its final fit's starts (:func:`final_fit`, the
    lowest objective first), the validation table and the wall time's split."""
    return Selection(
        name,
        tuple(k for _, k, _ in fits),
        tuple(table),
        tuple(folds),
        stops=tuple(stop for _, _, stop in fits),
        seconds=seconds,
    )


# what the fits of the running select share: set before its workers fork, so they have it
_RUN: dict = {}


def validate(ex, names: list, status) -> list:
    """The validation table's rows of the candidates ``names`` (of the running select): each
    fitted without each fold in turn and scored on it, in the pool ``ex``
    (harness/forkpool.py; None: here, one after the other), fit j of n announced by
    ``status``. No fold to leave out (one family): rows without scores."""
    folds = _RUN["folds"]
    tasks = [(c, f) for c in names for f in folds] if len(folds) > 1 else []
    n = len(tasks)

    def announce(j):
        c, f = tasks[j - 1]
        status(
            f"validation: {c} without {f} (fit {j} of {n})"
            if ex is None
            else (f"validation: {j - 1} of {n} fits done (fit {j} of {n})")
        )

    scores = dict(zip(tasks, forkpool.run(ex, _validation_fit, tasks, announce, status)))
    return [{"model": c, **{f: scores[c, f] for f in folds if (c, f) in scores}} for c in names]


def _validation_fit(task) -> float:
    """The left-out fold's mean normalised G of candidate ``task[0]`` fitted without fold
    ``task[1]`` (a task of :func:`validate`; its position in the list names it in the cap's
    phase)."""
    name, f = task
    r = _RUN
    cand, cp = r["cands"][name]
    out = r["folds"][f]
    j = list(r["cands"]).index(name) * len(r["folds"]) + list(r["folds"]).index(f) + 1
    n = len(r["cands"]) * len(r["folds"])
    r["cap"].phase = f"the validated fit's validation ({name} without {f} (fit {j} of {n}))"
    rest = [i for i in range(len(r["families"])) if i not in set(out)]
    cp = dataclasses.replace(cp, shared=True)  # many fits on subsets: the sets share solves
    k = fit(subset(cp, rest), cand, r["options"], features=r["features"], deadline=r["cap"])
    return float(per_load(subset(cp, out), k).mean())


def final_fit(ex, name: str, n_starts: int, seed: int, status) -> list:
    """[(training objective, constants, stop)] of candidate ``name``'s fit on every training
    state from each of :func:`starts`, the lowest objective first (in the pool ``ex``, as
    :func:`validate`)."""
    cand, cp = _RUN["cands"][name]
    M = basis(cp, _RUN["n_springs"], _RUN["features"]) if cand.groups == "features" else None
    tasks = [(name, i, x0, n_starts) for i, x0 in enumerate(starts(cp, n_starts, seed, M))]

    def announce(j):
        status(f"fitting {name} on every training state (start {j} of {n_starts})")

    fits = forkpool.run(ex, _final_start, tasks, announce, status)
    fits.sort(key=lambda t: t[0])
    return fits


def _final_start(task) -> tuple:
    """(training objective with the prior, constants, stop) of one start of the final fit."""
    name, i, x0, n_starts = task
    cand, cp = _RUN["cands"][name]
    cp = dataclasses.replace(cp, shared=True) if _RUN["shared_final"] else cp
    where = f"{name} on every training state (start {i + 1} of {n_starts})"
    _RUN["cap"].phase = f"the validated fit's final fit ({where})"
    with spread(cp, _RUN["spread"]):  # harness/optimize/evaluation.py
        r = fit_result(cp, cand, _RUN["final"], x0, _RUN["features"], _RUN["cap"])
    return r["info"]["phi"], r["k"], str(r["info"].get("stop"))
