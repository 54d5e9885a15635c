"""An evaluation spread over worker processes (harness/optimize/evaluation.py): the value
and the gradient of the caller alone bit for bit, the groups really computed in other
processes, and a validated fit of one start whose final fit is spread gives the selection
of the caller alone."""

import dataclasses
import os
import sys

import numpy as np
import pytest

from harness.optimize import evaluation, select
from harness.optimize.evaluation import spread, value_and_grad
from harness.optimize.synthetic import recoverable_problem
from tests.optimize.test_select import CANDS, FAMILIES, problem

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fork: Linux")


class _LOGGED:
    log, real = None, None


def _logged(*args):
    """evaluation.group_terms, its process id logged (module-level: a worker gets it by name;
    the workers are forks: they see the log the test set)."""
    with open(_LOGGED.log, "a") as f:
        f.write(f"{os.getpid()}\n")
    return _LOGGED.real(*args)


def test_a_spread_evaluation_is_the_callers_bit_for_bit(monkeypatch, tmp_path):
    prob = dataclasses.replace(recoverable_problem((8, 8, 8), seed=5)[0], shared=True)
    assert len(prob.solve_parts()) >= 2 and max(len(g) for g, _ in prob.solve_parts()) >= 2
    k = prob.k0 * np.random.default_rng(0).uniform(0.5, 2.0, prob.n_springs)
    here = value_and_grad(prob, k)
    log = tmp_path / "pids"
    monkeypatch.setattr(_LOGGED, "log", log)
    monkeypatch.setattr(_LOGGED, "real", evaluation.group_terms)
    monkeypatch.setattr(evaluation, "group_terms", _logged)
    with spread(prob, 2):
        there = value_and_grad(prob, k)
        again = value_and_grad(prob, k, grad=False)
    pids = log.read_text().split()
    assert len(pids) == 2 * len(prob.solve_parts()) and str(os.getpid()) not in pids
    assert there[0] == here[0] and np.array_equal(there[1], here[1])
    assert again[0] == here[0] and again[1] is None
    assert value_and_grad(prob, k)[0] == here[0]  # after the block: in the caller again
    assert log.read_text().split()[-1] == str(os.getpid())


def test_a_problem_of_one_group_is_not_spread():
    prob = select.subset(recoverable_problem((4, 4), seed=1)[0], [0])
    assert len(prob.solve_parts()) == 1
    with spread(prob, 2):
        assert id(prob) not in evaluation._SPREAD


def _one_start(prob, workers):
    groups = np.zeros(prob.n_springs, int)
    args = (FAMILIES, 1.0, groups, CANDS, {"maxiter": 20}, {"maxiter": 40}, 1)
    return select.select(prob, prob.n_springs, *args, workers=workers)


def test_a_final_fit_of_one_start_spread_gives_the_callers_selection(monkeypatch):
    prob, _, _ = problem(np.full(1, 2.0))
    assert len(prob.solve_parts()) >= 2
    alone = _one_start(prob, 1)
    spreads = []
    real = evaluation.spread

    def counted(p, workers):
        spreads.append(workers)
        return real(p, workers)

    monkeypatch.setattr(select, "spread", counted)
    pooled = _one_start(prob, 2)
    assert spreads == [2]
    assert pooled.choice == alone.choice != "rule"
    assert pooled.table == alone.table
    assert pooled.stops == alone.stops and len(pooled.starts) == 1
    assert np.array_equal(pooled.starts[0], alone.starts[0])
