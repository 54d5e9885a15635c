"""A benchmark's finished units are read back only when their inputs and code are the ones
they ran with (harness/bench/resume.py)."""

import numpy as np
import pytest

from harness.bench.resume import kept


def _boom():
    raise AssertionError("ran again")


@pytest.fixture
def module(monkeypatch, tmp_path):
    """A stand-in for a benchmark's module: resume's own folder moved to tmp_path (every
    module of harness/bench/ is part of a unit's code)."""
    import harness.bench.resume as resume

    f = tmp_path / "bench_module.py"
    f.write_text("X = 1\n")
    monkeypatch.setattr(resume, "__file__", str(tmp_path / "resume.py"))
    return f


def test_a_finished_unit_is_read_back_not_run(tmp_path, module):
    work = tmp_path / "work"
    row = dict(n=np.int64(3), err=np.float64(0.25), note="ok", missing=float("nan"))
    first = kept(work, "cyl1000", dict(n=1000, sizes=(1, 2)), lambda: row)
    again = kept(work, "cyl1000", dict(n=1000, sizes=(1, 2)), _boom, status=print)
    assert again["n"] == 3 and again["err"] == 0.25 and np.isnan(again["missing"])
    assert first is row  # the computed row itself the first time


def test_changed_inputs_or_code_run_again(tmp_path, module):
    work = tmp_path / "work"
    kept(work, "u", dict(n=1000), lambda: [dict(a=1)])
    with pytest.raises(AssertionError, match="ran again"):
        kept(work, "u", dict(n=2000), _boom)
    assert kept(work, "u", dict(n=1000), _boom) == [dict(a=1)]
    module.write_text("X = 2\n")  # the benchmark's code changed
    with pytest.raises(AssertionError, match="ran again"):
        kept(work, "u", dict(n=1000), _boom)


def test_no_work_folder_always_runs(tmp_path, module):
    assert kept(None, "u", {}, lambda: 1) == 1
    with pytest.raises(AssertionError, match="ran again"):
        kept(None, "u", {}, _boom)


def test_a_failed_unit_runs_again(tmp_path, module):
    work = tmp_path / "work"
    failed = dict(note="killed")
    assert kept(work, "u", {}, lambda: failed, finished=lambda r: not r["note"]) is failed
    done = dict(note="")
    assert kept(work, "u", {}, lambda: done, finished=lambda r: not r["note"]) is done
    assert kept(work, "u", {}, _boom, finished=lambda r: not r["note"]) == done
