"""``index.html`` of a results folder: the page a reader of the papers opens.

Per suite: what it reproduces, the units caveat, the curated headline tables
(:mod:`harness.report.headlines`), the key figures full width with captions, every other
figure behind a link, and the full summary.csv behind a link; then the benchmarks and a
glossary of the columns. Static HTML5 with an inline style sheet and relative links only,
so it works from the file system and from a web server alike; nothing is recomputed.
"""

from __future__ import annotations

import html
import struct
import sys
from pathlib import Path
from urllib.parse import quote

from harness.report.bench_tables import bench_table, provenance_line
from harness.report.claims import headline_findings, suite_lists
from harness.report.columns import glossary
from harness.report.findings import not_installed_note, status_counts
from harness.report.frames import REF_COARSE
from harness.report.headlines import headline_tables
from harness.report.origin import lines
from harness.report.text import BENCH, KEY_FIGURES, SUITES, UNITS, case_label, figure_caption

ORDER = ("deussen1995", "bourguignon2000", "verification")
CSS = """
body{font:15px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,Helvetica,Arial,sans-serif;color:#222;
 margin:0 auto;padding:1.5em 2em;max-width:1100px;box-sizing:border-box}
h1{font-size:1.7em;margin:.2em 0}h2{margin-top:2em;border-bottom:2px solid #ddd;padding-bottom:.2em}
h3{font-size:1.05em;margin:1.4em 0 .4em}
nav ul{padding-left:1.2em}.note,.caveat,figcaption{color:#555;font-size:.92em}
.caveat{border-left:3px solid #c90;padding:.2em .8em;background:#fffaf0}
.warn{border-left:3px solid #b00;padding:.2em .8em;background:#fff5f5}
table{border-collapse:collapse;font-size:13px;margin:.3em 0;max-width:100%}
th,td{border:1px solid #ccc;padding:3px 6px;vertical-align:top;overflow-wrap:break-word}
th{background:#f3f3f3;text-align:left}td.num{text-align:right;white-space:nowrap}
tr.flag td{background:#fffbea}
figure{margin:1.2em 0}figure img{width:100%;height:auto;border:1px solid #e3e3e3;display:block}
details{margin:.6em 0}summary{cursor:pointer}.figs li{margin:.15em 0}
dl{display:grid;grid-template-columns:max-content 1fr;gap:.3em 1em}dt{font-weight:600}dd{margin:0}
code{background:#f3f3f3;padding:0 .2em}
.scroll{overflow-x:auto;max-width:100%}ul.findings li{margin:.3em 0}
@media (max-width:600px){body{padding:1em .8em}dl{grid-template-columns:1fr}table{font-size:12px}}
"""


def _e(text) -> str:
    return html.escape(str(text), quote=True)


def _href(root: Path, path: Path) -> str:
    """A relative, URL-safe link from the page to ``path``."""
    return _e(quote(path.relative_to(root).as_posix()))


