"""springbench run: suites, resume, failures, same-seed identity, pool/Dask, kill -9.

The stages are replaced by a tiny fake stage (tests/test_runner_fakestages.py) so these
tests do not depend on the real stages' progress."""

from __future__ import annotations

import csv
import io
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from harness import cli, registry
from harness.report.build import TIMING
from harness.run.runner import run_suite
from tests.fakestage import FAKE, calls, write_case

ROOT = Path(__file__).resolve().parents[2]


def strip_timing(csv_text: str) -> str:
    """summary.csv without timing columns (the only ones allowed to differ)."""
    rows = list(csv.reader(io.StringIO(csv_text)))
    keep = [i for i, c in enumerate(rows[0]) if not TIMING.search(c)]
    return "\n".join(",".join(r[i] for i in keep) for r in rows)


def run(*argv):
    return cli.main(["run", *map(str, argv)])


def test_suite_tables_and_resume(tmp_path, fake, capsys):
    suite = tmp_path / "cases" / "demo"
    write_case(suite, "a", "rows=2")
    b = write_case(suite, "b", "rows=1")
    res = tmp_path / "results"
    assert run(suite, "--results", res, "--jobs", 1, "--no-figures") == 0
    df = __import__("pandas").read_csv(res / "demo" / "summary.csv")
    assert list(df["case"]) == ["a", "a", "b"] and list(df["model"]) == ["m0", "m1", "m0"]
    assert list(df.columns[:6]) == ["case", "model", "stage", "seed", "status", "mode"]
    assert (df["mode"] == "quick").all()
    assert df.columns[-1] == "seconds" and (df["status"] == "ok").all()
    assert df["weights"].iloc[0] == "1:3:15"
    assert (res / "demo" / "summary.md").read_text().count("\n| a |") == 2
    assert (res / "index.html").exists()
    assert len(calls(suite)) == 2
    # unchanged inputs: nothing recomputed; the table is the same
    before = (res / "demo" / "summary.csv").read_text()
    assert run(suite, "--results", res, "--jobs", 1, "--no-figures") == 0
    assert len(calls(suite)) == 2
    assert (res / "demo" / "summary.csv").read_text() == before
    assert "2 unchanged" in capsys.readouterr().out
    # a changed case file re-runs that case only
    b.write_text(b.read_text().replace("E = 1000.0", "E = 2000.0"))
    assert run(suite, "--results", res, "--jobs", 1, "--no-figures") == 0
    assert calls(suite)[2:] == ["b 0"]
    # --full is another input: re-runs both; --force re-runs everything
    assert run(suite, "--results", res, "--jobs", 1, "--no-figures", "--full") == 0
    assert len(calls(suite)) == 5
    assert run(suite, "--results", res, "--jobs", 1, "--no-figures", "--full", "--force") == 0
    assert len(calls(suite)) == 7


def _stage_copy(tmp_path, monkeypatch, extra: str = ""):
    """A copy of tests/fakestage.py (plus ``extra``) as a module of its own, registered as
    the stage 'fake'; its path."""
    import shutil
    import uuid

    mods = tmp_path / "mods"
    mods.mkdir()
    name = f"fake_copy_{uuid.uuid4().hex[:8]}"
    src = mods / f"{name}.py"
    shutil.copy(ROOT / "tests" / "fakestage.py", src)
    src.write_text(src.read_text() + extra)
    monkeypatch.syspath_prepend(str(mods))
    monkeypatch.setattr(registry, "STAGES", registry.STAGES.with_entries({"fake": name}))
    return src


def test_code_change_reruns_only_cases_that_loaded_it(tmp_path, monkeypatch):
    """The code version of a job is the hash of the sources it loaded: editing a stage
    module re-runs its cases; editing nothing re-runs nothing."""
    src = _stage_copy(tmp_path, monkeypatch)
    suite = tmp_path / "cases" / "demo"
    write_case(suite, "a")
    res = tmp_path / "results"
    run_suite([suite], results=res, jobs=1, figures=False, progress=False)
    manifest = json.loads((res / "demo" / "a" / "result-seed0.json").read_text())
    assert str(src.resolve()) in manifest["code"] and "harness/case/reader.py" in manifest["code"]
    assert not any(
        k.startswith(("harness/commands/", "harness/report/figures/")) for k in manifest["code"]
    )
    rep = run_suite([suite], results=res, jobs=1, figures=False, progress=False)
    assert len(rep.skipped) == 1 and len(calls(suite)) == 1
    src.write_text(src.read_text() + "\n# an edit\n")
    rep = run_suite([suite], results=res, jobs=1, figures=False, progress=False)
    assert len(rep.ran) == 1 and len(calls(suite)) == 2


