"""springbench bench engines: how far is each engine's deformable body from linear elasticity?

Bodies (gmsh .msh with physical surfaces ``clamp`` and ``load``): a box beam 0.5 x 0.1 x
0.1 m clamped at one end and loaded at the other, the elbow (a 120-degree torus sector, a
curved part) and the tapered bar bolted through its hole (a holed part) of
``springbench bench heldout``; each at two resolutions (about 400 and 1,200 tetrahedra).
E = 1e5 Pa, density 1000 kg/m^3, nu = 0.3, 0.45 and 0.49 (quick: the beam, coarse, nu 0.3).

Per (body, resolution, nu): ``springbench pack`` (``--clamp clamp --load-region load``;
the FEM is the reference's P2 with its error estimate) and, on its held-out loads (sag,
tip, tip2, torsion, bridge; peak strain about 1e-3):

- ``newton-tets`` and ``mujoco-flex``: the engine's own tetrahedral model from E and nu;
- ``newton-springs`` running springbench's exports of the same mesh: the best stiffness
  rule (``calibrate --method rule``) and the calibrated model (``calibrate``, ``--budget``
  BUDGET s), each run by Newton at its ``dt_safe`` with its ``settle_damping``.

Every answer is scored against the pack's FEM (``score --displacements``: G_norm = RMS
displacement error / RMS FEM displacement over the nodes). Rows: one per (body, n_tets, nu,
engine, model, load) with G_norm, max_error, G_ref (the FEM's own error as a G_norm), the
engine's status (settled / not-settled / diverged / unsupported), steps and wall seconds
to equilibrium, and a ``mean`` row per (body, n_tets, nu, engine, model) (G_norm: the mean
over the loads; wall_s: the sum). A run that fails leaves rows whose note says why.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from harness.bench.heldout import BODIES, Body, _near, make_body
from harness.progress import steps

E, RHO = 1e5, 1000.0
NUS = (0.3, 0.45, 0.49)
SIZES = {"coarse": 400, "fine": 1200}
BUDGET = 15.0
HELD = ("sag", "tip", "tip2", "torsion", "bridge")
COLUMNS = ["body", "resolution", "n_tets", "nu", "engine", "model", "load", "G_norm", "max_error", "G_ref",
           "status", "steps", "wall_s", "note"]


def _beam(occ):
    return occ.addBox(0, 0, 0, 0.5, 0.1, 0.1)


BEAM = Body("beam", _beam, _near(0, 0.05, 0.05), _near(0.5, 0.05, 0.05), ((0, -1, 0), (0, 0, -1)), (0, -1, 0))
ENGINE_BODIES = (BEAM, next(b for b in BODIES if b.name == "elbow"), next(b for b in BODIES if b.name == "taper"))


def _cli(*argv) -> int:
    """One springbench command in its own process (as a user runs it), its output kept
    out of the table's; its exit status."""
    return subprocess.run([sys.executable, "-m", "harness", *map(str, argv)], capture_output=True).returncode


def _material(nu):
    return ("--E", repr(E), "--nu", repr(nu), "--density", repr(RHO))


def _engine_rows(pack, pack_dir, engine, folder, model_json=None):
    """(answers' rows per held-out load) of one engine run through the CLI and scored."""
    from harness.export.pack_score import read_displacements, score_fields
    folder.mkdir(parents=True, exist_ok=True)
    out, log = folder / f"{engine}.npz", folder / f"{engine}.csv"
    extra = ("--model", model_json) if model_json else ()
    code = _cli("engines", "run", engine, pack_dir, "--loads", ",".join(HELD), "--out", out, "--log", log,
                *extra)
    if not out.exists():
        raise RuntimeError(f"engines run {engine}: exit {code}")
    run = pd.read_csv(log).set_index("load")
    fields = read_displacements(out, pack)
    scored = {r["load"]: r for r in score_fields(pack, fields, HELD) if r["load"] != "total"}
    rows = []
    for name in HELD:
        finite = bool(np.all(np.isfinite(fields[name])))
        s = scored[name]
        rows.append(dict(load=name, G_norm=s["G_norm"] if finite else math.nan,
                         max_error=s["max_error"] if finite else math.nan, G_ref=s["G_ref"],
                         status=run.status[name], steps=int(run.steps[name]), wall_s=float(run.wall_s[name]),
                         note="" if pd.isna(run.note[name]) else str(run.note[name])))
    return rows


