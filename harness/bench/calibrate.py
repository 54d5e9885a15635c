"""springbench bench calibrate: ``springbench calibrate`` end to end (mesh check, FEM
reference, rules, fit, held-out scoring, export) on gmsh cylinders of about 1k, 10k and
50k tetrahedra (E = 1e5 Pa, nu = 0.45, density 1000), each in its own process (so its
peak memory is its own) with an empty reference cache. Needs gmsh (``pip install -e
".[bench]"``); without it the benchmark writes one row saying so.

Targets: the 50k-tet mesh calibrated in <= 3 min with <= 4 GB, a 200k-tet mesh in <= 10 min with <= 12 GB (2 cores).
Columns: mesh size, seconds, peak memory, G_norm before (the start rule, the best on the
fitted loads) and after the fit, G_heldout of both, the reference's own error and the
ratio of seconds to the 1k mesh's (the baseline run in the same benchmark). The
reference's error: the 1k and 10k meshes are refined adaptively (up to 200k dofs); the
50k mesh (214k P2 dofs) is too large to refine and is estimated from coarse levels of
its body (reference/coarse.py: ~1/30 and ~1/10 of its dofs, its own system solved in
their subspaces), so its row has an estimate too. The solve on the mesh itself (203k free
P2 dofs, three held-out loads) takes the two-level method (reference/twolevel.py: 23 CG
iterations, ~30 s CPU; pyamg's AMG took ~190 s CPU, ~6 min on the loaded machine). The
50k calibration by stage, before (cProfile wall seconds of a run that got 56 % of a CPU:
328 s CPU in all) -> after (cProfile CPU seconds: 142 s CPU in all, 162 s wall at 97 %):
reference 365 -> 56 (the mesh's solve 276 -> 29, coarse levels 71 -> 18), the rules'
statics (5 networks; the mesh surface read 44 times, the symbolic factorisation 10 times)
125 -> 23, spring/mass build (Lloyd's per-element least squares batched) 12 -> 4, the fit
63 -> 61 (its 60 s wall budget); peak memory 2.7 -> 1.9 GB.
"""

from __future__ import annotations

import json
import resource
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

FULL = (1_000, 10_000, 50_000, 200_000)
QUICK = (1_000, 5_000)
RADIUS, LENGTH = 0.1, 0.5
BUDGET = 60.0                 # the optimiser's wall-time budget (calibrate's default)
RULE = "vangelder"            # the rule-only run beside each calibration: --method rule --rule RULE


def cylinder(path: Path, n_tets: int) -> int:
    """A gmsh cylinder with about n_tets tetrahedra (one size correction); returns the count."""
    import gmsh
    import meshio
    h = (8.5 * np.pi * RADIUS ** 2 * LENGTH / n_tets) ** (1 / 3)
    for _ in range(2):
        gmsh.initialize(["-noenv"])
        signal.signal(signal.SIGPIPE, signal.SIG_IGN)   # gmsh's start resets it: a closed pipe would kill us
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


def _calibrate(mesh: Path, out: Path, *extra) -> tuple[float, subprocess.CompletedProcess]:
    """(seconds, process) of one cold ``springbench calibrate``: its own process and an
    empty reference cache."""
    import os
    cmd = [sys.executable, "-m", "harness", "calibrate", str(mesh), "--E", "1e5", "--nu", "0.45",
           "--budget", str(BUDGET), "--out", str(out), *extra]
    env = dict(os.environ, SPRINGBENCH_CACHE=str(out.parent / f"cache-{out.stem}"))
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    return time.perf_counter() - t0, proc


def _one(mesh: Path, out: Path) -> dict:
    """The rule alone (``--method rule``), then the default calibration, on one mesh."""
    rule_out = out.with_name(out.stem + "-rule.vtu")
    rule_seconds, rule = _calibrate(mesh, rule_out, "--method", "rule", "--rule", RULE)
    seconds, proc = _calibrate(mesh, out)
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1e6      # GB: the largest run so far
    failed = next((p for p in (rule, proc) if p.returncode != 0), None)
    if failed is not None:
        return dict(seconds=seconds, rule_seconds=rule_seconds, peak_gb=peak,
                    note=(failed.stderr.strip().splitlines() or ["failed"])[-1])
    df = pd.read_csv(out.with_suffix(".csv"))
    data = json.loads(out.with_suffix(".json").read_text())
    fit = df[df.exported].iloc[0]
    rules = df[df.optimizer == "none"]
    best = rules.loc[rules.G_heldout_mean.idxmin()]           # the best rule in hindsight
    return dict(seconds=seconds, rule_seconds=rule_seconds, peak_gb=peak, n_nodes=int(fit.n_nodes),
                n_springs=int(fit.n_springs), choice=data.get("choice"),
                validation_skipped=data.get("validation_skipped"), start_rule=fit.stiffness,
                G_fit_score=float(fit.G_fit_score), G_heldout_mean=data.get("G_heldout_mean"),
                best_rule=best.stiffness, G_heldout_mean_best_rule=float(best.G_heldout_mean),
                reference_error_fitted=data.get("reference_error_fitted"),
                reference_error_heldout=data.get("reference_error_heldout"),
                dt_stable=data.get("dt_stable"), note=f"lbfgs {BUDGET:g} s budget; stop {fit.get('opt_stop', '')}")


def run(quick: bool = False) -> pd.DataFrame:
    try:
        import gmsh  # noqa: F401
    except ImportError:
        return pd.DataFrame([dict(task="calibrate", note="skipped: gmsh not installed (pip install 'springbench[bench]')")])
    rows = []
    with tempfile.TemporaryDirectory(prefix="springbench-bench-") as tmp:
        tmp = Path(tmp)
        for n in (QUICK if quick else FULL):
            mesh = tmp / f"cylinder{n}.vtu"
            tets = cylinder(mesh, n)
            rows.append(dict(task="calibrate", n_tets=tets, **_one(mesh, tmp / f"model{n}.vtu")))
    df = pd.DataFrame(rows)
    df["ratio"] = df["seconds"] / df["seconds"].iloc[0]
    df["ratio_to_rule"] = df["seconds"] / df["rule_seconds"]
    return df
