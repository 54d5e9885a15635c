"""Tables, figures and the HTML index, rebuilt from stored results (never recomputes).

Layout written by :mod:`harness.run.runner`::

    results/index.html                      one static page linking every suite
    results/<suite>/summary.csv, summary.md one row per case, model (and seed)
    results/<suite>/seeds.csv               mean/std/n over seeds (cases with several seeds)
    results/<suite>/provenance.json         the code and machine of the runs that made its results
    results/<suite>/<case>/result-seed<N>.json   manifest (input hash, status, files) + rows
    results/<suite>/<case>/[seed<N>/]<data files and fig-*.png>

Summary columns: ``case, model, stage, seed, status, mode`` (quick or full), then the sizes and
rule columns
(``n_nodes, n_springs, n_elements, n_dofs, structure, rule, stiffness, optimizer, objective,
grouped, weights``), then the scores (``G_initial, G_final`` = G_{a:b:c} with the case's
``weights``, ``G_norm_initial, G_norm_final, G_ref, ref_error_max, G_s_initial, G_s_final,
G_abc_initial,
G_abc_final, freq_error, f1_ratio, freq_error_initial, freq_error_final``), then every other
column a stage wrote, sorted by
name, then ``seconds`` and ``error``. ``G_ref`` is the reference's own estimated error as a
normalised G (same weights, loads and nodes as the row's ``G_norm_*``;
harness.scoring.g_ref_arrays),
``ref_error_max`` its largest point value relative to the largest reference displacement.
``status``: ``ok``; ``ref-coarse`` (scored, but G_ref > 10 % of the row's final normalised G
or the reference missed its tol: kept in every table, mean and paper comparison, and flagged);
``error`` (excluded from the numbers). A case's ``[expect] values`` (the paper's numbers) add
``paper_<col>`` and
``ratio_<col>`` = ours / paper right after ``<col>`` (only on rows that have ``<col>``);
rows with ``G_initial`` != ``G_final`` get ``improvement`` = G_initial / G_final and, where
the paper gives both, ``paper_improvement``. ``values = {G_final = 0.55}`` applies
to every row of the case, ``values = {grouped = {G_final = 0.55}}`` to rows whose
``model`` is ``grouped``. Timing columns (:data:`TIMING`: ``seconds``, ``*_seconds``,
``seconds_*``, ``*_ms``, ``*_per_s``, ``*_per_second``) are the only ones allowed to differ
between two runs with the same seed and inputs.

Data files a stage may write into ``ctx.out_dir`` (figures are drawn from them by the
registry in :mod:`harness.report.figures`; a missing file just means no figure):

- ``trace.csv`` — optimiser trace: ``step, G`` (+ optional ``model``, ``temperature``,
  ``G_best``); one line per model: G against SA steps (``fig-trace.png``).
- ``lloyd.csv`` — ``iteration, std_distance, std_area``: Lloyd statistics, Deussen Fig. 2
  (``fig-lloyd.png``).
- summary column ``lloyd_iterations`` with ``G_final`` (and ``G_initial``): bars of G per
  Lloyd iteration count, Deussen Fig. 12 (suite figure ``fig-lloyd-bars.png``).
- ``volume.csv`` — ``t, MS, MT0, MT``: relative volume variation in percent against time,
  Bourguignon-Cani Fig. 3 (``fig-volume.png``); any other column is drawn too.
- ``frequencies.csv`` — ``mode, fem, <model>, ...``: natural frequencies (Hz) of the FEM
  reference and of each model (``fig-spectrum.png``).
- ``anisotropy.csv`` — ``angle, model, stiffness`` (angle in degrees, effective stiffness in
  any unit; optional ``drift``): polar plot of undesired anisotropy (``fig-anisotropy.png``).
- ``deformed*.npz`` — arrays ``points`` (n, dim) rest positions, ``springs`` (e, 2) int
  (optional), ``u_ref_<load>`` and ``u_<load>`` (n, dim) displacements per load case,
  optional scalar ``scale`` (magnification; default: 10 % of the body size for the largest
  displacement): reference vs model deformed shapes, one panel per load, Deussen
  Fig. 8-11 (``fig-deformed[<suffix>].png``).
- ``fibres*.npz`` — ``points`` (m, 3) element centres, ``directions`` (m, 3) unit fibre
  directions (optional ``u`` (m, 3) displacement of the centres): Bourguignon-Cani Fig. 6
  (``fig-fibres[<suffix>].png``).

CSV files are read with pandas; write them with ``DataFrame.to_csv(path, index=False)``.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

from harness import paths as default_paths
from harness.errors import SpringbenchError
from harness.outputs import write_changed
from harness.report import figures as figs
from harness.report import origin
from harness.report.figures import make_bench_figures
from harness.report.frames import REF_COARSE, SCORED, optimizer_frame
from harness.report.markdown import cell as _cell  # noqa: F401  (markdown_table: report's API)
from harness.report.markdown import markdown_table
from harness.report.nu_sweep import markdown_section, skipped_lines, sweep_frame, sweep_table
from harness.report.page import index_html, page_suites
from harness.report.readme import readme_md

HEAD = (
    ["case", "model", "load", "stage", "seed", "status", "mode", "n_nodes"]
    + ["n_springs", "n_elements", "n_dofs", "structure", "rule", "stiffness"]
    + ["optimizer", "objective", "grouped", "weights", "G_initial", "G_final"]
    + ["improvement", "G_norm_initial", "G_norm_final", "G_ref"]
    + ["ref_error_max", "G_heldout_initial", "G_heldout", "G_ref_heldout"]
    + ["ref_error_heldout", "G_s_initial", "G_s_final", "G_abc_initial"]
    + ["G_abc_final", "freq_error", "f1_ratio", "freq_error_initial"]
    + ["freq_error_final", "freq_error_heldout", "error_estimate"]
    + ["closed_form_error", "tip_ratio", "flexion_ratio"]
    + ["pull_stiffness_spread", "pull_drift_max", "static_status", "engine"]
    + ["G_norm", "max_error", "engine_status", "wall_s"]
)
TAIL = ["seconds", "error"]
TIMING = re.compile(r"^(seconds|time|wall|wall_s)$|^seconds_|_(seconds|ms|per_s|per_second)$")
RESULT_GLOB = "result-seed*.json"


# -- reading stored results -----------------------------------------------------------------


def load_results(suite_dir: Path) -> list[dict]:
    """Stored result manifests of a suite, sorted by case then seed; if two case folders
    hold results of the same case file and seed, the newer one wins."""
    best: dict[tuple, tuple[float, dict]] = {}
    for f in sorted(Path(suite_dir).glob(f"*/{RESULT_GLOB}")):
        try:
            m = json.loads(f.read_text())
        except (OSError, ValueError):
            m = None
        if not isinstance(m, dict) or not isinstance(m.get("rows"), list):  # never skipped silently
            raise SpringbenchError(
                "not a result file springbench wrote (truncated or edited?)",
                file=str(f),
                fix="delete it and re-run that case with 'springbench run'",
            )
        m["_folder"] = f.parent.name
        key = (m.get("file") or f.parent.name, m.get("seed", 0))
        t = f.stat().st_mtime
        if key not in best or t > best[key][0]:
            best[key] = (t, m)
    return sorted(
        (m for _, m in best.values()), key=lambda m: (str(m.get("case")), m.get("seed", 0))
    )


def _num(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _with_expect(row: dict, expect: dict) -> dict:
    """Add paper_<col> and ratio_<col> for the paper's numbers that apply to ``row``."""
    row = dict(row)
    flat = {k: v for k, v in expect.items() if _num(v)}
    per_model = expect.get(row.get("model")) if isinstance(row.get("model"), str) else None
    if isinstance(per_model, dict):
        flat.update({k: v for k, v in per_model.items() if _num(v)})
    if row.get("status", "ok") not in SCORED:
        return row
    for col, paper in flat.items():
        ours = row.get(col)
        if not _num(ours):  # the paper's number only beside a number of ours
            continue
        row.setdefault(f"paper_{col}", paper)
        if _num(row[f"paper_{col}"]) and row[f"paper_{col}"] != 0:
            row.setdefault(f"ratio_{col}", ours / row[f"paper_{col}"])
    g0, g1 = row.get("G_initial"), row.get("G_final")
    if _num(g0) and _num(g1) and g1 > 0 and g0 != g1:
        # the papers' absolute G depends on units they do not state: compare improvements
        row.setdefault("improvement", g0 / g1)
        p0, p1 = row.get("paper_G_initial"), row.get("paper_G_final")
        if _num(p0) and _num(p1) and p1 > 0:
            row.setdefault("paper_improvement", p0 / p1)
    return row


