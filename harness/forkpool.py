"""Independent tasks in forked worker processes: the validated fit's 24 or so validation fits
and its final fit's starts, the reference's constraint sets (each its own factorisation)
depend on the input alone, so they can run side by side.

A worker is a fork of the caller, so it starts with everything the caller has built (the
problem, the compiled kernels, the cached orderings) and fills its own caches as it goes;
each task is a module-level function and small arguments, its result comes back pickled.
Every task runs with one BLAS thread, in a worker as in the caller, so a task's numbers are
the same bit for bit whichever process runs it and however many there are: the pool
changes the wall time, never the answer. The workers are as many as the CPUs, the tasks
and the free memory allow (a task's largest factorisation, predicted from its symbolic
factorisation: ~3 GB for a fit of a 200k-tet body with a node-volume term). Without fork
(not Linux), inside a worker of another pool, or for small problems, the tasks run one
after the other in the caller; so do the tasks left when a worker dies (the system kills
the largest process when memory runs out), said in one line.
"""

from __future__ import annotations

import math
import os
import signal
import sys
import threading
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager

MAX_WORKERS = 8
# springs (columns) from which a validated fit's fits are worth a process each (a fork and
# its first solves cost ~0.1-0.5 s; a fit of a 3,000-spring network takes seconds)
MIN_COLUMNS = 1000


# a worker's own memory per GB of its largest predicted factorisation: the estimate holds
# the factor and its largest fronts; the rest is the fit's cached orderings and restrictions
# (0.9 GB beside a 3.2 GB factor at 200k tets, measured)
WORKER_MEMORY = 1.5


def available_workers(
    n_tasks: int, size: int, task_gbytes: float = 0.0, min_size: int = MIN_COLUMNS
) -> int:
    """Processes for ``n_tasks`` tasks of a problem of ``size`` (a fit's constants, a solve's
    dofs): the CPUs this process may run on (at most MAX_WORKERS and the tasks) and, for
    tasks whose largest factorisation is ``task_gbytes`` (predicted), as many as the free
    memory now holds (WORKER_MEMORY each); 1 where forking is unavailable (not Linux), the
    caller is itself a pool's worker or runs in a thread other than the main one (a fork
    beside running threads can inherit a lock one of them holds), or the problem is smaller
    than ``min_size``."""
    import multiprocessing as mp

    if (
        not sys.platform.startswith("linux")
        or mp.parent_process() is not None
        or threading.current_thread() is not threading.main_thread()
        or size < min_size
    ):
        return 1
    n = min(len(os.sched_getaffinity(0)), MAX_WORKERS, n_tasks)
    if task_gbytes > 0:
        n = min(n, int(free_gbytes() // (WORKER_MEMORY * task_gbytes)))
    return max(1, n)


def free_gbytes() -> float:
    """The memory the system can give without swapping now (GB: MemAvailable)."""
    with open("/proc/meminfo") as f:
        for line in f:
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) / 1e6
    return math.inf


def _worker_init():
    """Worker initialiser: Ctrl-C is the caller's to handle (it stops the pool), and the
    worker writes to fresh null streams: a fork copies the caller's stream locks as they
    were, held perhaps by its progress line's thread, which the fork does not copy. The
    tasks print nothing; their errors come back to the caller."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    sys.stdout = sys.stderr = open(os.devnull, "w")


@contextmanager
def pool(workers: int):
    """A pool of ``workers`` forked processes for :func:`run` (None when ``workers`` is 1:
    :func:`run` then works in the caller). The workers are forked at the first task, so
    they inherit what the caller built before it."""
    if workers <= 1:
        yield None
        return
    import multiprocessing as mp

    ex = ProcessPoolExecutor(workers, mp_context=mp.get_context("fork"), initializer=_worker_init)
    try:
        yield ex
    finally:  # after an error the tasks not begun are dropped, not run to no purpose
        ex.shutdown(wait=True, cancel_futures=True)


def run(executor, fn, tasks, announce=lambda j: None, say=lambda msg: None) -> list:
    """[fn(task) for task in tasks], in the pool ``executor`` (or in the caller when None).
    ``announce(j)``: task j (from 1) of them is next: in the caller as it begins, in a pool
    as j - 1 tasks have finished (the pool's tasks start in their order). An error in a task
    is raised here as it was raised there. A worker that dies (killed by the system, e.g.
    out of memory) breaks the pool: the tasks without a result then run here, one after the
    other, with the same numbers (every task runs with one BLAS thread in either place);
    ``say`` gets the one line that says so."""
    tasks = list(tasks)
    if not tasks:
        return []
    if executor is None:
        return _here(fn, tasks, range(len(tasks)), [None] * len(tasks), announce)
    out, done = [None] * len(tasks), set()
    try:
        futures = {executor.submit(fn, task): j for j, task in enumerate(tasks)}
        pending = set(futures)
        announce(1)
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for f in finished:
                out[futures[f]] = f.result()
                done.add(futures[f])
            if pending:
                announce(len(tasks) - len(pending) + 1)
    except BrokenProcessPool:
        left = [j for j in range(len(tasks)) if j not in done]
        say(
            f"a worker process died (out of memory?): the {len(left)} tasks left run here "
            "one after the other (the same numbers, more time)"
        )
        return _here(fn, tasks, left, out, announce)
    return out


def _here(fn, tasks, which, out, announce) -> list:
    """``out`` with fn(tasks[j]) for each j of ``which``, run in the caller in order."""
    for j in which:
        announce(j + 1)
        out[j] = fn(tasks[j])
    return out
