"""G^2 and its gradient dG^2/dk by the adjoint method (docs/design.md, "The G criteria"),
one group of load sets at a time (a factorisation each: FitProblem.solve_parts), in the
caller or spread over forked worker processes (:func:`spread`).

The groups of one evaluation are independent solves, so a single fit (the final fit, one
start) can use both cores of a machine: each worker computes whole groups' terms, and the
caller adds every load set's term in the same order as the caller alone does, so the value
and the gradient are the same bit for bit with or without workers (every solve with one
BLAS thread in either place, harness/forkpool.py). Memory: a worker holds one group's
factorisation at a time, as the caller does.
"""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np

from harness import forkpool

# the running spreads: id(problem) -> (pool, problem); set before the pool forks (a worker
# inherits the problem and everything its caches hold)
_SPREAD: dict = {}


def value_and_grad(problem, k: np.ndarray, grad: bool = True, tension2: np.ndarray | None = None):
    """G^2 and dG^2/dk (e,) of a FitProblem at k. If ``tension2`` (e,) is given, the squared
    spring tensions of the model's solutions, sum over loads of (k_e b_e.u)^2, are added to
    it (in the caller: a spread evaluates without them)."""
    k = np.asarray(k, float)
    if tension2 is None:
        parts = per_group(problem, k, group_terms, grad)
    else:
        parts = _here(problem, k, group_terms, (grad, tension2))
    G2, g = 0.0, (np.zeros(len(k)) if grad else None)
    for part in parts:
        for term, gradient in part:
            G2 += term
            if grad:
                g += gradient
    return G2, g


def per_group(problem, k: np.ndarray, fn, *args) -> list:
    """[fn(group, solve, k, *args)] of each group of the problem's load sets at k (a fresh
    factorisation each, FitProblem.solvers), in the caller or, within :func:`spread`, in
    its workers (``fn`` a module-level function: it is pickled by its name); the list in the
    groups' order either way."""
    running = _SPREAD.get(id(problem))
    if running is None:
        return list(_here(problem, np.asarray(k, float), fn, args))
    tasks = [(id(problem), j, k, fn, args) for j in range(len(problem.solve_parts()))]
    return forkpool.run(running[0], _remote, tasks)


def group_terms(group: list, solve, k: np.ndarray, grad: bool, tension2=None) -> list:
    """[(G^2 term, its gradient or None)] of each load set of one group, given the group's
    solver (FitProblem.solver_of)."""
    Us = solve([s.F for s in group])
    out, Rs = [], []
    for s, U in zip(group, Us):
        D = s.Uref - U
        Rs.append(s.W * D)
        out.append([float(np.sum(D * Rs[-1])) + s.const, None])
        if tension2 is not None:
            tension2 += np.sum((k[:, None] * (s.B.T @ U)) ** 2, axis=1)
    if grad:
        for term, s, U, Lam in zip(out, group, Us, solve(Rs)):
            term[1] = 2.0 * np.sum((s.B.T @ Lam) * (s.B.T @ U), axis=1)
    return out


def _here(problem, k: np.ndarray, fn, args):
    """Each group's fn(...) in the caller, its factorisation dropped before the next one."""
    for group, solve in problem.solvers(k):
        yield fn(group, solve, k, *args)
        del solve  # its factorisation, before the next one


def _remote(task):
    """One group's fn(...) (a task of a spread's pool)."""
    token, j, k, fn, args = task
    group, solve = _SPREAD[token][1].solver_of(j, k)
    return fn(group, solve, k, *args)


@contextmanager
def spread(problem, workers: int):
    """Within the block, :func:`per_group` (and so :func:`value_and_grad`) of ``problem``
    (this very object) sends its groups to a pool of ``workers`` processes (at most one per
    group; none when that is one: the caller evaluates). The pool forks at the first
    evaluation after the block begins, so what the caller computed before it (the first
    evaluation's orderings and maps) is shared."""
    workers = min(workers, len(problem.solve_parts()))
    if workers <= 1:
        yield
        return
    with forkpool.pool(workers) as ex:
        _SPREAD[id(problem)] = (ex, problem)
        try:
            yield
        finally:
            del _SPREAD[id(problem)]
