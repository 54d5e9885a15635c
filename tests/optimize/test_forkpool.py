"""The validated fit's fits in forked worker processes (harness/forkpool.py): the
same selection bit for bit as one after the other in the caller (choice, every score,
every start's constants and stop), a cap passed inside a worker aborts in the same one
line, and the pool's bookkeeping (results in task order, errors raised in the caller)."""

import os
import signal
import sys

import numpy as np
import pytest

from harness import forkpool
from harness.optimize import select as sel
from tests.optimize.test_select import CANDS, FAMILIES, jumping_clock, problem

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fork: Linux")


def _select(prob, workers, **kw):
    groups = np.zeros(prob.n_springs, int)
    args = (FAMILIES, 1.0, groups, CANDS, {"maxiter": 20}, {"maxiter": 40}, 3)
    return sel.select(prob, prob.n_springs, *args, workers=workers, **kw)


def test_the_pool_gives_the_selection_of_the_fits_one_after_the_other():
    prob, _, _ = problem(np.full(1, 2.0))
    alone, pooled = _select(prob, 1), _select(prob, 2)
    assert pooled.choice == alone.choice != "rule"
    assert pooled.table == alone.table  # every score, bit for bit
    assert pooled.stops == alone.stops and len(pooled.starts) == 3
    for a, b in zip(pooled.starts, alone.starts):
        assert np.array_equal(a, b)


def test_a_cap_passed_in_a_worker_aborts_the_validated_fit_in_one_line(monkeypatch):
    from harness.optimize.deadline import BudgetExceeded

    prob, _, _ = problem(np.full(1, 2.0))
    jumping_clock(monkeypatch)  # the workers are forks: their clock jumps too
    with pytest.raises(BudgetExceeded) as err:
        _select(prob, 2, max_seconds=60.0)
    text = str(err.value)
    assert "\n" not in text and "past its budget max_seconds = 60 s;" in text
    assert "the validated fit's validation (" in text


def _square(x):
    return x * x


def _fail(x):
    if x == 3:
        raise ValueError("three")
    return x


def test_run_keeps_the_task_order_and_raises_a_tasks_error():
    announced = []
    with forkpool.pool(2) as ex:
        assert forkpool.run(ex, _square, range(7), announced.append) == [x * x for x in range(7)]
        with pytest.raises(ValueError, match="three"):
            forkpool.run(ex, _fail, range(6))
    assert announced[0] == 1 and announced == sorted(announced) and max(announced) <= 7
    with forkpool.pool(1) as ex:
        assert ex is None and forkpool.run(ex, _square, [2, 3]) == [4, 9]


def test_small_problems_and_workers_of_other_pools_stay_in_one_process():
    assert forkpool.available_workers(24, forkpool.MIN_COLUMNS - 1) == 1
    assert 1 <= forkpool.available_workers(24, forkpool.MIN_COLUMNS) <= forkpool.MAX_WORKERS
    assert forkpool.available_workers(1, 10**6) == 1


def _in_a_worker() -> bool:
    import multiprocessing as mp

    return mp.parent_process() is not None


def _dies_in_a_worker(x):
    """x squared; task 2 kills its worker process (as the system does when memory runs out)."""
    if x == 2 and _in_a_worker():
        os.kill(os.getpid(), signal.SIGKILL)
    return x * x


def test_a_dead_worker_hands_its_tasks_back_to_the_caller():
    said = []
    with forkpool.pool(2) as ex:
        out = forkpool.run(ex, _dies_in_a_worker, range(6), say=said.append)
        assert out == [x * x for x in range(6)]
        again = forkpool.run(ex, _square, [3, 4], say=said.append)  # the pool stays broken
    assert again == [9, 16]
    assert len(said) == 2 and "died (out of memory?)" in said[0] and "\n" not in said[0]
    assert "the 2 tasks left" in said[1]


_REAL_FIT = sel._validation_fit


def _validation_fit_dies_once(task):
    """The validation fit, whose second candidate's first fold kills its worker."""
    if task == (CANDS[1].name, FAMILIES[0]) and _in_a_worker():
        os.kill(os.getpid(), signal.SIGKILL)
    return _REAL_FIT(task)


def test_a_selection_whose_worker_died_is_the_selection_one_after_the_other(monkeypatch):
    prob, _, _ = problem(np.full(1, 2.0))
    alone = _select(prob, 1)
    monkeypatch.setattr(sel, "_validation_fit", _validation_fit_dies_once)
    said = []
    pooled = _select(prob, 2, status=said.append)
    assert any("died (out of memory?)" in m for m in said)
    assert pooled.choice == alone.choice and pooled.table == alone.table
    for a, b in zip(pooled.starts, alone.starts):
        assert np.array_equal(a, b)


def test_the_workers_share_the_networks_map_built_before_the_fork(monkeypatch, tmp_path):
    """The map k -> K (at 200k tets ~1 GB with a volume term) is built once, by the caller
    before the pool forks, and the workers' load sets and shared groups restrict it: no
    process but the caller builds a map (the rule's scores given, as calibrate gives them,
    so that nothing else would build it before the fork)."""
    from harness.linalg import shared
    from harness.optimize import permatrix as pm
    from harness.optimize import problem as pr

    log = tmp_path / "maps"

    def recording(make):
        def built(B):
            with open(log, "a") as f:
                f.write(f"{os.getpid()}\n")
            return make(B)

        return built

    monkeypatch.setattr(pr, "stiffness_map", recording(pr.stiffness_map))
    monkeypatch.setattr(pm, "stiffness_map", recording(pm.stiffness_map))
    monkeypatch.setattr(shared, "stiffness_map", recording(shared.stiffness_map))
    prob, _, _ = problem(np.full(1, 2.0))
    pooled = _select(prob, 2, rule_scores=np.ones(len(prob.blocks)))
    assert pooled.choice != "rule"
    pids = log.read_text().split()
    assert pids and set(pids) == {str(os.getpid())}


def test_a_thread_other_than_the_main_one_never_forks():
    """A fork beside running threads can inherit a lock one of them holds: from such a
    thread the tasks run in it, whatever the CPUs."""
    from concurrent.futures import ThreadPoolExecutor

    main = forkpool.available_workers(24, 10**6)
    with ThreadPoolExecutor(1) as pool:
        there = pool.submit(forkpool.available_workers, 24, 10**6).result()
    assert there == 1 and (main > 1 or len(os.sched_getaffinity(0)) == 1)
