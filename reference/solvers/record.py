"""What one solve did: :class:`SolveRecord` (what solved it, to what residual, after which
failed attempts), made once the solve is over and appended to the caller's list."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Fallback:
    """A step that was not accepted: its name (``method``), residual, why, and its wall
    seconds."""

    method: str
    residual: float
    reason: str
    seconds: float


@dataclass(frozen=True)
class SolveRecord:
    """One factorisation or iterative solve (all the loads sharing its constraints).

    ``method``: the step that solved it (a key of ``reference.solvers.sparse.STEPS``, or
    'linear' for a linear field found without a solve);
    ``residual``: max over the columns of ||b - A x|| / ||b||; ``rtol``: the tolerance it
    was accepted at; ``iterations`` (iterative methods); ``seconds`` (wall, the whole
    solve); ``fallbacks``: the attempts before; ``estimate``: the Cholesky's symbolic
    estimate {gflop, gbytes} when one was made; ``loads``: the loads it solved; ``n``: free
    dofs; ``nnz``: nonzeros of A (when recorded); ``matrix_free``: K was never assembled;
    ``coarse``: solved in a coarser subspace (reference/adaptive/coarse.py)."""

    method: str
    residual: float = 0.0
    rtol: float = 0.0
    iterations: int = 0
    seconds: float = 0.0
    fallbacks: tuple[Fallback, ...] = ()
    estimate: dict | None = None
    loads: tuple[str, ...] = ()
    n: int = 0
    nnz: int = 0
    matrix_free: bool = False
    coarse: bool = False
