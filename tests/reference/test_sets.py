"""The constraint sets of one system solved side by side (reference/solvers/sets.py): the
same numbers, bit for bit, in forked workers as one after the other in the caller, and
whatever number of BLAS threads the caller allows (a threaded factorisation would round
differently)."""

import os
import sys

import numpy as np
import pytest
import skfem
from threadpoolctl import threadpool_limits

from harness import forkpool
from harness.linalg.sparse import single_thread_blas
from reference.fem import Discretisation
from reference.problem import solve_system
from reference.solvers import sets

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fork: Linux")


def isotropic(E=1.0, nu=0.3) -> np.ndarray:
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    C = np.zeros((6, 6))
    C[:3, :3] = lam
    C[np.arange(6), np.arange(6)] += np.r_[[2 * mu] * 3, [mu] * 3]
    return C


def bar(n: int):
    """A 3 x 1 x 1 P2 bar (3n x n x n cells): four constraint sets (each end clamped, both,
    a side) under a body force and an end traction-like load each."""
    mesh = skfem.MeshTet.init_tensor(*[np.linspace(0, s, s * n + 1) for s in (3, 1, 1)])
    d = Discretisation(mesh, "tet", "P2")
    K = d.stiffness(np.tile(isotropic(), (d.nelems, 1, 1)))
    where = {
        "x0": lambda x: x[0] < 1e-9,
        "x1": lambda x: x[0] > 3 - 1e-9,
        "both": lambda x: (x[0] < 1e-9) | (x[0] > 3 - 1e-9),
        "y0": lambda x: x[1] < 1e-9,
    }
    g = d.body_load(np.tile([0.0, 0.3, -1.0], (d.nelems, 1)))
    loads, fixed = {}, {}
    for name, pred in where.items():
        held = d.part_dofs(pred, range(3))
        for k, F in enumerate((g, np.roll(g, 1))):
            loads[f"{name}-{k}"], fixed[f"{name}-{k}"] = F, held
    return K, loads, fixed, d


def _solve(n, workers, monkeypatch, threads=1, log=None):
    monkeypatch.setattr(forkpool, "available_workers", lambda *a, **k: workers)
    if log is not None:  # which processes solve (inside the task: a fork has the patch)
        solve = sets.sparse.solve

        def logged(*args, **kw):
            with open(log, "a") as f:
                f.write(f"{os.getpid()}\n")
            return solve(*args, **kw)

        monkeypatch.setattr(sets.sparse, "solve", logged)
    K, loads, fixed, d = bar(n)
    records = []
    with threadpool_limits(threads):
        out = solve_system(K, loads, fixed, "direct", d, records=records)
    return out, records


def test_the_sets_solved_in_workers_equal_those_solved_one_after_the_other(monkeypatch, tmp_path):
    alone, rec1 = _solve(2, 1, monkeypatch)
    log = tmp_path / "pids"
    pooled, rec2 = _solve(2, 2, monkeypatch, log=log)
    assert set(alone) == set(pooled) and len(alone) == 8
    for name in alone:
        assert np.array_equal(alone[name], pooled[name]), name
    pids = set(log.read_text().split())
    assert len(pids) == 2 and str(os.getpid()) not in pids  # two workers solved them
    # one record per set, in the sets' order, naming its loads
    assert [r.loads for r in rec1] == [r.loads for r in rec2]
    assert [r.loads for r in rec1] == [(f"{s}-0", f"{s}-1") for s in ("x0", "x1", "both", "y0")]


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="needs two CPUs for two threads")
def test_the_reference_is_the_same_with_one_blas_thread_or_two(monkeypatch):
    """Fronts of >= 1000 dofs would factorise with every BLAS thread the caller allows: a
    set is solved with one, so a machine's CPUs do not change the reference's rounding."""
    one, _ = _solve(6, 1, monkeypatch, threads=1)
    two, _ = _solve(6, 1, monkeypatch, threads=2)
    for name in one:
        assert np.array_equal(one[name], two[name]), name


def test_solves_running_at_once_in_threads_keep_their_own_sets(monkeypatch):
    """The graded levels solve meshes in threads: two solves at once each get their own
    sets' answers (one finishing first must not take the other's sets away), solved in
    their thread (no fork beside running threads)."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    barrier, solve, pids = threading.Barrier(2, timeout=60), sets.sparse.solve, set()

    def together(*args, **kw):  # both threads inside a set's solve at once, once
        pids.add(os.getpid())
        if not getattr(threading.current_thread(), "met", False):
            threading.current_thread().met = True
            barrier.wait()
        return solve(*args, **kw)

    alone, _ = _solve(2, 1, monkeypatch)
    monkeypatch.undo()  # forkpool's own choice from here
    monkeypatch.setattr(sets.sparse, "solve", together)
    monkeypatch.setattr(sets, "MIN_DOFS", 0)  # large enough: only the thread keeps it here
    K, loads, fixed, d = bar(2)
    # as the graded levels run them: one BLAS thread held around the pool by its caller
    with single_thread_blas(), ThreadPoolExecutor(2) as pool:
        outs = list(pool.map(lambda _: solve_system(K, loads, fixed, "direct", d), range(2)))
    for out in outs:
        assert all(np.array_equal(out[n], alone[n]) for n in alone)
    assert pids == {os.getpid()}
