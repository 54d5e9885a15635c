"""springbench bench shapes: does ``springbench calibrate`` keep its promise on shapes a user
brings? Eight gmsh bodies no test has (harness/bench/shapes_bodies.py: two ellipsoids, a
torus, a plate with a hole, a hollow ball, a wedge, a T-beam, a frustum; 0.7-3k
tetrahedra; nu 0.3, 0.45 or 0.49), each calibrated with calibrate's defaults (its own
clamp and load regions, held-out loads and reference) in its own process with an empty
reference cache, then once more with both cores busy (two spinning processes beside it).

Read from calibrate's own JSON: the choice, the exported model's held-out error
(``G_heldout_mean``) beside the best rule's on the same loads (``best_rule_heldout``, the
rules calibrate computed itself), the reference's own error on the held-out loads, its
status, and a digest of the exported model (every array an engine reads: positions,
masses, springs, stiffness, damping, the volume or kn terms).

Then the same mesh mirrored across the mid-plane of its longest axis is calibrated once
(``*_mirror`` columns): the held-out loads are then held at the other end. Which rule wins
the held-out loads can belong to one end of a body (docs/calibrate.md, "What to trust"):
the mirror shows how much of a ratio is that end's.

Acceptance, per body: ratio = G_heldout_mean / best rule's <= ACCEPT_RATIO, the
reference's held-out error <= ACCEPT_REF, and the same digest twice (the export does not
depend on the machine's load). Columns: shape, n_tets, nu, choice, rule (the exported
row's start rule), G_heldout_mean, best_rule, best_rule_heldout, ratio, reference_error,
reference_error_heldout, status, seconds, seconds_busy, same_export, ok,
G_heldout_mean_mirror, best_rule_mirror, best_rule_heldout_mirror, ratio_mirror.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from functools import partial
from pathlib import Path

import numpy as np
import pandas as pd

from harness.bench.resume import kept
from harness.bench.shapes_bodies import SHAPES, make_shape, mirror
from harness.progress import steps
from harness.provenance import version

E, RHO = 1e5, 1000.0
ACCEPT_RATIO, ACCEPT_REF = 1.05, 0.01
# the JSON's model: what an engine reads (the scores and the stop messages are not the model)
MODEL_KEYS = (
    "particle_q particle_mass spring_indices spring_rest_length spring_stiffness "
    "spring_damping volume_indices volume_rest volume_stiffness node_volume_nodes "
    "node_volume_rest node_volume_stiffness node_volume_elements node_volume_element_rest "
    "kn_nodes kn_stiffness choice"
).split()


def digest(data: dict) -> str:
    """sha256 of the export's model arrays (MODEL_KEYS, in that order, as float64/int64)."""
    h = hashlib.sha256()
    for key in MODEL_KEYS:
        if key in data and data[key] is not None:
            v = data[key]
            h.update(key.encode())
            h.update(v.encode() if isinstance(v, str) else np.asarray(v).tobytes())
    return h.hexdigest()[:16]


@contextmanager
def busy(n: int = 2):
    """n processes spinning on the CPU for as long as the block runs."""
    spin = [sys.executable, "-c", "while True: pass"]
    procs = [subprocess.Popen(spin) for _ in range(n)]
    try:
        yield procs
    finally:
        for p in procs:
            p.kill()
            p.wait()


def calibrate(mesh: Path, out: Path, nu: float, cache: Path) -> tuple[dict, float]:
    """(calibrate's JSON, wall seconds) of one default calibration in its own process."""
    cmd = [sys.executable, "-m", "harness", "calibrate", str(mesh), "--E", repr(E)]
    cmd += ["--nu", repr(nu), "--density", repr(RHO), "--quiet", "--out", str(out)]
    env = dict(os.environ, SPRINGBENCH_CACHE=str(cache))
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    seconds = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError((proc.stderr.strip().splitlines() or ["failed"])[-1])
    return json.loads(out.with_suffix(".json").read_text()), seconds


