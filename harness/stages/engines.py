"""Stage ``engines``: how far is each engine's deformable body from linear elasticity?

For a case with ``[model] kind = "engines"`` and a tetrahedral mesh body, it does what a
user does at the command line, each command in its own process: ``springbench pack`` of
the mesh (``--clamp``, ``--load-region``: the FEM is the reference's P2 with its error
estimate), ``springbench engines run ENGINE`` for every engine of ``[model] engines`` (the
engine's own model from E and nu) and for springbench's exports of the same mesh
(``[model] exports``, harness/registry.py ENGINE_EXPORTS: ``calibrate --method rule``, the
best stiffness rule; ``calibrate``, the calibrated springs; ``--engine mujoco-springs``;
``--model p1-global`` and ``--model p1``, calibrated materials for the engines' own
tetrahedra), each run by every engine that takes it (``engines run ENGINE --model``);
every answer scored against the pack's FEM as ``springbench score`` does (G_norm = RMS
displacement error / RMS FEM displacement over the nodes).

Rows: one per (engine, model, load) with G_norm, max_error, G_ref (the FEM's own error
as a G_norm), engine_status (settled / not-settled / diverged / not-installed / failed),
steps and wall_s to equilibrium, a note, and a ``mean`` row per (engine, model) (G_norm:
the mean over the loads; wall_s: the sum). An engine that cannot represent a case says so
in its rows; the case goes on. Each row's ``status`` is ``not-installed`` where its engine's
package is missing (the note names the extra that installs it), else ``ok``.
"""

from __future__ import annotations

import importlib.util
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd

from harness.engines import EXTRA
from harness.errors import SpringbenchError
from harness.export.pack import read_pack
from harness.export.pack_score import read_displacements, score_fields
from harness.io.meshfile import read_mesh
from harness.registry import ENGINE_EXPORTS, ENGINES

NAME = "engines"
# its commands (pack, calibrate, engines run) run in their own processes: a result depends on
# every source file, not only on those this process imports (harness/run/jobs.py)
SUBPROCESS_CODE = True
OWN = "own (E, nu)"
UNSUPPORTED = "unsupported-load"  # a load an engine does not take (its rows say why)
COLUMNS = (
    ["body", "resolution", "n_tets", "nu", "engine", "model", "load"]
    + ["G_norm", "max_error", "G_ref", "engine_status", "steps", "wall_s"]
    + ["note"]
)


def applies(case) -> bool:
    m = case.section("model")
    return m is not None and m.get("kind") == "engines"


def check(case):
    """A mesh body in 3-D: the engines' models are tetrahedral."""
    if case.body.shape != "mesh" or case.dim != 3:
        raise SpringbenchError(
            "the engines stage needs a 3-D tetrahedral mesh body",
            file=str(case.path),
            field="body.shape",
            fix='shape = "mesh" with file = a tetrahedral mesh, dim = 3',
        )


def cli(*argv) -> subprocess.CompletedProcess:
    """One springbench command in its own process, as a user runs it; output captured."""
    return subprocess.run(
        [sys.executable, "-m", "harness", *map(str, argv)], capture_output=True, text=True
    )


def _why(proc) -> str:
    lines = [ln for ln in (proc.stderr or "").splitlines() if ln.strip()]
    return lines[-1] if lines else f"exit {proc.returncode}"


def material_args(E: float, nu: float, density: float) -> tuple:
    return "--E", repr(float(E)), "--nu", repr(float(nu)), "--density", repr(float(density))


def _installed(engine: str) -> bool:
    return importlib.util.find_spec(ENGINES.about[engine][0]) is not None


