"""A benchmark's finished units are read back only when their inputs and code are the ones
they ran with (harness/bench/resume.py)."""

import numpy as np
import pytest

from harness.bench.resume import kept


def _boom():
    raise AssertionError("ran again")


@pytest.fixture
def module(tmp_path):
    """A stand-in for the benchmark's own module (its hash is part of the code)."""
    f = tmp_path / "bench_module.py"
    f.write_text("X = 1\n")
    return f


def test_a_finished_unit_is_read_back_not_run(tmp_path, module):
    work = tmp_path / "work"
    row = dict(n=np.int64(3), err=np.float64(0.25), note="ok", missing=float("nan"))
    first = kept(work, "cyl1000", dict(n=1000, sizes=(1, 2)), str(module), lambda: row)
    again = kept(work, "cyl1000", dict(n=1000, sizes=(1, 2)), str(module), _boom, status=print)
    assert again["n"] == 3 and again["err"] == 0.25 and np.isnan(again["missing"])
    assert first is row  # the computed row itself the first time


def test_changed_inputs_or_code_run_again(tmp_path, module):
    work = tmp_path / "work"
    kept(work, "u", dict(n=1000), str(module), lambda: [dict(a=1)])
    with pytest.raises(AssertionError, match="ran again"):
        kept(work, "u", dict(n=2000), str(module), _boom)
    assert kept(work, "u", dict(n=1000), str(module), _boom) == [dict(a=1)]
    module.write_text("X = 2\n")  # the benchmark's code changed
    with pytest.raises(AssertionError, match="ran again"):
        kept(work, "u", dict(n=1000), str(module), _boom)


def test_no_work_folder_always_runs(tmp_path, module):
    assert kept(None, "u", {}, str(module), lambda: 1) == 1
    with pytest.raises(AssertionError, match="ran again"):
        kept(None, "u", {}, str(module), _boom)