def study_one(shape, folder: Path) -> dict:
    """One shape's row: calibrated on an idle and on a busy machine, then mirrored."""
    mesh = folder / f"{shape.name}.vtu"
    n_tets = make_shape(shape, mesh)
    row = dict(shape=shape.name, n_tets=n_tets, nu=shape.nu, note="")
    try:
        data, row["seconds"] = calibrate(mesh, folder / "a.vtu", shape.nu, folder / "ca")
        with busy():
            again, row["seconds_busy"] = calibrate(mesh, folder / "b.vtu", shape.nu, folder / "cb")
        mirror(mesh, folder / "mirror.vtu")
        other, _ = calibrate(folder / "mirror.vtu", folder / "m.vtu", shape.nu, folder / "cm")
    except RuntimeError as exc:  # a failed run: its row says why, the study goes on
        return dict(row, note=str(exc), ok=False)
    best = data.get("best_rule_heldout") or {}
    row.update(
        choice=data.get("choice"),
        G_heldout_mean=data.get("G_heldout_mean"),
        best_rule=best.get("rule"),
        best_rule_heldout=best.get("G_heldout_mean"),
        reference_error=data.get("reference_error"),
        reference_error_heldout=data.get("reference_error_heldout"),
        status=data.get("status"),
        same_export=digest(data) == digest(again),
    )
    ratio = (row["G_heldout_mean"] or np.nan) / (row["best_rule_heldout"] or np.nan)
    ref = row["reference_error_heldout"]
    row["ratio"] = float(ratio)
    row.update(_mirrored(other))
    row["ok"] = bool(
        ratio <= ACCEPT_RATIO and ref is not None and ref <= ACCEPT_REF and row["same_export"]
    )
    return row


def _mirrored(data: dict) -> dict:
    """The mirror's columns (module doc): its export's held-out error beside its own best
    rule's, and their ratio."""
    best = data.get("best_rule_heldout") or {}
    held, rule = data.get("G_heldout_mean"), best.get("G_heldout_mean")
    return dict(
        G_heldout_mean_mirror=held,
        best_rule_mirror=best.get("rule"),
        best_rule_heldout_mirror=rule,
        ratio_mirror=float((held or np.nan) / (rule or np.nan)),
    )


def verdict(df: pd.DataFrame) -> str:
    """One line: how many shapes meet each acceptance."""
    n = len(df)
    r = int((df.ratio <= ACCEPT_RATIO).sum())
    f = int((df.reference_error_heldout <= ACCEPT_REF).sum())
    s = int(df.same_export.fillna(False).astype(bool).sum())
    m = int((df.get("ratio_mirror", pd.Series(dtype=float)) <= ACCEPT_RATIO).sum())
    return (
        f"{r} of {n} shapes within {ACCEPT_RATIO:g}x the best rule (worst "
        f"{df.ratio.max():.3g}; mirrored: {m}), reference error <= {ACCEPT_REF:.0%} on {f}, "
        f"the same export on a busy machine on {s}"
    )


def run(quick: bool = False, work: Path | None = None) -> pd.DataFrame:
    """Every shape's row; ``work``: the folder that keeps each finished row
    (harness/bench/resume.py)."""
    shapes = SHAPES[1:2] if quick else SHAPES
    rows = []
    with tempfile.TemporaryDirectory(prefix="springbench-shapes-") as tmp:
        for shape in steps(shapes, "bench shapes", "shape"):
            folder = Path(tmp) / shape.name
            folder.mkdir()
            inputs = dict(shape=shape.name, nu=shape.nu, n_tets=shape.n_tets, gmsh=version("gmsh"))
            one = partial(study_one, shape, folder)
            rows.append(kept(work, shape.name, inputs, one, finished=lambda r: not r["note"]))
    df = pd.DataFrame(rows)
    print(verdict(df))
    return df