def test_a_stage_running_commands_in_their_own_processes_depends_on_every_source(
    tmp_path, monkeypatch
):
    """A stage with SUBPROCESS_CODE (the engines stage: pack, calibrate, engines run as
    commands) records every source file of harness/ and reference/ as its code, the commands
    included (this process never imports what they run); the report and the bench are not."""
    from harness.stages import engines

    assert engines.SUBPROCESS_CODE is True
    _stage_copy(tmp_path, monkeypatch, "\nSUBPROCESS_CODE = True\n")
    suite = tmp_path / "cases" / "demo"
    write_case(suite, "a")
    res = tmp_path / "results"
    run_suite([suite], results=res, jobs=1, figures=False, progress=False)
    code = json.loads((res / "demo" / "a" / "result-seed0.json").read_text())["code"]
    every = {
        p.relative_to(ROOT).as_posix()
        for root in ("harness", "reference")
        for p in (ROOT / root).rglob("*.py")
    }
    assert {k for k in every if not k.startswith(("harness/report/", "harness/bench/"))} <= set(
        code
    )
    assert "harness/commands/calibrate_write.py" in code
    assert not any(k.startswith(("harness/report/", "harness/bench/")) for k in code)


def test_failures_are_rows_not_tracebacks(tmp_path, fake, capsys):
    suite = tmp_path / "cases" / "demo"
    write_case(suite, "good", "rows=1")
    write_case(suite, "badinput", "fail=case")
    write_case(suite, "bug", "fail=bug")
    (suite / "broken.toml").write_text("name = 'broken'\ndim = 2\n[body\n")
    res = tmp_path / "results"
    assert run(suite, "--results", res, "--jobs", 1, "--no-figures") == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.startswith("springbench: error:")]
    assert len(lines) == 3  # one line per failure
    assert any("material.E: E must be positive (give E > 0)" in ln for ln in lines)
    assert any("broken.toml: not valid TOML" in ln for ln in lines)
    bug = [ln for ln in lines if "ZeroDivisionError" in ln][0]
    log = Path(bug.split("(traceback in ")[1].rstrip(")"))
    assert log.exists() and "Traceback" in log.read_text() and "1 / 0" in log.read_text()
    df = __import__("pandas").read_csv(res / "demo" / "summary.csv")
    assert sorted(df.loc[df.status == "error", "case"]) == ["badinput", "broken", "bug"]
    assert (df.loc[df.case == "good", "status"] == "ok").all()
    # failed jobs are not 'finished': they run again next time, finished ones do not
    n = len(calls(suite))
    assert run(suite, "--results", res, "--jobs", 1, "--no-figures") == 2
    assert sorted(calls(suite)[n:]) == ["badinput 0", "bug 0"]


def test_same_seed_identical_tables(tmp_path, fake):
    suite = tmp_path / "cases" / "demo"
    write_case(suite, "a", "rows=3", extra="[run]\nseeds = [0, 1]")
    write_case(suite, "b", "rows=2")
    res = tmp_path / "results"
    run_suite([suite], results=res, jobs=1, figures=False, progress=False)
    first = (res / "demo" / "summary.csv").read_text()
    run_suite([suite], results=res, jobs=1, figures=False, progress=False, force=True)
    second = (res / "demo" / "summary.csv").read_text()
    assert len(calls(suite)) == 6
    assert first != second  # the timing column did change ...
    assert strip_timing(first) == strip_timing(second)  # ... nothing else did
    df = __import__("pandas").read_csv(res / "demo" / "summary.csv")
    a = df[df.case == "a"]
    assert sorted(set(a.seed)) == [0, 1]
    # different seeds give different numbers (the identity is not trivial)
    assert a[a.seed == 0].G_initial.tolist() != a[a.seed == 1].G_initial.tolist()
    seeds = __import__("pandas").read_csv(res / "demo" / "seeds.csv")
    assert set(seeds.case) == {"a"} and (seeds.n_seeds == 2).all() and "G_final_std" in seeds


