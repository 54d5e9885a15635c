"""bench calibrate's measurement of one run: its exit code, output and its own peak memory
(not the largest of every run before it). Linux gives a spawned process the resident-set
high-water mark of the process that spawned it (exec keeps it), so every peak here is
compared with this process's own."""

import os
import resource
import sys

from harness.bench.calibrate import measured


def _run(tmp_path, code: str, name: str):
    logs = (tmp_path / f"{name}.out", tmp_path / f"{name}.err")
    return measured([sys.executable, "-c", code], dict(os.environ), logs)


def _own_gb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6


def _touch(n_bytes: int) -> str:
    return f"x = bytearray({n_bytes}); x[::4096] = b'1' * len(x[::4096])"


def test_each_run_reports_its_own_peak(tmp_path):
    own = _own_gb()
    big = int((own + 0.5) * 1e9)
    _, proc, peak_big = _run(tmp_path, _touch(big) + "; print('done')", "big")
    assert proc.returncode == 0 and proc.stdout.strip() == "done"
    assert own + 0.45 <= peak_big < own + 1.0
    # a small run after it: its own peak (at most this process's), not the big one's
    _, proc, peak_small = _run(tmp_path, "import sys; sys.exit(3)", "small")
    assert proc.returncode == 3 and peak_small < _own_gb() + 0.1 < peak_big


def test_a_fork_workers_peak_counts(tmp_path):
    """A child that allocates after the fork (as a fit worker does): the run's peak is its."""
    own = _own_gb()
    code = (
        "import os\n"
        "pid = os.fork()\n"
        "if pid == 0:\n"
        f"    {_touch(int((own + 0.4) * 1e9))}; os._exit(0)\n"
        "os.waitpid(pid, 0)\n"
    )
    _, proc, peak = _run(tmp_path, code, "fork")
    assert proc.returncode == 0 and own + 0.35 <= peak < own + 1.0


def _rows(change=()):
    """bench calibrate's rows that meet every target, one field of one row changed."""
    import pandas as pd

    rows = [
        dict(body="cylinder", n_tets=n, choice=c, start_rule="vangelder", fit_ratio=f, peak_gb=p)
        for n, c, f, p in (
            (875, "springs-prior1", 3.0, 0.5),  # small meshes: no time target
            (9_261, "springs-prior1+node-volume", 0.9, 2.0),
            (48_880, "scale+node-volume", 0.7, 3.9),
            (201_639, "scale", 0.5, 11.0),
        )
    ]
    rows.append(
        dict(
            body="bracket",
            n_tets=30_512,
            choice="springs-prior1",
            start_rule="vangelder",
            fit_ratio=0.9,
            peak_gb=2.5,
            G_heldout_mean=0.04,
            G_heldout_mean_best_rule=0.05,
        )
    )
    df = pd.DataFrame(rows)
    df["ratio_to_rule"] = df.fit_ratio + 1
    for (i, key), value in dict(change).items():
        df.loc[i, key] = value
    return df


def test_verdict_names_each_missed_target():
    from harness.bench.calibrate import verdict

    assert verdict(_rows()).startswith("PASS")
    for change, words in (
        ({(2, "choice"): "rule"}, "48880 tets exported the rule vangelder"),
        ({(1, "fit_ratio"): 1.2}, "9261 tets: fit 1.20x"),
        ({(2, "peak_gb"): 4.2}, "peak 4.2 GB > 4"),
        ({(3, "peak_gb"): 12.5}, "peak 12.5 GB > 12"),
        ({(4, "G_heldout_mean"): 0.045}, "held-out 0.90x the best rule"),
        ({(4, "ratio_to_rule"): 2.3}, "in 2.30x the rule-only time"),
        ({(4, "choice"): "rule"}, "bracket 30512 tets exported the rule"),
    ):
        text = verdict(_rows(change))
        assert text.startswith("FAIL") and words in text, (change, text)
