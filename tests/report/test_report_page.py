"""The results page (index.html) a person reads: curated tables from the stored results,
figures with captions, links that resolve, valid structure, rendered in real headless
Chromium (screenshot not blank, no horizontal scroll bar at 1280 px, tables in the DOM)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote

import numpy as np
import pandas as pd
import pytest

from harness.report.headlines import fmt, pair

HERE = Path(__file__).resolve().parents[1]  # tests/
ROOT = HERE.parent

VOID = {
    "area",
    "base",
    "br",
    "col",
    "embed",
    "hr",
    "img",
    "input",
    "link",
    "meta",
    "source",
    "track",
    "wbr",
}
BLOCK = {
    "table",
    "div",
    "ul",
    "ol",
    "dl",
    "figure",
    "section",
    "h1",
    "h2",
    "h3",
    "p",
    "details",
    "nav",
}


class Page(HTMLParser):
    """Structure of a page: nesting problems, ids, links, images, tables (rows of cell texts)."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.stack, self.problems, self.ids, self.links, self.imgs = [], [], [], [], []
        self.tables, self.doctype, self.attrs = [], "", {}
        self._cell = None

    def handle_decl(self, decl):
        self.doctype = decl

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "html":
            self.attrs = a
        if tag in BLOCK and "p" in self.stack:
            self.problems.append(f"<{tag}> inside <p>")
        if "id" in a:
            self.ids.append(a["id"])
        if tag == "a" and "href" in a:
            self.links.append(a["href"])
        if tag == "img":
            self.imgs.append(a)
            self.links.append(a.get("src", ""))
        if tag == "table":
            self.tables.append([])
        if tag == "tr":
            self.tables[-1].append([])
        if tag in ("td", "th"):
            self._cell = ""
        if tag not in VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        if tag in VOID:
            return
        if not self.stack or self.stack[-1] != tag:
            self.problems.append(f"</{tag}> closes <{self.stack[-1] if self.stack else None}>")
            return
        self.stack.pop()
        if tag in ("td", "th"):
            self.tables[-1][-1].append(self._cell)
            self._cell = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell += data


def parse(text: str) -> Page:
    p = Page()
    p.feed(text)
    p.close()
    return p


def table(page: Page, first_header: str) -> list[dict]:
    """The rows (header -> cell) of the first table whose first column is ``first_header``."""
    for t in page.tables:
        if t and t[0] and t[0][0] == first_header:
            return [dict(zip(t[0], r)) for r in t[1:]]
    raise AssertionError(f"no table starting with {first_header!r}")


def number(text: str) -> float:
    return float(text.replace(",", "").strip().rstrip("x"))


def test_numbers_formatted_by_hand():
    assert fmt(0.022991) == "0.0230" and fmt(72.0) == "72" and fmt(5.0884) == "5.09"
    assert fmt(1234.6) == "1,235" and fmt(float("nan")) == "" and fmt(None) == ""
    assert pair(0.116990, 0.022991) == "0.117 \u2192 0.0230" and pair(0.2467, 0.2467) == "0.247"


def test_page_is_valid_html5_with_relative_links_that_resolve(built):
    path, text = built
    page = parse(text)
    assert page.doctype.lower() == "doctype html" and page.attrs.get("lang") == "en"
    assert "<meta charset='utf-8'>" in text and "<title>" in text
    assert not page.problems and not page.stack, page.problems[:5] + page.stack
    assert len(page.ids) == len(set(page.ids))
    assert page.imgs and all(i.get("alt") and i.get("width") and i.get("height") for i in page.imgs)
    root = path.parent
    for link in page.links:
        # relative: works from file:// and http
        assert link and not re.match(r"^[a-z]+:|^/", link), link
        target, _, frag = unquote(link).partition("#")
        if target:
            assert (root / target).is_file(), link
        else:
            assert frag in page.ids, link
    for name in ("summary.csv", "seeds.csv"):
        assert f"demo/{name}" in page.links
    assert "bench/sa.csv" in page.links
    assert re.search(r"<li>c: [^<]*material\.E: E must be positive", text)  # a failed row says why
    # every figure of every case is reachable, the key ones shown full width with a caption
    pngs = {p.relative_to(root).as_posix() for p in root.rglob("fig-*.png")}
    assert pngs and pngs <= set(page.links)
    assert text.count("<figure>") == text.count("<figcaption>") >= 4
    assert {
        "bourguignon2000/volume_cube343/fig-volume.png",
        "deussen1995/fig08_grid25_grouped/fig-deformed-deussen-sa.png",
    } <= {i["src"] for i in page.imgs}