def study_one(body: Body, resolution: str, mesh: Path, n_tets: int, nu: float, folder: Path,
              budget: float = BUDGET) -> list[dict]:
    """The rows of one (body, resolution, nu)."""
    from harness.export.pack import read_pack
    folder.mkdir(parents=True, exist_ok=True)
    base = dict(body=body.name, resolution=resolution, n_tets=n_tets, nu=nu)
    groups = ("--clamp", "clamp", "--load-region", "load")
    if _cli("pack", mesh, *_material(nu), *groups, "--out", folder / "pack") != 0:
        return [dict(base, engine="-", model="-", load="-", note="springbench pack failed")]
    pack = read_pack(folder / "pack")
    runs = [("newton-tets", "own (E, nu)", None), ("mujoco-flex", "own (E, nu)", None)]
    for label, extra in (("rule", ("--method", "rule")), ("calibrated", ("--budget", repr(budget)))):
        out = folder / f"{label}.vtu"
        code = _cli("calibrate", mesh, *_material(nu), *groups, "--out", out, *extra)
        if code != 0 or not out.with_suffix(".json").exists():
            runs.append(("newton-springs", label, RuntimeError(f"calibrate {label}: exit {code}")))
            continue
        data = json.loads(out.with_suffix(".json").read_text())
        row = pd.read_csv(out.with_suffix(".csv")).query("exported").iloc[0]
        choice = data.get("choice") if label == "calibrated" else None
        what = f"springbench {label}: " + (choice if choice and choice != "rule" else f"rule {row.stiffness}")
        runs.append(("newton-springs", what, out.with_suffix(".json")))
    rows = []
    for engine, model, source in runs:
        try:
            if isinstance(source, Exception):
                raise source
            sub = folder / (model.split(":")[0].split()[-1] if engine == "newton-springs" else "own")
            got = _engine_rows(pack, folder / "pack", engine, sub, source)
        except (RuntimeError, ValueError, OSError) as exc:
            got = [dict(load=name, status="failed", note=str(exc)) for name in HELD]
        rows += [dict(base, engine=engine, model=model, **r) for r in got]
    return rows


def summarise(df: pd.DataFrame) -> pd.DataFrame:
    """The per-load rows plus a ``mean`` row per (body, resolution, nu, engine, model)."""
    keys = ["body", "resolution", "n_tets", "nu", "engine", "model"]
    out = []
    for key, g in df.groupby(keys, sort=False, dropna=False):
        out.append(g)
        settled = bool((g.status == "settled").all())
        out.append(pd.DataFrame([dict(zip(keys, key), load="mean", G_norm=float(g.G_norm.mean()),
                                      max_error=float(g.max_error.max()), G_ref=float(g.G_ref.max()),
                                      status="settled" if settled else "see loads",
                                      steps=float(g.steps.sum()), wall_s=float(g.wall_s.sum()), note="")]))
    return pd.concat(out, ignore_index=True).reindex(columns=COLUMNS)


def summary_table(df: pd.DataFrame) -> pd.DataFrame:
    """Mean G_norm per (body, n_tets, nu) row and (engine: model) column."""
    m = df[df.load == "mean"].copy()
    m["who"] = m.engine + ": " + m.model.str.replace(r"springbench (\w+):.*", r"springbench \1", regex=True)
    return m.pivot_table(index=["body", "n_tets", "nu"], columns="who", values="G_norm", sort=False).reset_index()


def run(quick: bool = False) -> pd.DataFrame:
    try:
        import gmsh  # noqa: F401
    except ImportError:
        return pd.DataFrame([dict(body="all", note="skipped: gmsh not installed (pip install 'springbench[bench]')")])
    bodies, sizes, nus = ((BEAM,), {"coarse": SIZES["coarse"]}, NUS[:1]) if quick else (ENGINE_BODIES, SIZES, NUS)
    rows = []
    with tempfile.TemporaryDirectory(prefix="springbench-engines-") as tmp:
        tmp = Path(tmp)
        for body in steps(bodies, "bench engines", "body"):
            for resolution, target in sizes.items():
                mesh = tmp / f"{body.name}-{resolution}.msh"
                n_tets = make_body(body, mesh, target)
                for nu in nus:
                    rows += study_one(body, resolution, mesh, n_tets, nu, tmp / f"{body.name}-{resolution}-{nu:g}",
                                      budget=5.0 if quick else BUDGET)
    df = summarise(pd.DataFrame(rows))
    print(summary_table(df).to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    return df