def order_columns(cols) -> list[str]:
    """Stable column order: HEAD, others by name, TAIL; paper_/ratio_ after their column."""
    cols = list(dict.fromkeys(cols))
    extra = [c for c in cols if c.startswith(("paper_", "ratio_"))]
    plain = [c for c in cols if c not in extra]
    out = [c for c in HEAD if c in plain]
    out += sorted(c for c in plain if c not in HEAD and c not in TAIL)
    out += [c for c in TAIL if c in plain]
    for c in sorted(extra, key=lambda c: (c.split("_", 1)[1], c.startswith("ratio_"))):
        base = c.split("_", 1)[1]
        if base in out:
            i = out.index(base) + 1
            while i < len(out) and out[i] in (f"paper_{base}", f"ratio_{base}"):
                i += 1
            out.insert(i, c)
        else:
            out.insert(len(out) - sum(t in out for t in TAIL), c)
    return out


def summary_frame(manifests: list[dict]):
    """One DataFrame of every row of every stored result, columns in the stable order."""
    import pandas as pd

    rows = []
    for m in manifests:
        expect = m.get("expect") if isinstance(m.get("expect"), dict) else {}
        for r in m["rows"]:
            r = _with_expect(r, expect)
            r.setdefault("mode", m.get("mode", ""))  # quick or full: which budgets made the row
            rows.append(r)
    df = pd.DataFrame(rows)
    if df.empty:
        return pd.DataFrame(columns=["case", "model", "stage", "seed", "status"])
    return df[order_columns(df.columns)]


