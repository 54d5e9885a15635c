"""calibrate's progress line follows the work (harness/commands/calibrate_progress.py): the
ETA of a phase is its elapsed time per unit done (fits, starts, iterations: the "k of n"
of the stage's messages) times the units left, whatever --budget is."""

import pytest

from harness.commands import calibrate_progress as cp


class Record:
    def __init__(self):
        self.calls = []

    def set(self, phase=None, detail=""):
        self.calls.append(("set", phase, detail))

    def bound(self, seconds):
        self.calls.append(("bound", seconds))


# (seconds since the start, message)
MESSAGES = [
    (0.0, "building the spring/mass system"),
    (5.0, "FEM adaptive level 1 (100 dofs)"),
    (10.0, "validation: scale without constant (fit 1 of 4)"),
    (22.0, "validation: scale without clamped (fit 2 of 4)"),
    (34.0, "validation: springs-prior1 without constant (fit 3 of 4)"),
    (50.0, "fitting springs-prior1 on every training state (start 1 of 3)"),
    (80.0, "fitting springs-prior1 on every training state (start 2 of 3)"),
]
# by hand: validation from 10 s, 1 fit done at 22 s (12 s), 3 left: 36 s; 2 done at 34 s
# (24 s), 2 left: 24 s; final fit from 50 s, 1 start done at 80 s (30 s), 2 left: 60 s
BOUNDS = [None, None, None, 36.0, 24.0, None, 60.0]


def run(monkeypatch, budget, messages):
    now = [0.0]
    monkeypatch.setattr(cp.time, "monotonic", lambda: now[0])
    rec = Record()
    status = cp.tracker(rec, budget, True)
    for t, msg in messages:
        now[0] = t
        status(msg)
    return rec


@pytest.mark.parametrize("budget", [60.0, 1e6])
def test_the_eta_follows_the_fits_done_not_the_budget(monkeypatch, budget):
    rec = run(monkeypatch, budget, MESSAGES)
    assert [c[1] for c in rec.calls if c[0] == "bound"] == pytest.approx(BOUNDS)
    phases = [c[1] for c in rec.calls if c[0] == "set"]
    assert phases == (
        ["building the network", "FEM reference"]
        + ["validation fit 1 of 4", "validation fit 2 of 4", "validation fit 3 of 4"]
        + ["final fit", "final fit"]
    )


def test_a_plain_fit_counts_its_iterations(monkeypatch):
    """lbfgs reports iteration k of maxiter once it is done: 10 of 400 after 4 s leaves
    390 x 0.4 s."""
    rec = run(
        monkeypatch,
        60.0,
        [(1.0, "optimising (lbfgs)"), (5.0, "lbfgs it 10 of 400 G=0.1"), (6.0, "a note")],
    )
    assert [c[1] for c in rec.calls if c[0] == "bound"] == pytest.approx([None, 156.0])
    assert rec.calls[-1] == ("set", None, "a note")


def test_left_reads_k_of_n():
    assert cp.left("start 1 of 3", True, 9.0) is None  # nothing done yet
    assert cp.left("start 3 of 3", True, 9.0) == pytest.approx(4.5)
    assert cp.left("it 3 of 3", False, 9.0) == 0.0
    assert cp.left("no count here", False, 9.0) is None
    assert cp.left("it 5 of 3", False, 9.0) is None  # not a count of this work


def test_the_closing_line_splits_the_wall_time_by_phase(monkeypatch):
    """By hand from MESSAGES (+ rules at 8 s, the end at 95 s of 100): building 5 s, FEM
    reference 3 s, rules 2 s, validation 40 s, final fit 45 s, the rest 5 s."""
    now = [0.0]
    monkeypatch.setattr(cp.time, "monotonic", lambda: now[0])
    spent = {}
    status = cp.tracker(Record(), spent=spent)
    messages = sorted(MESSAGES + [(8.0, "statics of the 6 stiffness rules")])
    for t, msg in messages:
        now[0] = t
        status(msg)
    now[0] = 95.0
    status.stop()
    assert spent == {"building": 5, "fem": 3, "rules": 2, "validation": 40, "final": 45}
    assert cp.split(spent, 100.0) == (
        "wall time: building 5 s, FEM reference 3 s, rules 2 s, validation 40 s, "
        "final fit 45 s, the rest 5 s (100 s)"
    )