def engine_rows(
    pack, pack_dir: Path, engine: str, loads, folder: Path, model_json=None
) -> list[dict]:
    """Per load: one engine run through ``springbench engines run`` and scored."""
    if not _installed(engine):
        return [
            dict(load=n, engine_status="not-installed", note=f"{EXTRA} installs {engine}")
            for n in loads
        ]
    folder.mkdir(parents=True, exist_ok=True)
    out, log = folder / f"{engine}.npz", folder / f"{engine}.csv"
    extra = ("--model", model_json) if model_json else ()
    proc = cli(
        "engines",
        "run",
        engine,
        pack_dir,
        "--loads",
        ",".join(loads),
        "--out",
        out,
        "--log",
        log,
        *extra,
    )
    if not out.exists():
        return [dict(load=n, engine_status="failed", note=_why(proc)) for n in loads]
    run = pd.read_csv(log).set_index("load")
    fields = read_displacements(out, pack)  # the loads with a displacement (finite)
    have = [n for n in loads if n in fields]
    scored_rows = score_fields(pack, fields, have) if have else []
    scored = {r["load"]: r for r in scored_rows if r["load"] != "total"}
    nan = dict(G_norm=math.nan, max_error=math.nan, G_ref=math.nan)
    rows = []
    for name in loads:
        finite = name in fields
        s = scored.get(name, nan)
        rows.append(
            dict(
                load=name,
                G_norm=s["G_norm"] if finite else math.nan,
                max_error=s["max_error"] if finite else math.nan,
                G_ref=s["G_ref"],
                engine_status=run.status[name],
                steps=int(run.steps[name]),
                wall_s=float(run.wall_s[name]),
                note="" if pd.isna(run.note[name]) else str(run.note[name]),
            )
        )
    return rows


def export(mesh: Path, material: tuple, groups: tuple, label: str, folder: Path):
    """(model label, JSON path or the reason there is none) of one springbench export made
    with ENGINE_EXPORTS[label]'s flags: its fit stops by iteration counts (no wall-time
    budget: the same export on any machine)."""
    out = folder / f"{label}.vtu"
    proc = cli("calibrate", mesh, *material, *groups, "--out", out, *ENGINE_EXPORTS[label].flags)
    if proc.returncode != 0 or not out.with_suffix(".json").exists():
        return f"springbench {label}", f"calibrate {label}: {_why(proc)}"
    data = json.loads(out.with_suffix(".json").read_text())
    row = pd.read_csv(out.with_suffix(".csv")).query("exported").iloc[0]
    return f"springbench {label}: {exported(data, row, label)}", out.with_suffix(".json")


def exported(data: dict, row, label: str) -> str:
    """What an export holds, in words: its rule, its fitted choice, its fitted pair."""
    choice = None if label == "rule" else data.get("choice")
    if not choice or choice == "rule":
        return f"rule {row.stiffness}"
    E, nu = data.get("E_effective"), data.get("nu_effective")
    if label == "p1-global" and E is not None and nu is not None:
        return f"E {E:.3g} Pa, nu {nu:.3f}"
    return "a material per tetrahedron" if label == "p1" else str(choice)


def study(
    mesh: Path, E: float, nu: float, density: float, spec, scratch: Path, status=lambda msg: None
):
    """The per-load rows of one mesh and material (``spec``: the ``[model]`` section)."""
    material, loads = material_args(E, nu, density), list(spec["loads"])
    groups = ("--clamp", spec["clamp"], "--load-region", spec["load_region"])
    status("pack")
    proc = cli(
        "pack",
        mesh,
        *material,
        *groups,
        "--peak-strain",
        repr(float(spec["peak_strain"])),
        "--loads",
        "all",  # the case names the loads it scores: each is packed, its FEM error reported
        "--out",
        scratch / "pack",
    )
    if proc.returncode != 0:
        raise SpringbenchError(
            f"springbench pack failed: {_why(proc)}",
            file=str(mesh),
            field="body.file",
            fix="run springbench pack on the mesh to see why",
        )
    pack = read_pack(scratch / "pack")
    runs = [(engine, OWN, None) for engine in spec["engines"]]
    for label in spec["exports"]:
        engines = ENGINE_EXPORTS[label].engines
        if not any(map(_installed, engines)):  # their rows say so; no export to make
            runs += [(engine, f"springbench {label}", None) for engine in engines]
            continue
        status(f"calibrate {label}")
        model, source = export(mesh, material, groups, label, scratch / "exports")
        runs += [(engine, model, source) for engine in engines]
    rows = []
    for i, (engine, model, source) in enumerate(runs):
        status(f"{engine} {model}")
        if isinstance(source, str):
            got = [dict(load=n, engine_status="failed", note=source) for n in loads]
        else:
            got = engine_rows(pack, scratch / "pack", engine, loads, scratch / f"run{i}", source)
        rows += [dict(engine=engine, model=model, **r) for r in got]
    return rows


