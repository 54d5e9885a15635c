"""The optimisers' wall-time cap (harness/optimize/deadline.py) never stops a fit: under a
clock that jumps by hours at every reading each optimiser returns the same constants, stop
and step count as under the real clock, bit for bit; and a cap the clock passes aborts in
one line (the phase, the time it ran, the budget, the fix) instead of returning the best
point seen so far."""

import time

import numpy as np
import pytest

from harness.linalg.sparse import single_thread_blas
from harness.optimize import optimize
from harness.optimize import select as sel
from harness.optimize.deadline import FIX, BudgetExceeded, Deadline
from harness.optimize.synthetic import recoverable_problem

# (method, options that stop it by counts, grouped problem)
METHODS = [
    ("lbfgs", {"maxiter": 15}, False),
    ("nelder-mead", {"maxiter": 80}, True),
    ("gauss-newton", {"maxiter": 4}, False),
    ("sa", {"max_steps": 400}, False),
    ("sa-refactor", {"max_steps": 100}, False),
]
PHASE = {"sa-refactor": "the annealing chain", "sa": "the annealing chain"}


@pytest.fixture(autouse=True)
def _one_blas_thread():
    with single_thread_blas():
        yield


def jump(monkeypatch, hours: float = 3.0) -> list:
    """time.perf_counter jumping ``hours`` further at every reading (a machine so busy that
    every step seems to take hours); returns the reading count."""
    real, calls = time.perf_counter, [0]

    def clock():
        calls[0] += 1
        return real() + 3600.0 * hours * calls[0]

    monkeypatch.setattr(time, "perf_counter", clock)
    return calls


def problem(grouped: bool):
    return recoverable_problem((4, 3), sigma=0.3, seed=2, grouped=grouped)[0]


@pytest.mark.parametrize("method,options,grouped", METHODS)
def test_the_clock_never_changes_a_fit(monkeypatch, method, options, grouped):
    prob = problem(grouped)
    idle = optimize(prob, method, options, seed=0)
    calls = jump(monkeypatch)
    for cap in ({}, {"max_seconds": 1e300}):
        busy = optimize(prob, method, {**options, **cap}, seed=0)
        assert np.array_equal(busy.k, idle.k) and busy.info["stop"] == idle.info["stop"]
        assert busy.n_steps == idle.n_steps and busy.G_final == idle.G_final
    assert idle.G_final < idle.G_initial  # the fit moved: its counts, not the clock, stopped it
    assert calls[0] > 0


@pytest.mark.parametrize("method,options,grouped", METHODS)
def test_a_fit_past_its_cap_aborts_in_one_line(monkeypatch, method, options, grouped):
    prob = problem(grouped)
    jump(monkeypatch)
    with pytest.raises(BudgetExceeded) as err:
        optimize(prob, method, {**options, "max_seconds": 60.0}, seed=0)
    text = str(err.value)
    assert "\n" not in text and text.startswith("optimizer.options.max_seconds: ")
    assert f"{PHASE.get(method, f'the {method} fit')} aborted after " in text
    assert "past its budget max_seconds = 60 s;" in text and text.endswith(f"({FIX})")


def test_the_features_fit_obeys_the_same_contract(monkeypatch):
    """select's 'features' fit (its own L-BFGS-B loop): counts stop it, its cap aborts."""
    prob = sel.balanced(problem(False))
    X = np.linspace(0.0, 1.0, prob.n_springs)[:, None]
    M = sel.basis(prob, prob.n_springs, X)
    idle = sel.features_fit(prob, M, {"maxiter": 10})
    jump(monkeypatch)
    busy = sel.features_fit(prob, M, {"maxiter": 10, "max_seconds": 1e300})
    assert np.array_equal(busy["k"], idle["k"]) and busy["info"] == idle["info"]
    assert idle["info"]["phi"] < 1.0
    with pytest.raises(
        BudgetExceeded, match="the features fit aborted after .* max_seconds = 60 s;"
    ):
        sel.features_fit(prob, M, {"maxiter": 10, "max_seconds": 60.0})


def test_a_deadline_counts_from_its_start_and_names_its_phase(monkeypatch):
    now = [100.0]
    monkeypatch.setattr(time, "perf_counter", lambda: now[0])
    cap, none = Deadline(30.0, "the first phase"), Deadline(None, "uncapped")
    now[0] = 130.0
    cap.check()  # exactly at the cap: not past it
    cap.phase = "the second phase"
    now[0] = 130.5
    none.check()
    with pytest.raises(BudgetExceeded, match=r"^optimizer.options.max_seconds: the second phase "):
        cap.check()
    assert "aborted after 30.5 s, past its budget max_seconds = 30 s;" in str(
        pytest.raises(BudgetExceeded, cap.check).value
    )
