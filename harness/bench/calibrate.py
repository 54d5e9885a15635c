"""springbench bench calibrate: ``springbench calibrate`` end to end (mesh check, FEM
reference, rules, validation, fit, held-out scoring, export) on gmsh cylinders of about
1k, 10k, 50k and 200k tetrahedra and on a gmsh L-bracket of about 30k (the held-out study's
bracket; E = 1e5 Pa, nu = 0.45, density 1000, calibrate's default regions), each beside the
rule alone on the same mesh (``--method rule --rule vangelder``: the reference and the
rules' statics, no fit), each run in its own process (so its peak memory is its own)
with an empty reference cache. Needs gmsh (``pip install -e ".[bench]"``); without it
the benchmark writes one row saying so.

Targets (:func:`verdict`): every mesh of 9k tets and more fits (the choice is not a rule), the
fit's time at most the rule alone's (fit_ratio <= 1), peak memory <= 4 GB at 50k tets and
<= 12 GB at 200k; the bracket's held-out error <= 0.8x the best rule's in at most twice its
rule-only time (ratio_to_rule <= 2). Times are ratios within the run, so a busy machine
slows both sides alike.
Columns: body, mesh size, seconds (the default calibration) and rule_seconds (the rule alone),
peak memory of each run (peak_gb, rule_peak_gb: its largest process), the choice the
validation made and the level of the fit's counts it ran (fit_level, with its predicted
work and budget in Gflop: harness/optimize/select_counts.py; validation_skipped: always
empty, the validation always runs), the start
rule's G_fit_score, the exported model's G_heldout_mean beside the best
rule's in hindsight, the reference's own error on the fitted and held-out loads, and the
ratios of seconds to the 1k mesh's and to the rule alone, and fit_ratio: the fit's time
(seconds - rule_seconds) over the rule alone's (target: at most 1). The reference's error: meshes
of up to a quarter of the adaptive cap's dofs (reference/adaptive/adapt.py TARGET_DOFS: 150k
dofs, ~30k tets) are refined adaptively; larger ones are estimated from
coarse levels of their body (reference/adaptive/coarse.py, their own system solved in the coarse
levels' subspaces), the solve on the mesh itself by the two-level method
(reference/solvers/twolevel.py).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from functools import partial
from pathlib import Path

import numpy as np
import pandas as pd

from harness.bench.heldout_bodies import BODIES, make_body
from harness.bench.resume import kept
from harness.progress import steps
from harness.provenance import version

FULL = (1_000, 10_000, 50_000, 200_000)
QUICK = (1_000, 5_000)
BRACKET_FULL, BRACKET_QUICK = 30_000, 2_000  # the L-bracket's size
RADIUS, LENGTH = 0.1, 0.5
NU = 0.45  # every mesh's Poisson ratio (E = 1e5 Pa)
RULE = "vangelder"  # the rule-only run beside each calibration: --method rule --rule RULE


def cylinder(path: Path, n_tets: int) -> int:
    """A gmsh cylinder with about n_tets tetrahedra (one size correction); returns the count."""
    import gmsh
    import meshio

    h = (8.5 * np.pi * RADIUS**2 * LENGTH / n_tets) ** (1 / 3)
    for _ in range(2):
        gmsh.initialize(["-noenv"])
        # gmsh's start resets it: a closed pipe would kill us
        signal.signal(signal.SIGPIPE, signal.SIG_IGN)
        try:
            gmsh.option.setNumber("General.Terminal", 0)
            gmsh.option.setNumber("General.NumThreads", 1)
            gmsh.option.setNumber("Mesh.RandomSeed", 0)
            gmsh.model.occ.addCylinder(0, 0, 0, LENGTH, 0, 0, RADIUS)
            gmsh.model.occ.synchronize()
            gmsh.option.setNumber("Mesh.MeshSizeMax", h)
            gmsh.option.setNumber("Mesh.MeshSizeMin", h)
            gmsh.model.mesh.generate(3)
            tags, coords, _ = gmsh.model.mesh.getNodes()
            _, nodes = gmsh.model.mesh.getElementsByType(4)
        finally:
            gmsh.finalize()
        tets = len(nodes) // 4
        h *= (tets / n_tets) ** (1 / 3)
    index = np.zeros(int(tags.max()) + 1, int)
    index[tags.astype(int)] = np.arange(len(tags))
    cells = index[nodes.astype(int)].reshape(-1, 4)
    used = np.unique(cells)
    remap = np.full(len(tags), -1)
    remap[used] = np.arange(len(used))
    meshio.write(path, meshio.Mesh(coords.reshape(-1, 3)[used], [("tetra", remap[cells])]))
    return tets


def measured(cmd: list, env: dict, logs: tuple) -> tuple[float, subprocess.CompletedProcess, float]:
    """(seconds, process, peak GB) of ``cmd`` run to its end, its output in ``logs`` (stdout,
    stderr files); the peak is the largest resident set of the process or of any child it
    waited for (its fit workers): os.wait4's rusage of this run alone (at least this
    process's own: Linux hands a spawned process its parent's high-water mark)."""
    t0 = time.perf_counter()
    with open(logs[0], "w") as fo, open(logs[1], "w") as fe:
        child = subprocess.Popen(cmd, stdout=fo, stderr=fe, text=True, env=env)
        _, status, usage = os.wait4(child.pid, 0)
    seconds = time.perf_counter() - t0
    code = os.waitstatus_to_exitcode(status)
    out, err = (Path(f).read_text() for f in logs)
    return seconds, subprocess.CompletedProcess(cmd, code, out, err), usage.ru_maxrss / 1e6


def _calibrate(mesh: Path, out: Path, *extra) -> tuple[float, subprocess.CompletedProcess, float]:
    """:func:`measured` of one cold ``springbench calibrate``: its own process and an empty
    reference cache."""
    cmd = [sys.executable, "-m", "harness", "calibrate", str(mesh), "--E", "1e5", "--nu", repr(NU)]
    cmd += ["--out", str(out), *extra]
    env = dict(os.environ, SPRINGBENCH_CACHE=str(out.parent / f"cache-{out.stem}"))
    return measured(cmd, env, tuple(out.with_name(f"{out.stem}.{s}.txt") for s in ("out", "err")))


def _one(mesh: Path, out: Path) -> dict:
    """The rule alone (``--method rule``), then the default calibration, on one mesh."""
    rule_out = out.with_name(out.stem + "-rule.vtu")
    rule_seconds, rule, rule_peak = _calibrate(mesh, rule_out, "--method", "rule", "--rule", RULE)
    seconds, proc, peak = _calibrate(mesh, out)
    failed = next((p for p in (rule, proc) if p.returncode != 0), None)
    if failed is not None:
        return dict(
            seconds=seconds,
            rule_seconds=rule_seconds,
            peak_gb=peak,
            rule_peak_gb=rule_peak,
            note=(failed.stderr.strip().splitlines() or ["failed"])[-1],
        )
    df = pd.read_csv(out.with_suffix(".csv"))
    data = json.loads(out.with_suffix(".json").read_text())
    fit = df[df.exported].iloc[0]
    rules = df[df.optimizer == "none"]
    best = rules.loc[rules.G_heldout_mean.idxmin()]  # the best rule in hindsight
    return dict(
        seconds=seconds,
        rule_seconds=rule_seconds,
        peak_gb=peak,
        rule_peak_gb=rule_peak,
        n_nodes=int(fit.n_nodes),
        n_springs=int(fit.n_springs),
        choice=data.get("choice"),
        fit_level=(data.get("fit_counts") or {}).get("level"),
        fit_work_gflop=(data.get("fit_counts") or {}).get("work_gflop"),
        fit_budget_gflop=(data.get("fit_counts") or {}).get("budget_gflop"),
        validation_skipped=data.get("validation_skipped"),
        start_rule=fit.stiffness,
        G_fit_score=float(fit.G_fit_score),
        G_heldout_mean=data.get("G_heldout_mean"),
        best_rule=best.stiffness,
        G_heldout_mean_best_rule=float(best.G_heldout_mean),
        reference_error_fitted=data.get("reference_error_fitted"),
        reference_error_heldout=data.get("reference_error_heldout"),
        dt_stable=data.get("dt_stable"),
        note=f"fits by iteration counts; stop {fit.get('opt_stop', '')}",
    )


def _sized(body: str, n: int, tmp: Path) -> dict:
    """The row of one body meshed to about n tets."""
    mesh = tmp / f"{body}{n}.{'vtu' if body == 'cylinder' else 'msh'}"
    tets = cylinder(mesh, n) if body == "cylinder" else make_body(BODIES[0], mesh, n)
    return dict(
        task="calibrate", body=body, n_tets=tets, **_one(mesh, tmp / f"model-{body}{n}.vtu")
    )


def run(quick: bool = False, work: Path | None = None) -> pd.DataFrame:
    """The rows of every mesh; ``work``: the folder that keeps each mesh's finished row
    (harness/bench/resume.py)."""
    try:
        import gmsh  # noqa: F401
    except ImportError:
        return pd.DataFrame(
            [
                dict(
                    task="calibrate",
                    note="skipped: gmsh not installed (pip install 'springbench[bench]')",
                )
            ]
        )
    sizes = [("cylinder", n) for n in (QUICK if quick else FULL)]
    sizes.append(("bracket", BRACKET_QUICK if quick else BRACKET_FULL))
    rows = []
    with tempfile.TemporaryDirectory(prefix="springbench-bench-") as tmp:
        for body, n in steps(sizes, "bench calibrate", "mesh"):
            inputs = dict(body=body, n=n, nu=NU, gmsh=version("gmsh"))
            one = partial(_sized, body, n, Path(tmp))
            rows.append(kept(work, f"{body}{n}", inputs, one, finished=lambda r: "choice" in r))
    df = pd.DataFrame(rows)
    df["ratio"] = df["seconds"] / df["seconds"].iloc[0]
    df["ratio_to_rule"] = df["seconds"] / df["rule_seconds"]
    # the fit's time: everything beyond the rule-only path (each run solves its own reference)
    df["fit_ratio"] = (df["seconds"] - df["rule_seconds"]) / df["rule_seconds"]
    print(verdict(df))
    return df


def _misses(row) -> list[str]:
    """What one row misses of its targets (the module's docstring)."""
    n, misses = row.n_tets, []
    if not isinstance(row.choice, str):
        return [f"{row.body} {n} tets: {row.get('note') or 'no export'}"]
    rule = row.choice == "rule"
    if n >= 9_000 and rule:
        misses.append(f"{row.body} {n} tets exported the rule {row.start_rule}")
    if row.body == "cylinder" and n >= 9_000 and not rule and row.fit_ratio > 1:
        misses.append(f"{row.body} {n} tets: fit {row.fit_ratio:.2f}x the rule-only time")
    cap = 12.0 if n >= 100_000 else 4.0 if n >= 40_000 else None
    if cap is not None and row.peak_gb > cap:
        misses.append(f"{row.body} {n} tets: peak {row.peak_gb:.1f} GB > {cap:g}")
    if row.body == "bracket":
        held = row.G_heldout_mean / row.G_heldout_mean_best_rule
        if held > 0.8 or row.ratio_to_rule > 2:
            misses.append(
                f"bracket {n} tets: held-out {held:.2f}x the best rule (<= 0.8) in "
                f"{row.ratio_to_rule:.2f}x the rule-only time (<= 2)"
            )
    return misses


def verdict(df: pd.DataFrame) -> str:
    """PASS when every row meets its targets (the module's docstring), else what each misses."""
    misses = [m for _, row in df.iterrows() for m in _misses(row)]
    fits = ", ".join(f"{r.n_tets}: {r.choice}" for r in df.itertuples())
    return f"{'FAIL: ' + '; '.join(misses) if misses else 'PASS'} ({fits})"