def png_size(path: Path) -> tuple[int, int] | None:
    """Width and height from a PNG header (so the page reserves the space), None if unreadable."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(24)
    except OSError:
        return None
    if len(head) < 24 or head[:8] != b"\x89PNG\r\n\x1a\n":
        return None
    return struct.unpack(">II", head[16:24])


def html_table(df) -> str:
    """A table of display strings; cells that look like numbers are right-aligned, rows
    whose status is ref-coarse, not-installed or error are tinted."""
    cols = [str(c) for c in df.columns]
    out = [
        "<table>",
        "<thead><tr>" + "".join(f"<th scope='col'>{_e(c)}</th>" for c in cols) + "</tr></thead>",
        "<tbody>",
    ]
    for row in df.itertuples(index=False):
        cells = ["" if v is None or v != v else str(v) for v in row]
        flag = (
            " class='flag'"
            if "status" in cols
            and cells[cols.index("status")] in (REF_COARSE, "not-installed", "error")
            else ""
        )
        tds = []
        for v in cells:
            num = v.replace(",", "").replace("x", "").strip()
            try:
                float(num)
                tds.append(f"<td class='num'>{_e(v)}</td>")
            except ValueError:
                tds.append(f"<td>{_e(v)}</td>")
        out.append(f"<tr{flag}>" + "".join(tds) + "</tr>")
    out.append("</tbody></table>")
    return "\n".join(out)


def _figure(root: Path, png: Path, caption: str) -> str:
    size = png_size(png)
    wh = f" width='{size[0]}' height='{size[1]}'" if size else ""
    href = _href(root, png)
    return (
        f"<figure><a href='{href}'><img src='{href}'{wh} alt='{_e(caption)}'></a>"
        f"<figcaption>{_e(caption)} <a href='{href}'>{_e(png.relative_to(root).as_posix())}</a>"
        "</figcaption></figure>"
    )


def _key_figures(suite: Path, pngs: list[Path]) -> list[tuple[Path, str]]:
    """The figures shown full width: the suite's curated list where present, else the
    suite-level figures and the first figure of each kind."""
    chosen = [
        (suite / rel, cap)
        for rel, cap in KEY_FIGURES.get(suite.name, [])
        if (suite / rel).is_file()
    ]
    if chosen:
        return chosen
    seen, out = set(), []
    for p in sorted(pngs, key=lambda p: (p.parent != suite, str(p))):
        kind = p.name.split("-")[1].split(".")[0] if "-" in p.name else p.name
        if p.parent == suite or kind not in seen:
            seen.add(kind)
            where = (
                case_label(p.parent.relative_to(suite).as_posix())
                if p.parent != suite
                else suite.name
            )
            out.append((p, f"{where}: {figure_caption(p.name)}"))
    return out[:8]


def _col_or_empty(df, name) -> list:
    return df[name].tolist() if name in df else [""] * len(df)


def _summary(suite: Path):
    import pandas as pd

    try:
        return pd.read_csv(suite / "summary.csv")
    except (OSError, ValueError, pd.errors.EmptyDataError):
        return None


def _notes(suite: Path, df) -> list[str]:
    """The suite's counts, the units caveat, and the warnings (quick budgets, engines not
    installed, failed rows)."""
    status = df["status"].astype(str) if "status" in df else None
    counts = (status_counts(status) if status is not None else "") or "no status"
    modes = sorted(set(df["mode"].dropna().astype(str))) if "mode" in df else []
    parts = [
        f"<p class='note'>{df['case'].nunique()} cases, {len(df)} rows ({counts}); budgets: "
        f"{_e(', '.join(modes) or 'unknown')}.</p>"
    ]
    if "G_final" in df:  # the units caveat belongs to suites that report G
        parts.append(f"<p class='caveat'>{_e(UNITS)}</p>")
    if "quick" in modes:
        parts.append(
            "<p class='warn'>Quick budgets: a smoke run, not the published numbers "
            "(those are the <code>--full</code> run in <code>results/</code>).</p>"
        )
    if status is not None and (status == "not-installed").any():
        parts.append(f"<p class='warn'>{_e(not_installed_note(df))}</p>")
    if status is not None and (status == "error").any():
        errs = df[status == "error"]
        msg = [e[:200] if isinstance(e, str) else "" for e in _col_or_empty(errs, "error")]
        items = "".join(f"<li>{_e(c)}: {_e(m)}</li>" for c, m in zip(errs["case"].head(10), msg))
        parts.append(f"<div class='warn'><p>{len(errs)} rows failed:</p><ul>{items}</ul></div>")
    return parts


def _tables(suite: Path, df) -> list[str]:
    """The suite's headline tables (a summary the tables cannot read: a warning, none)."""
    try:
        tables = headline_tables(suite.name, df)
    except Exception as exc:  # a foreign or damaged summary must not stop the page
        print(
            f"springbench: warning: tables of {suite}: {type(exc).__name__}: {exc}".replace(
                "\n", " "
            ),
            file=sys.stderr,
        )
        tables = []
    parts = []
    for heading, table, note in tables:
        parts += [f"<h3>{_e(heading)}</h3>", f"<div class='scroll'>{html_table(table)}</div>"]
        if note:
            parts.append(f"<p class='note'>{_e(note)}</p>")
    return parts