def test_seed_folders_and_pruning(tmp_path, fake):
    suite = tmp_path / "cases" / "demo"
    p = write_case(suite, "a", "files=1", extra="[run]\nseeds = [3, 4]")
    res = tmp_path / "results"
    run_suite([suite], results=res, jobs=1, figures=False, progress=False)
    d = res / "demo" / "a"
    assert (d / "seed3" / "trace.csv").exists() and (d / "seed4" / "volume.csv").exists()
    assert sorted(f.name for f in d.glob("result-seed*.json")) == [
        "result-seed3.json",
        "result-seed4.json",
    ]
    p.write_text(p.read_text().replace("[3, 4]", "3"))
    run_suite([suite], results=res, jobs=1, figures=False, progress=False)
    assert [f.name for f in d.glob("result-seed*.json")] == ["result-seed3.json"]
    assert (d / "trace.csv").exists()


def test_expect_columns_beside_ours(tmp_path, fake):
    suite = tmp_path / "cases" / "paper"
    write_case(
        suite,
        "fig8",
        "rows=2",
        extra='[expect]\nsource = "Deussen 1995 Fig. 8"\n'
        "values = {G_initial = 2.8, m1 = {G_final = 0.55}}",
    )
    res = tmp_path / "results"
    run_suite([suite], results=res, jobs=1, figures=False, progress=False)
    df = __import__("pandas").read_csv(res / "paper" / "summary.csv")
    cols = list(df.columns)
    i = cols.index("G_initial")
    assert cols[i + 1 : i + 3] == ["paper_G_initial", "ratio_G_initial"]
    j = cols.index("G_final")
    assert cols[j + 1 : j + 3] == ["paper_G_final", "ratio_G_final"]
    assert (df.paper_G_initial == 2.8).all()
    assert df.ratio_G_initial.tolist() == pytest.approx((df.G_initial / 2.8).tolist(), rel=1e-15)
    m1 = df[df.model == "m1"].iloc[0]
    assert m1.paper_G_final == 0.55 and m1.ratio_G_final == pytest.approx(m1.G_final / 0.55)
    assert df[df.model == "m0"].paper_G_final.isna().all()


def test_run_stages_selection_and_unknown_stage(tmp_path, fake):
    suite = tmp_path / "cases" / "demo"
    write_case(suite, "a", extra='[run]\nstages = ["fake"]')
    write_case(suite, "b", extra='[run]\nstages = ["nosuch"]')
    write_case(suite, "c", tags=["skip"])
    res = tmp_path / "results"
    rep = run_suite([suite], results=res, jobs=1, figures=False, progress=False)
    assert [r.job.case for r in rep.failed] == ["b"]
    assert "run.stages: unknown stage 'nosuch' (available: fake)" in rep.failed[0].error
    df = __import__("pandas").read_csv(res / "demo" / "summary.csv")
    assert df.set_index("case").loc["c", "status"] == "no stage applies"


def test_case_names_cannot_leave_the_results_folder(tmp_path, fake):
    suite = tmp_path / "cases" / "demo"
    write_case(suite, "../../escaped", file="up.toml")
    write_case(suite, "/tmp/absolute", file="abs.toml")
    write_case(suite, "a/b", file="sub.toml")
    write_case(suite, "Fig 8 (grouped)", file="spaces.toml")
    write_case(suite, "twin", file="twin1.toml")
    write_case(suite, "twin", file="twin2.toml")
    res = tmp_path / "out" / "results"
    rep = run_suite([suite], results=res, jobs=1, figures=False, progress=False)
    errors = {r.job.rel_file.split("/")[-1]: r.error for r in rep.failed}
    assert set(errors) == {"up.toml", "abs.toml", "sub.toml", "twin2.toml"}
    assert all("name" in e for e in errors.values())
    written = {p.resolve() for p in tmp_path.rglob("*") if p.is_file()}
    assert all(
        p.is_relative_to(res.resolve()) or p.is_relative_to(suite.resolve()) for p in written
    )
    assert (res / "demo" / "Fig_8__grouped_" / "result-seed0.json").exists()
    assert not (tmp_path / "escaped").exists() and not Path("/tmp/absolute").exists()


