"""The constraint sets of one system, solved side by side.

Loads that hold the same dofs share one factorisation (a *set*: reference/problem.py
``solve_system``); the sets of one mesh (the held-out loads' clamp, the bridge's two
clamps, the clamped training states) are independent solves of K restricted to their
free dofs, so they run in forked worker processes (harness/forkpool.py) where the CPUs and
the free memory allow and the sets are large enough to be worth a process.

Every set is solved with one BLAS thread, in a worker as in the caller: a threaded LAPACK
factorisation rounds differently with one thread and with two (dpotrf of a 3,000 x 3,000
front: 3e-14 apart), so the reference, and every fit made on it, would depend on the
machine's CPUs. One thread per set gives the same numbers, bit for bit, on any machine and
however many workers run; the pool only changes the wall time.
"""

from __future__ import annotations

import dataclasses
import itertools
import warnings
from dataclasses import dataclass

import numpy as np

from harness import forkpool
from harness.linalg.sparse import single_thread_blas
from reference.solvers import sparse
from reference.solvers.plan import CHOLESKY_GBYTES
from reference.solvers.record import SolveRecord

# free dofs from which the sets are worth a process each: a fork and its first solve cost
# ~0.1 s; a P2 set of 10k free dofs factorises in ~0.1 s, of 28k in ~0.5 s (the README lug)
MIN_DOFS = 20_000


@dataclass(frozen=True)
class SetSolve:
    """One set: the loads ``names`` that share it, its ``free`` dofs, their right-hand
    sides (free, m) and ``tried``: a matrix-free solve that failed before it (its record)."""

    names: tuple[str, ...]
    free: np.ndarray
    rhs: np.ndarray
    tried: SolveRecord | None = None


@dataclass(frozen=True)
class Shared:
    """What the sets of one system share: the assembled stiffness ``K`` (all dofs), the
    case's solver ``method``, the rigid modes ``R`` and the location ``coords`` of every
    dof, the P1/Q1 subspace ``P`` (or None) and ``tensor_of(free)``, the tensor mesh's
    preconditioner of a set (None: not a tensor mesh)."""

    K: object
    method: str
    R: np.ndarray
    coords: np.ndarray
    P: object = None
    tensor_of: object = None


# the running solves' Shared and sets, by a token of each call: set before its pool forks (a
# worker inherits them); several calls may run at once in threads (the graded levels')
_RUNS: dict = {}
_TOKENS = itertools.count()


def solve_sets(shared: Shared, sets: list[SetSolve]) -> list[tuple[np.ndarray, SolveRecord]]:
    """(x (free, m), its SolveRecord) of each set, in the order given (module docstring);
    from a thread other than the main one (the graded levels') one after the other there
    (harness/forkpool.py never forks from such a thread)."""
    n = max(len(s.free) for s in sets)
    matrix_gb = 3 * 12 * shared.K.nnz / 1e9  # a set's restriction of K, equilibrated, sorted
    workers = forkpool.available_workers(len(sets), n, CHOLESKY_GBYTES + matrix_gb, MIN_DOFS)
    token = next(_TOKENS)
    _RUNS[token] = (shared, sets)
    try:
        with single_thread_blas(), forkpool.pool(workers) as ex:
            tasks = [(token, j) for j in range(len(sets))]
            return forkpool.run(ex, _solve_one, tasks, say=warnings.warn)
    finally:
        del _RUNS[token]


def _solve_one(task: tuple[int, int]) -> tuple[np.ndarray, SolveRecord]:
    """Set j of the solve ``token`` (a module-level function: a worker's task)."""
    token, j = task
    sh, s = _RUNS[token][0], _RUNS[token][1][j]
    tensor = sh.tensor_of(s.free) if sh.tensor_of is not None and s.tried is None else None
    done: list = []
    x = sparse.solve(
        sh.K[s.free][:, s.free],
        s.rhs,
        "auto" if s.tried else sh.method,
        sh.R[s.free],
        records=done,
        coords=sh.coords[s.free],
        coarse=None if sh.P is None else sh.P[s.free],
        tensor=tensor,
    )
    rec = done[0]
    if s.tried:
        rec = dataclasses.replace(rec, fallbacks=(s.tried,) + rec.fallbacks)
    return x, rec