def _data(root: Path, suite: Path, df) -> list[str]:
    """Links to the suite's full tables, and its code and machine."""
    data = [
        f"<a href='{_href(root, suite / 'summary.csv')}'>summary.csv</a> (all {len(df)} rows, "
        f"{len(df.columns)} columns: every score, per-load G and stage detail)"
    ]
    for name, what in (
        ("summary.md", "the key columns as Markdown"),
        ("seeds.csv", "means and spreads over seeds"),
    ):
        if (suite / name).is_file():
            data.append(f"<a href='{_href(root, suite / name)}'>{name}</a> ({what})")
    return [
        "<p>Full tables: " + "; ".join(data) + ".</p>",
        "<details class='note'><summary>Code and machine</summary>"
        + "".join(f"<p>{_e(line)}</p>" for line in lines(suite))
        + "</details>",
    ]


def _all_figures(root: Path, suite: Path, pngs: list[Path]) -> list[str]:
    """Every figure of the suite, linked by case folder, folded."""
    if not pngs:
        return []
    parts = [
        f"<details><summary>All {len(pngs)} figures of this suite, by case</summary><ul "
        "class='figs'>"
    ]
    by_folder: dict[Path, list[Path]] = {}
    for p in pngs:
        by_folder.setdefault(p.parent, []).append(p)
    for folder, files in by_folder.items():
        name = folder.relative_to(suite).as_posix()
        links = ", ".join(
            f"<a href='{_href(root, p)}' title='{_e(figure_caption(p.name))}'>"
            f"{_e(p.name[4:-4])}</a>"
            for p in files
        )
        parts.append(f"<li>{_e(suite.name if name == '.' else name)}: {links}</li>")
    parts.append("</ul></details>")
    return parts


def _suite_section(root: Path, suite: Path) -> list[str]:
    title, text = SUITES.get(suite.name, (suite.name, ""))
    parts = [f"<section id='{_e(suite.name)}'>", f"<h2>{_e(title)}</h2>"]
    if text:
        parts.append(f"<p>{_e(text)}</p>")
    df = _summary(suite)
    if df is None:
        parts.append(
            f"<p class='warn'>{_e(suite.name)}/summary.csv could not be read: run "
            "<code>springbench report</code> again.</p></section>"
        )
        return parts
    parts += _notes(suite, df) + _tables(suite, df)
    pngs = sorted(suite.rglob("fig-*.png"))
    key = _key_figures(suite, pngs)
    lists = suite_lists(suite.name, df)
    if lists and key:  # findings read beside their figure
        parts += [_figure(root, p, cap) for p, cap in key]
        key = []
    for heading, sentences in lists:
        parts += [
            f"<h3>{_e(heading)}</h3>",
            "<ul class='findings'>" + "".join(f"<li>{_e(x)}</li>" for x in sentences) + "</ul>",
        ]
    parts += _data(root, suite, df)
    if key:
        parts.append("<h3>Figures</h3>")
        parts += [_figure(root, p, cap) for p, cap in key]
    parts += _all_figures(root, suite, pngs)
    parts.append("</section>")
    return parts