def test_pool_matches_serial(tmp_path, fake):
    suite = tmp_path / "cases" / "demo"
    for n in "abc":
        write_case(suite, n, "rows=2 sleep=0.3", extra="[run]\nseeds = [0, 1]" if n == "a" else "")
    r1, r2 = tmp_path / "serial", tmp_path / "pool"
    rep = run_suite([suite], results=r1, jobs=1, figures=False, progress=False)
    rep2 = run_suite([suite], results=r2, jobs=2, figures=False, progress=False)
    assert len(rep2.ran) == 4 and not rep2.failed
    assert strip_timing((r1 / "demo" / "summary.csv").read_text()) == strip_timing(
        (r2 / "demo" / "summary.csv").read_text()
    )
    assert len(rep.ran) == 4


@pytest.mark.slow
def test_dead_worker_is_an_error_row_and_others_finish(tmp_path, fake, capsys):
    suite = tmp_path / "cases" / "demo"
    write_case(suite, "a", "rows=1 sleep=0.5")
    write_case(suite, "b", "die=1")
    write_case(suite, "c", "rows=1")
    write_case(suite, "d", "rows=1")
    rep = run_suite([suite], results=tmp_path / "r", jobs=2, figures=False, progress=False)
    assert [r.job.case for r in rep.failed] == ["b"]
    assert "its worker process died" in rep.failed[0].error
    assert sorted(r.job.case for r in rep.ran) == ["a", "c", "d"]
    assert "retrying" in capsys.readouterr().err


def test_status_reaches_the_progress_bar(tmp_path, fake):
    from harness.run import runner

    seen = []

    class Spy(runner._Progress):
        def set(self, label, msg):
            seen.append((label, msg))
            super().set(label, msg)

    suite = tmp_path / "cases" / "demo"
    write_case(suite, "a", "sleep=1")
    write_case(suite, "b", "sleep=1")
    orig = runner._Progress
    runner._Progress = Spy
    try:
        run_suite([suite], results=tmp_path / "r", jobs=2, figures=False, progress=False)
    finally:
        runner._Progress = orig
    assert {lbl for lbl, m in seen if m.startswith("sleeping")} == {"a", "b"}


@pytest.mark.slow
def test_dask_local_cluster_matches_serial(tmp_path, fake):
    distributed = pytest.importorskip("distributed")
    suite = tmp_path / "cases" / "demo"
    write_case(suite, "a", "rows=2", extra="[run]\nseeds = [0, 1]")
    write_case(suite, "b", "rows=1 files=1")
    r1, r2 = tmp_path / "serial", tmp_path / "dask"
    run_suite([suite], results=r1, jobs=1, figures=False, progress=False)
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        assert (
            cli.main(
                (
                    ["run", str(suite), "--results", str(r2), "--executor", "dask"]
                    + ["--scheduler", cluster.scheduler_address, "--no-figures"]
                )
            )
            == 0
        )
    assert strip_timing((r1 / "demo" / "summary.csv").read_text()) == strip_timing(
        (r2 / "demo" / "summary.csv").read_text()
    )
    assert (r2 / "demo" / "b" / "deformed.npz").read_bytes() == (
        r1 / "demo" / "b" / "deformed.npz"
    ).read_bytes()


@pytest.mark.slow
def test_dask_dead_worker_is_an_error_row(tmp_path, fake):
    """A job that kills its Dask worker each time becomes an error row; the others finish."""
    distributed = pytest.importorskip("distributed")
    import dask

    suite = tmp_path / "cases" / "demo"
    write_case(suite, "a", "rows=1")
    write_case(suite, "b", "die=1")
    with (
        dask.config.set({"distributed.scheduler.allowed-failures": 1}),
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
        ) as cluster,
    ):
        rep = run_suite(
            [suite],
            results=tmp_path / "r",
            executor="dask",
            scheduler=cluster.scheduler_address,
            figures=False,
            progress=False,
        )
    assert [r.job.case for r in rep.failed] == ["b"]
    assert "Dask worker died" in rep.failed[0].error
    df = __import__("pandas").read_csv(tmp_path / "r" / "demo" / "summary.csv")
    assert set(df[df.status == "ok"]["case"]) == {"a"}


