"""springbench bench tets: do calibrate's materials for linear tetrahedra beat the plain
(E, nu) on bodies, clamps and loads calibrate never saw? The judge is independent of
springbench's FEM and statics: its truth is bench heldout's P2 solve with scikit-fem, its
model answer the linear-tetrahedra statics of the exported JSON assembled in the judge
(harness/bench/heldout_judge.py ``tet_solve``).

Bodies: bench heldout's four gmsh solids (an L-bracket, a tapered bar bolted through its
hole, an elbow, a dumbbell; ~3,000 tetrahedra each, physical surfaces ``clamp`` and
``load`` unlike calibrate's own held-out ends), E = 1e5 Pa, nu = 0.3 and 0.45, density
1000 (quick: the bracket, ~1,000 tets, nu = 0.3).

Models, on the body's own tetrahedra: ``plain`` (every tet the body's E, nu: what an engine
gets without calibrate), ``p1-global`` (``springbench calibrate --model p1-global``: one
fitted E', nu') and ``p1`` (``--model p1``: a material per tetrahedron). Each calibrate
runs with its defaults and ``--max-refine 1`` in its own process; per (body, nu) they
share one reference cache, empty before the first (p1-global, whose ``seconds`` therefore
include the reference; p1's reuse it). Only the JSON exports are read: tet_indices matched
to the body's tetrahedra (any row and corner order; a different set fails the run), tet_E,
tet_nu. A run that fails leaves its rows with err NaN and the reason in ``note``.

Loads (bench heldout's, clamp group held in every component): tractions on the load group
along two directions across it, a twist about its normal, gravity, and gravity with the
load group held too; each scaled so that the 99th percentile of the truth's strain norm is
1e-3. The model's nodal forces: P1-consistent tractions on the load group's facets (exact
for linear tractions); gravity rho V / 4 g at each corner of every tetrahedron (the lumped
P1 mass a tet engine uses; for a constant g also the consistent P1 load), the clamp group's
nodes held, one sparse LU per support.

Truth: P2 on the body's mesh itself (scikit-fem), as bench heldout.

Metric: err = |u_model - u_truth| / |u_truth| over the mesh's vertices; per (body, nu,
model) the geometric mean over the loads, ratio_to_plain = geomean(err_model) /
geomean(err_plain); overall the geometric mean of the ratios over (body, nu). Acceptance:
p1-global <= 0.7 overall, p1 <= 0.5 overall, each <= 1 on every (body, nu).

Rows: one per (body, nu, model, load) (ratio_to_plain: err over plain's err on that load),
a ``geomean`` row per (body, nu, model) and an overall row per model (body ``all``).
Columns: body, n_tets, nu, model (plain, p1-global, p1), choice (the JSON's ``choice``;
plain: plain), load, err, ratio_to_plain, seconds (that calibrate's wall time),
truth_seconds, note, E_effective, nu_effective (the export's, where it gives them; plain:
E, nu).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import pandas as pd

from harness.bench.heldout import (
    NO_GMSH,
    PEAK_STRAIN,
    calibrate,
    geomean,
    over_bodies,
    relative,
)
from harness.bench.heldout_bodies import Body, read_body
from harness.bench.heldout_judge import E, export_materials, study_loads, tet_solve, truth

# each with a reference refined once (--max-refine 1): the published tets.csv's setting
MODELS = (
    ("p1-global", ("--model", "p1-global", "--max-refine", "1")),
    ("p1", ("--model", "p1", "--max-refine", "1")),
)
TARGETS = {"p1-global": 0.7, "p1": 0.5}  # overall ratio to plain; every (body, nu) <= 1
ACCEPT_EACH = 1.0
COLUMNS = ["body", "n_tets", "nu", "model", "choice", "load", "err", "ratio_to_plain"]
COLUMNS += ["seconds", "truth_seconds", "note", "E_effective", "nu_effective"]


def _load_rows(row: dict, u, fem: dict, scale: dict, loads) -> list[dict]:
    """One row per load: err of the answers u (None: NaN) against the scaled truth."""
    out = []
    for load in loads:
        ut = scale[load.name] * fem[load.name][0]
        err = math.nan if u is None else relative(u[load.name], ut)
        out.append(dict(row, load=load.name, err=err))
    return out


def study_one(body: Body, mesh: Path, nu: float, folder: Path, models=MODELS) -> list[dict]:
    """The rows of one (body, nu): plain, then every calibrated export, under every load."""
    points, tets, groups = read_body(mesh)
    loads = study_loads(body, points, groups)
    t0 = time.perf_counter()
    fem = truth(points, tets, groups, loads, nu)
    truth_seconds = time.perf_counter() - t0
    scale = {name: PEAK_STRAIN / peak for name, (_, peak) in fem.items()}
    base = dict(body=body.name, n_tets=len(tets), nu=nu, truth_seconds=truth_seconds, note="")
    plain = dict(base, model="plain", choice="plain", seconds=math.nan, E_effective=E)
    plain["nu_effective"] = nu
    u = tet_solve(points, tets, groups, loads, scale, E, nu)
    rows = _load_rows(plain, u, fem, scale, loads)
    cache = folder / f"cache-{body.name}-{nu:g}"  # empty: the first calibrate run is cold
    for model, extra in models:
        row = dict(base, model=model, choice=None, seconds=math.nan)
        row.update(E_effective=math.nan, nu_effective=math.nan)
        out = folder / f"{body.name}-{nu:g}-{model}.vtu"
        try:
            data, row["choice"], _, row["seconds"] = calibrate(mesh, out, nu, cache, *extra)
            for key in ("E_effective", "nu_effective"):
                row[key] = math.nan if data.get(key) is None else float(data[key])
            Et, nut = export_materials(data, points, tets, out.with_suffix(".json").name)
            u = tet_solve(points, tets, groups, loads, scale, Et, nut)
        except (RuntimeError, ValueError) as exc:  # a failed run: its rows say why
            u, row["note"] = None, str(exc)
        rows += _load_rows(row, u, fem, scale, loads)
    return rows


def summarise(df: pd.DataFrame) -> pd.DataFrame:
    """The per-load rows with their ratio to plain, a geomean row per (body, nu, model) and
    an overall row per model (body 'all': the geometric mean of its (body, nu) ratios)."""
    out = []
    keep = ["n_tets", "choice", "seconds", "truth_seconds", "note", "E_effective", "nu_effective"]
    for (body, nu), g in df.groupby(["body", "nu"], sort=False):
        plain = g[g.model == "plain"].set_index("load").err
        g = g.assign(ratio_to_plain=g.err.values / g.load.map(plain).values)
        gm = g.groupby("model", sort=False)["err"].apply(geomean)
        first = g.groupby("model", sort=False)[keep].first().loc[gm.index].reset_index()
        ref = gm.get("plain", math.nan)
        summary = first.assign(
            body=body, nu=nu, load="geomean", err=gm.values, ratio_to_plain=gm.values / ref
        )
        out += [g, summary]
    df = pd.concat(out, ignore_index=True)
    each = df[df.load == "geomean"]
    overall = [
        dict(
            body="all",
            model=model,
            load="geomean",
            err=geomean(g.err),
            ratio_to_plain=geomean(g.ratio_to_plain),
            seconds=float(g.seconds.sum()) if g.seconds.notna().any() else math.nan,
            note="; ".join(sorted({n for n in g.note if isinstance(n, str) and n})),
        )
        for model, g in each.groupby("model", sort=False)
    ]
    df = pd.concat([df, pd.DataFrame(overall)], ignore_index=True)
    return df.astype({"n_tets": "Int64"})[COLUMNS]


def summary_table(df: pd.DataFrame) -> pd.DataFrame:
    """Per (body, nu): plain's geomean err, each calibrated model's and its ratio."""
    g = df[(df.load == "geomean") & (df.body != "all")]
    table = (
        g[g.model == "plain"].set_index(["body", "nu"])[["err"]].rename(columns={"err": "plain"})
    )
    for model in TARGETS:
        m = g[g.model == model].set_index(["body", "nu"])
        table[model] = m.err
        table[f"{model}_ratio"] = m.ratio_to_plain
        table[f"{model}_seconds"] = m.seconds
    m = g[g.model == "p1-global"].set_index(["body", "nu"])
    table["E_eff"], table["nu_eff"] = m.E_effective, m.nu_effective
    return table.reset_index()


def verdict(df: pd.DataFrame) -> str:
    """PASS when every model meets its overall target and <= 1 on every (body, nu)."""
    ok, parts = True, []
    for model, target in TARGETS.items():
        each = df[(df.load == "geomean") & (df.model == model) & (df.body != "all")]
        overall = df[(df.body == "all") & (df.model == model)].ratio_to_plain
        if not len(each) or each.ratio_to_plain.isna().any() or overall.isna().any():
            notes = sorted({n for n in each.note if isinstance(n, str) and n})
            ok, parts = False, parts + [f"{model} not judged ({'; '.join(notes) or 'no rows'})"]
            continue
        worst = each.loc[each.ratio_to_plain.idxmax()]
        r = float(overall.iloc[0])
        ok = ok and r <= target and bool((each.ratio_to_plain <= ACCEPT_EACH).all())
        parts.append(
            f"{model} / plain = {r:.3g} overall (accept <= {target:g}), worst "
            f"{worst.ratio_to_plain:.3g} on {worst.body} nu={worst.nu:g} "
            f"(accept <= {ACCEPT_EACH:g} each)"
        )
    n = len(df[(df.load == "geomean") & (df.model == "plain") & (df.body != "all")])
    return f"{'PASS' if ok else 'FAIL'}: " + "; ".join(parts) + f"; {n} (body, nu)"


def run(quick: bool = False, work: Path | None = None) -> pd.DataFrame:
    rows = over_bodies(quick, "tets", study_one, work)
    if rows is None:
        return NO_GMSH
    df = summarise(rows)
    print(summary_table(df).to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    print(verdict(df))
    return df