def with_means(
    df: pd.DataFrame,
    keys=("body", "resolution", "n_tets", "nu", "engine", "model"),
    status: str = "engine_status",
) -> pd.DataFrame:
    """The per-load rows plus a ``mean`` row per ``keys`` (G_norm: the mean over the loads
    the engine takes, its note naming them when it takes fewer than all; max_error, G_ref:
    the largest; steps, wall_s: the sums)."""
    keys = [k for k in keys if k in df.columns]
    out = []
    for key, g in df.groupby(keys, sort=False, dropna=False):
        out.append(g)
        took = g[g[status] != UNSUPPORTED]
        note = "" if len(took) == len(g) else f"the mean over {', '.join(took.load)}"
        g = took if len(took) else g
        settled = bool((g[status] == "settled").all())
        out.append(
            pd.DataFrame(
                [
                    dict(
                        zip(keys, key if isinstance(key, tuple) else (key,)),
                        load="mean",
                        G_norm=float(g.G_norm.mean()),
                        max_error=float(g.max_error.max()),
                        G_ref=float(g.G_ref.max()),
                        **{status: "settled" if settled else "see loads"},
                        steps=float(g.steps.sum()),
                        wall_s=float(g.wall_s.sum()),
                        note=note,
                    )
                ]
            )
        )
    return pd.concat(out, ignore_index=True)


def n_tets(mesh: Path) -> int:
    return int(len(read_mesh(mesh).cells.get("tetra", ())))


def case_rows(case, scratch: Path, spec=None, status=lambda msg: None) -> pd.DataFrame:
    """The table of one engines case (``spec``: its ``[model]`` section unless given):
    per-load rows and the ``mean`` rows."""
    spec = case.section("model") if spec is None else spec
    mesh = Path(case.body.file)
    base = dict(
        body=spec.get("body") or mesh.stem,
        resolution=spec["resolution"],
        n_tets=n_tets(mesh),
        nu=case.material.nu,
    )
    rows = study(
        mesh, case.material.E, case.material.nu, case.material.density, spec, scratch, status
    )
    df = with_means(pd.DataFrame([dict(base, **r) for r in rows]).reindex(columns=COLUMNS))
    df["note"] = df["note"].fillna("")
    return df


def row_status(df: pd.DataFrame) -> list[str]:
    """Each row's ``status``: ``not-installed`` where the engine's package is missing (a
    ``mean`` row: where every load of its engine and model is), else ``ok``; so a run
    without the engines never reads as a run that passed."""
    loads = df[df["load"] != "mean"]
    gone = {
        key
        for key, g in loads.groupby(["engine", "model"], sort=False, dropna=False)
        if (g["engine_status"] == "not-installed").all()
    }
    return [
        "not-installed" if st == "not-installed" or (e, m) in gone else "ok"
        for e, m, st in zip(df["engine"], df["model"], df["engine_status"])
    ]


def run(case, ctx) -> list[dict]:
    with tempfile.TemporaryDirectory(prefix="springbench-engines-") as tmp:
        df = case_rows(case, Path(tmp), status=ctx.status)
    df.insert(0, "case", case.name)
    df["status"] = row_status(df)
    return df.to_dict("records")