def test_unreachable_scheduler_is_one_line(tmp_path, fake, capsys, monkeypatch):
    pytest.importorskip("distributed")
    from harness.run import runner

    monkeypatch.setattr(runner, "DASK_CONNECT_TIMEOUT", "1s")
    suite = tmp_path / "cases" / "demo"
    write_case(suite, "a")
    code = cli.main(
        (
            ["run", str(suite), "--results", str(tmp_path / "r")]
            + ["--executor", "dask", "--scheduler", "tcp://127.0.0.1:9"]
        )
    )
    err = capsys.readouterr().err
    assert (
        code == 2
        and "--scheduler: cannot connect to the Dask scheduler" in err
        and "Traceback" not in err
    )


@pytest.mark.slow
def test_sigkill_loses_no_finished_case(tmp_path):
    suite = tmp_path / "cases" / "demo"
    write_case(suite, "a_fast", "rows=1")
    write_case(suite, "b_slow", "sleep=60")
    res = tmp_path / "results"
    script = (
        f"import sys; sys.path.insert(0, {str(ROOT)!r}); import harness.registry as r; "
        f"r.STAGES = r.STAGES.with_entries({{'fake': {FAKE!r}}}); from harness.cli import main; "
        f"sys.exit(main(['run', {str(suite)!r}, '--results', {str(res)!r}, '--jobs', '1']))"
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", script], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    done = res / "demo" / "a_fast" / "result-seed0.json"
    t0 = time.monotonic()
    try:
        while not (calls(suite)[1:] and done.exists()):
            assert proc.poll() is None and time.monotonic() - t0 < 60, "first case did not finish"
            time.sleep(0.05)
        time.sleep(0.2)  # b_slow is now running
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    assert json.loads(done.read_text())["status"] == "ok"
    assert not (res / "demo" / "b_slow" / "result-seed0.json").exists()
    # harness.outputs' temp files
    assert not list(res.rglob(".*.tmp")) and not list(res.rglob(".*.part.*"))
    (suite / "b_slow.toml").write_text(
        (suite / "b_slow.toml").read_text().replace("sleep=60", "sleep=0")
    )
    n = len(calls(suite))
    proc = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, proc.stderr
    assert calls(suite)[n:] == ["b_slow 0"]  # a_fast was skipped, not recomputed
    assert "1 ran, 1 unchanged" in proc.stdout


@pytest.mark.slow
def test_ctrl_c_stops_workers_quietly(tmp_path):
    """SIGINT to the whole process group (what Ctrl-C does): exit 130, one line, no worker
    tracebacks, no process left behind, finished cases kept."""
    suite = tmp_path / "cases" / "demo"
    write_case(suite, "a_fast", "rows=1")
    for n in ("b_slow", "c_slow"):
        write_case(suite, n, "sleep=60")
    res = tmp_path / "results"
    script = (
        f"import sys; sys.path.insert(0, {str(ROOT)!r}); import harness.registry as r; "
        f"r.STAGES = r.STAGES.with_entries({{'fake': {FAKE!r}}}); from harness.cli import main\n"
        f"if __name__ == '__main__':\n"
        f"    sys.exit(main(['run', {str(suite)!r}, '--results', {str(res)!r}, '--jobs', '2']))\n"
    )
    (tmp_path / "go.py").write_text(script)
    proc = subprocess.Popen(
        [sys.executable, str(tmp_path / "go.py")],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    t0 = time.monotonic()
    while not (len(calls(suite)) >= 3 and (res / "demo" / "a_fast" / "result-seed0.json").exists()):
        assert proc.poll() is None and time.monotonic() - t0 < 90, "jobs did not start"
        time.sleep(0.1)
    time.sleep(0.5)
    os.killpg(proc.pid, signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130
    assert "Traceback" not in err and err.strip().splitlines()[-1].startswith(
        "springbench: interrupted"
    )
    deadline = time.monotonic() + 20
    while True:  # every worker of the group is gone (zombies are reaped within seconds)
        try:
            os.killpg(proc.pid, 0)
        except ProcessLookupError:
            break
        assert time.monotonic() < deadline, "processes of the run are still alive"
        time.sleep(0.2)
    assert json.loads((res / "demo" / "a_fast" / "result-seed0.json").read_text())["status"] == "ok"