def key_columns(cols) -> list[str]:
    """The columns of summary.md: the stable head, the paper comparisons, the tail."""
    return [
        c
        for c in cols
        if c in HEAD or c in TAIL or c.startswith(("paper_", "ratio_")) or c == "lloyd_iterations"
    ]


def comparable(df):
    """The table without timing columns: what must be bit-identical between two runs."""
    return df[[c for c in df.columns if not TIMING.search(c)]]


def seeds_frame(df):
    """Mean, standard deviation and count over seeds of every numeric score, for the
    cases that ran several seeds."""
    import pandas as pd

    if df.empty or "seed" not in df or "status" not in df:
        return pd.DataFrame()
    ok = df[df["status"].isin(SCORED)]
    n_seeds = ok.groupby("case")["seed"].nunique()
    multi = ok[ok["case"].isin(n_seeds[n_seeds > 1].index)]
    if multi.empty:
        return pd.DataFrame()
    # an optimised row shares its model with the unoptimised one: tell them apart
    keys = [c for c in ("case", "model", "stage", "optimizer", "objective") if c in multi]
    num = [
        c
        for c in multi.columns
        if c not in keys
        and c != "seed"
        and pd.api.types.is_numeric_dtype(multi[c])
        and not c.startswith(("paper_", "ratio_"))
    ]
    g = multi.groupby(keys, sort=True, dropna=False)
    out = g[num].agg(["mean", "std"])
    out.columns = [f"{c}_{s}" for c, s in out.columns]
    out.insert(0, "n_seeds", g["seed"].nunique())
    if (
        multi["status"] == REF_COARSE
    ).any():  # the flag: how many of the averaged rows are ref-coarse
        out.insert(1, "n_ref_coarse", g["status"].agg(lambda s: int((s == REF_COARSE).sum())))
    return out.reset_index()


# -- markdown and html ---------------------------------------------------------------------