def _bench_section(root: Path, files: list[Path]) -> list[str]:
    import pandas as pd

    parts = [
        "<section id='bench'><h2>Benchmarks</h2>",
        "<p>Each benchmark is measured by <code>springbench bench NAME</code> (speeds as "
        "ratios against a "
        "baseline measured in the same run); README.md gives the targets.</p>",
    ]
    for png in sorted((root / "bench").glob("fig-*.png")):
        parts.append(_figure(root, png, figure_caption(png.name)))
    for f in files:
        parts.append(f"<h3>{_e(f.stem)}: {_e(BENCH.get(f.stem, 'benchmark'))}</h3>")
        try:
            table, note = bench_table(f.stem, pd.read_csv(f))
            parts += [
                f"<div class='scroll'>{html_table(table)}</div>",
                f"<p class='note'>{_e(note)} Code and machine: "
                f"{_e(provenance_line(pd.read_csv(f)))}. "
                f"<a href='{_href(root, f)}'>{_e(f.name)}</a></p>",
            ]
        except (OSError, ValueError, pd.errors.EmptyDataError):
            parts.append(f"<p class='warn'>{_e(f.name)} could not be read.</p>")
    return parts + ["</section>"]


def _findings(suites: list[Path]) -> list[str]:
    items = headline_findings(suites)
    if not items:
        return []
    return [
        "<section id='findings'><h2>Findings</h2><ul class='findings'>"
        + "".join(f"<li>{_e(s)}</li>" for s in items)
        + "</ul>",
        "<p class='note'>Each sentence is generated from the stored tables below "
        "(normalised G: RMS displacement "
        "error relative to the FEM's, 0.05 = 5 %; held-out: loads no fit saw).</p></section>",
    ]


def _glossary() -> list[str]:
    items = "".join(f"<dt>{_e(k)}</dt><dd>{_e(v)}</dd>" for k, v in glossary())
    return [
        "<section id='glossary'><h2>Columns</h2>",
        "<p class='note'>The columns a reader meets first; "
        "every column of every summary.csv is explained in docs/columns.md.</p>",
        f"<dl>{items}</dl></section>",
    ]


def page_suites(root: Path) -> tuple[list[Path], list[Path]]:
    """(the suite folders of ``root`` (those holding a summary.csv) in page order, its
    benchmark CSVs)."""
    suites = sorted(
        (d for d in root.iterdir() if (d / "summary.csv").is_file()) if root.is_dir() else [],
        key=lambda s: (ORDER.index(s.name) if s.name in ORDER else len(ORDER), s.name),
    )
    bench = sorted((root / "bench").glob("*.csv")) if (root / "bench").is_dir() else []
    return suites, bench


def index_html(results_root) -> str:
    """The page of ``results_root`` (its suites: the folders holding a summary.csv)."""
    root = Path(results_root)
    suites, bench = page_suites(root)
    findings = _findings(suites)
    toc = [("findings", "Findings")] if findings else []
    toc += [(s.name, SUITES.get(s.name, (s.name,))[0]) for s in suites]
    toc += [("bench", "Benchmarks")] if bench else []
    toc += [("glossary", "Columns")]
    parts = [
        "<!DOCTYPE html>",
        "<html lang='en'><head><meta charset='utf-8'>",
        "<meta name='viewport' content='width=device-width, initial-scale=1'>",
        "<title>springbench results</title>",
        f"<style>{CSS}</style></head><body>",
        "<header><h1>springbench results</h1>",
        "<p>How well does a spring/mass model imitate linear elasticity? Each suite below "
        "reproduces a "
        "paper's experiments against a verified scikit-fem reference and scores the models "
        "with Deussen's "
        "G criterion. This page is rebuilt from the stored results by <code>springbench "
        "report</code>; "
        "nothing on it is recomputed.</p>",
        "<nav><ul>"
        + "".join(f"<li><a href='#{_e(a)}'>{_e(t)}</a></li>" for a, t in toc)
        + "</ul></nav>",
        "</header><main>",
    ] + findings
    for s in suites:
        parts += _suite_section(root, s)
    if bench:
        parts += _bench_section(root, bench)
    parts += _glossary()
    parts.append("</main></body></html>\n")
    return "\n".join(parts)
