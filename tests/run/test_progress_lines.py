"""``springbench run``'s progress without a terminal (harness/progress.py SuiteProgress): a
line per finished case and, every 30 s, a line with the cases done, the elapsed time and
the time left, estimated from counts (the recorded seconds of the cases finished and still
to run), driven here by a fake clock; silent with --quiet and on a terminal."""

from __future__ import annotations

import pytest

from harness.progress import EVERY, Remaining, SuiteProgress, duration


class Clock:
    """A clock that moves only when told."""

    def __init__(self):
        self.now = 1000.0

    def __call__(self):
        return self.now


@pytest.fixture
def no_tty(monkeypatch):
    import sys

    monkeypatch.setattr(sys.stderr, "isatty", lambda: False, raising=False)


def test_a_line_every_30_s_with_the_time_left_from_the_cases_recorded_seconds(no_tty, capsys):
    clock = Clock()
    bar = SuiteProgress(3, None, {"a": 10.0, "b": 30.0, "c": None}, clock=clock, tick=None)
    assert EVERY == 30.0
    clock.now += 29
    assert not bar.poll() and capsys.readouterr().out == ""
    clock.now += 2
    bar.set("a", "sms: lbfgs")
    assert bar.poll()
    assert capsys.readouterr().out == (
        "[0/3] 31 s elapsed, time left: known once a case finishes (running: a: sms: lbfgs)\n"
    )
    clock.now += 9  # 40 s
    bar.done("a", "ok (40.0 s)")
    assert capsys.readouterr().out == "[1/3] a: ok (40.0 s)\n"
    clock.now += 10  # 50 s: 10 since the last line
    assert not bar.poll()
    clock.now += 21  # 71 s: the weight left is b's 30 and c's 20 (the mean), 10 finished
    assert bar.poll()
    assert capsys.readouterr().out == f"[1/3] 1 min 11 s elapsed, about {duration(71 * 5)} left\n"
    bar.done("b", "ok")
    bar.done("c", "ok")
    clock.now += 60
    assert not bar.poll()  # all done: no more lines
    bar.close()


def test_quiet_and_a_terminal_print_no_lines(monkeypatch, capsys):
    import sys

    clock = Clock()
    quiet = SuiteProgress(1, False, {"a": 1.0}, clock=clock, tick=None)
    clock.now += 100
    assert not quiet.poll()
    quiet.done("a", "ok")
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    tty = SuiteProgress(1, None, {"a": 1.0}, clock=clock, tick=None)
    clock.now += 100
    assert not tty.poll()
    quiet.close()
    tty.close()
    assert capsys.readouterr().out == ""


def test_the_estimate_is_the_weight_left_over_the_weight_done():
    clock = Clock()
    left = Remaining({"a": 1.0, "b": 3.0}, clock)
    assert left.seconds() is None
    clock.now += 20
    left.finish("b")
    assert left.seconds() == pytest.approx(20 * 1 / 3)
    left.finish("a")
    assert left.seconds() == 0.0
    assert [duration(s) for s in (5, 65, 3725)] == ["5 s", "1 min 05 s", "1 h 02 min"]


def test_the_runner_hands_the_recorded_seconds_to_the_progress(tmp_path, fake):
    from harness.run import runner
    from tests.fakestage import write_case

    seen = []

    class Spy(runner._Progress):
        def __init__(self, total, enabled, weights=None, **kw):
            seen.append(dict(weights))
            super().__init__(total, enabled, weights, **kw)

    suite = tmp_path / "cases" / "demo"
    write_case(suite, "a")
    write_case(suite, "b")
    orig, runner._Progress = runner._Progress, Spy
    try:
        runner.run_suite([suite], results=tmp_path / "r", jobs=1, figures=False, progress=False)
        runner.run_suite([suite], results=tmp_path / "r", jobs=1, figures=False, force=True)
    finally:
        runner._Progress = orig
    assert seen[0] == {"a": None, "b": None}  # never run: no record
    assert set(seen[1]) == {"a", "b"} and all(s > 0 for s in seen[1].values())