def _flagged(df):
    """The table for Markdown with ref-coarse rows marked: their ``G_ref`` cell gets a
    trailing ``!`` (the status column says "ref-coarse")."""
    if "status" not in df or "G_ref" not in df or not (df["status"] == REF_COARSE).any():
        return df
    df = df.copy()
    coarse = (df["status"] == REF_COARSE).to_numpy()
    df["G_ref"] = [(_cell(v) + " !" if c else _cell(v)) for v, c in zip(df["G_ref"], coarse)]
    return df


# -- building -----------------------------------------------------------------------------


def data_folders(suite_dir: Path, manifests: list[dict]) -> list[Path]:
    """Every folder that holds a case's data files (the case folder, seed<N>/ folders)."""
    out = []
    for m in manifests:
        d = Path(suite_dir) / m["_folder"] / m.get("data_dir", ".")
        d = d.resolve()
        if d.is_dir() and d not in out:
            out.append(d)
    return out


def _seeds_csv(suite_dir: Path, df):
    """seeds.csv (the across-seed table), removed when the suite has one seed."""
    seeds = seeds_frame(df)
    seeds_path = suite_dir / "seeds.csv"
    if not seeds.empty:
        write_changed(seeds_path, seeds.to_csv(index=False).encode())
    elif seeds_path.exists():
        seeds_path.unlink()
    return seeds


def _head(suite_dir: Path, manifests, df) -> list[str]:
    """summary.md's title, counts and the ref-coarse note."""
    n_err = int((df.get("status") == "error").sum()) if "status" in df else 0
    n_coarse = int((df.get("status") == REF_COARSE).sum()) if "status" in df else 0
    md = [
        f"# {suite_dir.name}\n",
        f"{len(manifests)} results, {len(df)} rows, {n_err} errors, {n_coarse} ref-coarse. "
        "The key columns "
        f"are shown; all {len(df.columns)} (per-load G, stage details) are in summary.csv; "
        "column meanings in "
        "docs/columns.md. The papers' absolute G depends on units they do not state: compare "
        "`improvement` with `paper_improvement`, and trends.\n",
    ]
    if n_coarse:
        md.append(
            f"**{n_coarse} rows are `ref-coarse`**: the reference's own estimated error at "
            "the row's "
            "nodes (`G_ref`, a normalised G like `G_norm_final`) is more than 10 % of the row's "
            "normalised G, or the reference missed its `tol`; their G says as much about the "
            "reference as about the model. They stay in every table and mean, marked by "
            "their status and "
            "a `!` after `G_ref`.\n"
        )
    return md


OPTIMISERS_TEXT = (
    "Same initial model, reference and weights per case; means over seeds. "
    "`G_final_vs_sa` = "
    "G_final / G_final of SA (same seed); `opt_evaluations`: G evaluations (SA: proposals; "
    "gauss-newton: outer iterations); `*_to_sa_G`: when the trace first reaches "
    "SA's G_final; "
    "`jac_cond_*`: condition of the weighted Jacobian at the result over log k and over k "
    "(identifiable directions: `jac_rank` of `n_params`); `freq_error_*`: RMS "
    "relative error "
    "of the first natural frequencies against the FEM; `G_ref`: the reference's own "
    "error as a "
    "normalised G (compare with `G_norm_final`); `G_heldout`: normalised G on the "
    "loads the fits "
    "never saw (`[loads] heldout`); `status` ref-coarse if any seed's row is.\n"
)
SWEEP_TEXT = (
    "Per body and nu, each model class's fitted row (`p1`: its only row, no constants): "
    "`G_norm` on the fitted loads, `G_heldout` on the loads no fit saw; the classes share "
    "nodes, masses, loads and reference. The frequency error, `k_spread` and "
    "`dt_stable` per "
    "row are in summary.csv; `fig-nu-sweep.png` plots the table.\n"
)