def test_curated_tables_come_from_the_stored_results(built, site):
    _, text = built
    page = parse(text)
    # no raw dump: every table is a curated one, far narrower than summary.csv
    assert max(len(t[0]) for t in page.tables) <= 12
    assert len(pd.read_csv(site / "deussen1995" / "summary.csv").columns) > 30
    # Deussen Fig. 8: the SA row, against the stored manifest's own numbers and the case's paper
    # values
    m = json.loads(
        (site / "deussen1995" / "fig08_grid25_grouped" / "result-seed0.json").read_text()
    )
    sa = next(r for r in m["rows"] if r.get("optimizer") == "sa" and r.get("objective", "G") == "G")
    row = next(r for r in table(page, "case") if r["case"].startswith("Fig. 8"))
    g0, g1 = map(number, row["G before \u2192 after"].split("\u2192"))
    assert g0 == pytest.approx(sa["G_initial"], rel=5e-3) and g1 == pytest.approx(
        sa["G_final"], rel=5e-3
    )
    ours, paper = (number(v) for v in row["improvement ours / paper"].split("/"))
    assert ours == pytest.approx(sa["G_initial"] / sa["G_final"], rel=2e-2)
    assert paper == pytest.approx(m["expect"]["G_initial"] / m["expect"]["G_final"], rel=2e-2)
    assert (
        row["weights"] == "1:6:18"
        and row["springs"] == str(sa["n_springs"])
        and row["status"] == "ok"
    )
    # B&C Fig. 3: the peak |dV/V| of each model, straight from the stored curve
    vol = pd.read_csv(site / "bourguignon2000" / "volume_cube343" / "volume.csv")
    peak = next(r for r in table(page, "experiment") if r["experiment"].startswith("Fig. 3"))
    for model in ("MS", "MT0", "MT"):
        assert number(peak[model]) == pytest.approx(np.abs(vol[model]).max(), rel=5e-3)
    # the unit caveat and the glossary are on the page
    assert "units they do not state" in text
    for term in ("G_norm", "G_heldout", "G_ref", "ref-coarse"):
        assert re.search(rf"<dt>[^<]*{re.escape(term)}|<dd>[^<]*{re.escape(term)}", text), term


def test_volume_figure_overlays_the_original_program(site):
    """The figure's alignment of the original record with our curve reproduces the stage's
    own deviation column (computed when the case ran, by another code path)."""
    from harness.report.figures import volume

    folder = site / "bourguignon2000" / "volume_cube343"
    orig = volume.original_curves(folder)
    if not orig:
        pytest.skip(
            "the original program's record (../shared/reference-data/bourguignon2000) is not here"
        )
    dev = volume.deviations(pd.read_csv(folder / "volume.csv"), orig)
    stage = {
        r["model"]: r["max_dev_vs_original_percent"]
        for r in json.loads((folder / "result-seed0.json").read_text())["rows"]
    }
    assert set(dev) == {"MS", "MT0", "MT"}
    for model, (_, _, d) in dev.items():
        assert np.abs(d).max() == pytest.approx(stage[model], rel=1e-6, abs=1e-12)


def test_3d_shapes_show_the_faces_towards_the_viewer(tmp_path):
    """A unit cube seen from +x, -y, +z (the default view): 7 of its 8 corners and 9 of its
    12 edges lie on the faces x = 1, y = 0, z = 1; the hidden corner is (0, 1, 0)."""
    from itertools import product

    from harness.report.figures import deformed

    p = np.array(list(product([0.0, 1.0], repeat=3)))
    edges = np.array(
        [(i, j) for i in range(8) for j in range(i + 1, 8) if np.abs(p[i] - p[j]).sum() == 1]
    )
    nodes, springs = deformed.visible_surface(p, edges)
    assert len(edges) == 12 and springs.sum() == 9
    assert p[~nodes].tolist() == [[0.0, 1.0, 0.0]]
    np.savez(
        tmp_path / "deformed-m.npz", points=p, springs=edges, u_ref_pull=0.01 * p, u_pull=0.011 * p
    )
    assert [f.name for f in deformed.make(tmp_path)] == ["fig-deformed-m.png"]


def test_log_axis_only_where_values_span_decades():
    from harness.report.figures import log_if_decades, subplots

    fig, ax = subplots()
    assert not log_if_decades(ax, [1.0, 10.0]) and ax.get_yscale() == "linear"
    assert not log_if_decades(ax, [-1.0, 1000.0])
    assert log_if_decades(ax, [0.01, 0.6, np.nan]) and ax.get_yscale() == "log"


def _chromium() -> str:
    exe = next(
        (
            shutil.which(n)
            for n in ("chromium", "chromium-browser", "google-chrome")
            if shutil.which(n)
        ),
        None,
    )
    if exe is None:
        pytest.skip("chromium is not installed (apt-get install -y chromium; .ci/run installs it)")
    return exe


def _browse(exe: str, tmp: Path, *args: str) -> subprocess.CompletedProcess:
    cmd = (
        [exe, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic"]
        + ["--no-first-run", "--disable-background-networking"]
        + ["--disable-component-update"]
        + ["--disable-sync", f"--user-data-dir={tmp / 'profile'}"]
        + ["--window-size=1280,2000", *args]
    )
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300)


@pytest.mark.slow
def test_page_renders_in_headless_chromium(built, tmp_path):
    from PIL import Image

    exe = _chromium()
    path, text = built
    shot = tmp_path / "page.png"
    r = _browse(exe, tmp_path, f"--screenshot={shot}", path.as_uri())
    assert shot.is_file(), r.stderr[-2000:]
    img = np.asarray(Image.open(shot).convert("L"), float)
    assert img.shape == (2000, 1280)
    assert (img < 200).mean() > 0.01 and img.std() > 10  # text and tables, not a blank page
    # the DOM as Chromium parsed it, with the page's layout width measured after load
    probe = path.with_name("index-probe.html")
    probe.write_text(
        text.replace(
            "</body>",
            "<script>var d = document.documentElement; document.body.setAttribute("
            "'data-overflow', String(d.scrollWidth - d.clientWidth));</script></body>",
        )
    )
    r = _browse(exe, tmp_path, "--dump-dom", probe.as_uri())
    dom = r.stdout
    assert "<h1>springbench results</h1>" in dom, r.stderr[-2000:]
    assert dom.count("<table") == text.count("<table") >= 4
    assert dom.count("<img") == text.count("<img")
    overflow = re.search(r'data-overflow="(-?\d+)"', dom)
    assert overflow and int(overflow.group(1)) <= 0, "horizontal scroll bar at 1280 px"
