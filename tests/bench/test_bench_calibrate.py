"""bench calibrate's measurement of one run: its exit code, output and its own peak memory
(not the largest of every run before it)."""

import os
import sys

from harness.bench.calibrate import measured


def _run(tmp_path, code: str, name: str):
    logs = (tmp_path / f"{name}.out", tmp_path / f"{name}.err")
    return measured([sys.executable, "-c", code], dict(os.environ), logs)


def test_each_run_reports_its_own_peak(tmp_path):
    big = "x = bytearray(400_000_000); x[::4096] = b'1' * len(x[::4096]); print('done')"
    _, proc, peak_big = _run(tmp_path, big, "big")
    assert proc.returncode == 0 and proc.stdout.strip() == "done"
    assert 0.4 <= peak_big < 1.0
    # a small run after it: its own peak, not the big one's
    _, proc, peak_small = _run(tmp_path, "import sys; sys.exit(3)", "small")
    assert proc.returncode == 3 and peak_small < 0.2


def test_a_fork_workers_peak_counts(tmp_path):
    """A child that allocates after the fork (as a fit worker does): the run's peak is its."""
    code = (
        "import os\n"
        "pid = os.fork()\n"
        "if pid == 0:\n"
        "    x = bytearray(300_000_000); x[::4096] = b'1' * len(x[::4096]); os._exit(0)\n"
        "os.waitpid(pid, 0)\n"
    )
    _, proc, peak = _run(tmp_path, code, "fork")
    assert proc.returncode == 0 and 0.3 <= peak < 1.0