def _sections(df) -> list[str]:
    """summary.md's optimiser comparison and Poisson-ratio sweep, where the suite has them."""
    md = []
    opts = optimizer_frame(df)
    if not opts.empty:
        md += ["\n## Optimisers compared\n", OPTIMISERS_TEXT, markdown_table(opts)]
    sweep = sweep_table(sweep_frame(df))
    if not sweep.empty:
        md += [
            "\n## Model classes against Poisson's ratio\n",
            SWEEP_TEXT,
            markdown_table(sweep),
        ]
        skipped = skipped_lines(df)
        if skipped:
            md += ["\nNo rows (status `skip`):\n"] + skipped
        md += markdown_section(df)
    return md


def build_suite(suite_dir, figures: bool = True, redraw: bool = False) -> dict:
    """(Re)write summary.csv, summary.md, seeds.csv and the figures of one suite."""
    suite_dir = Path(suite_dir)
    manifests = load_results(suite_dir)
    if not manifests:
        raise SpringbenchError(
            "no stored results here",
            file=str(suite_dir),
            fix="give a folder results/<suite> written by 'springbench run'",
        )
    df = summary_frame(manifests)
    origin.write(suite_dir, manifests)
    csv_path, md_path = suite_dir / "summary.csv", suite_dir / "summary.md"
    write_changed(csv_path, df.to_csv(index=False).encode())
    seeds = _seeds_csv(suite_dir, df)
    md = _head(suite_dir, manifests, df) + [markdown_table(_flagged(df[key_columns(df.columns)]))]
    if not seeds.empty:
        md += ["\n## Across seeds (mean, std)\n", markdown_table(seeds)]
    md += _sections(df)
    sources = sorted(
        {
            str(m["expect"].get("source", ""))
            for m in manifests
            if isinstance(m.get("expect"), dict) and m["expect"].get("source")
        }
    )
    write_changed(md_path, "\n".join(md).encode())
    pngs = []
    if figures:
        for d in data_folders(suite_dir, manifests):
            pngs += figs.make_case_figures(d, redraw=redraw)
        pngs += figs.make_suite_figures(suite_dir, redraw=redraw)
    return {"csv": csv_path, "md": md_path, "figures": pngs, "table": df, "sources": sources}


def suites_under(results_root) -> list[Path]:
    """Suite folders under a results root (those holding stored case results)."""
    root = Path(results_root)
    if not root.is_dir():
        return []
    return sorted(d for d in root.iterdir() if d.is_dir() and any(d.glob(f"*/{RESULT_GLOB}")))


def build_index(results_root) -> Path:
    """``<results_root>/index.html``, the page a person reads (:mod:`harness.report.page`),
    and ``README.md``, its tables as Markdown (:mod:`harness.report.readme`)."""
    root = Path(results_root)
    out = root / "index.html"
    write_changed(out, index_html(root).encode())
    suites, bench = page_suites(root)
    write_changed(root / "README.md", readme_md(root, suites, bench).encode())
    return out


def rebuild(paths=(), results_root=None, figures: bool = True, redraw: bool = False) -> list[dict]:
    """``springbench report``: rebuild the named suite folders (default: all under the
    results root, runs/ unless given) and the index."""
    if paths:
        suites = []
        for p in map(Path, paths):
            if not p.is_dir():
                raise SpringbenchError("no such folder", file=str(p), fix="give results/<suite>")
            if any(p.glob(f"*/{RESULT_GLOB}")):
                suites.append(p)
            elif suites_under(p):
                suites += suites_under(p)
            else:
                raise SpringbenchError(
                    "no stored results here",
                    file=str(p),
                    fix="give a folder results/<suite> written by 'springbench run'",
                )
        roots = {s.resolve().parent for s in suites}
    else:
        root = Path(results_root or default_paths.DEFAULT_RUNS)  # read when called
        suites = suites_under(root)
        if not suites:
            raise SpringbenchError(
                "no stored results",
                file=str(root),
                fix="run 'springbench run' first, or report the published ones: --results results",
            )
        roots = {root.resolve()}
    out = [build_suite(s, figures=figures, redraw=redraw) for s in suites]
    for r in roots:
        if figures and (r / "bench").is_dir():
            make_bench_figures(r / "bench", redraw=redraw)
        build_index(r)
    return out
