"""The results page in real headless Chromium at a desktop width (1280 px) and a phone
width (390 px): a screenshot that is not blank, no horizontal scroll of the page, every
image decoded by the browser, every in-page anchor present and every file link on disk.
Run on the page of a small results folder built here and on the committed results/."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path
from urllib.parse import unquote

import numpy as np
import pytest

HERE = Path(__file__).resolve().parents[1]  # tests/

ROOT = HERE.parent
WIDTHS = (1280, 390)
PROBE = """<script>window.addEventListener('load', function () {
  var d = document.documentElement, imgs = Array.prototype.slice.call(document.images);
  var bad = imgs.filter(function (i) { return !(i.complete && i.naturalWidth > 0); })
    .map(function (i) { return i.getAttribute('src'); });
  var anchors = Array.prototype.slice.call(document.querySelectorAll("a[href^='#']"))
    .filter(function (a) {
    return !document.getElementById(a.getAttribute('href').slice(1)); }).map(function (a) {
    return a.getAttribute('href'); });
  document.body.setAttribute('data-overflow', String(d.scrollWidth - d.clientWidth));
  document.body.setAttribute('data-images', String(imgs.length));
  document.body.setAttribute('data-broken', bad.concat(anchors).join(' '));
});</script></body>"""


def chromium() -> str:
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


def browse(exe: str, tmp: Path, width: int, *args: str) -> subprocess.CompletedProcess:
    cmd = (
        [exe, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic"]
        + ["--no-first-run", "--disable-background-networking"]
        + ["--disable-component-update", "--disable-sync"]
        + ["--hide-scrollbars", f"--user-data-dir={tmp / f'profile{width}'}"]
        + [f"--window-size={width},1600", "--virtual-time-budget=10000", *args]
    )
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300)


def check_page(page: Path, tmp: Path):
    """Screenshots and the probed DOM at both widths; the file links of the page's source."""
    from PIL import Image

    exe = chromium()
    text = page.read_text(encoding="utf-8")
    links = re.findall(r"(?:href|src)='([^'#][^']*)'", text)
    missing = [u for u in links if not (page.parent / unquote(u)).exists()]
    assert not missing, missing[:10]
    probe = page.with_name("index-probe.html")
    probe.write_text(text.replace("</body>", PROBE), encoding="utf-8")
    try:
        for width in WIDTHS:
            shot = tmp / f"page{width}.png"
            r = browse(exe, tmp, width, f"--screenshot={shot}", page.as_uri())
            assert shot.is_file(), r.stderr[-2000:]
            img = np.asarray(Image.open(shot).convert("L"), float)
            assert img.shape == (1600, width)
            assert (img < 200).mean() > 0.01 and img.std() > 10  # text, not a blank page
            dom = browse(exe, tmp, width, "--dump-dom", probe.as_uri()).stdout
            over = re.search(r'data-overflow="(-?\d+)"', dom)
            assert over, f"no probe result at {width} px"
            assert int(over.group(1)) <= 0, (
                f"the page scrolls sideways at {width} px by {over.group(1)} px"
            )
            assert int(re.search(r'data-images="(\d+)"', dom).group(1)) == text.count("<img")
            broken = re.search(r'data-broken="([^"]*)"', dom).group(1)
            assert broken == "", f"at {width} px, not loaded or no target: {broken[:300]}"
    finally:
        probe.unlink()


@pytest.mark.slow
def test_built_page_in_chromium(built, tmp_path):
    path, _ = built
    check_page(path, tmp_path)


@pytest.mark.slow
def test_committed_page_in_chromium(tmp_path):
    src = ROOT / "results"
    if not (src / "index.html").exists():
        pytest.skip("no committed results")
    copy = tmp_path / "results"  # the probe file goes into a copy, never into the checkout
    shutil.copytree(src, copy, ignore=shutil.ignore_patterns("_work", "*.npz", "*.vtu"))
    text = (copy / "index.html").read_text()
    assert "<section id='findings'>" in text and text.index("id='findings'") < text.index(
        "id='deussen1995'"
    )
    sections = dict(re.findall(r"<section id='([^']+)'>(.*?)</section>", text, re.S))
    nu = sections["nu_sweep"]  # its figure and findings per body and nu, no wall of numbers
    assert "fig-nu-sweep-families.png" in nu and "<table" not in nu
    assert nu.count("<li>nu = ") == len(
        __import__("pandas").read_csv(src / "nu_sweep" / "summary.csv")["case"].unique()
    )
    assert (
        "verified against" in sections["verification"]
        and "closed-form solution" in sections["verification"]
    )
    bench = sections["bench"]
    assert "fig-bench-reference.png" in bench and bench.count("<table") == len(
        list((src / "bench").glob("*.csv"))
    )
    readme = (copy / "README.md").read_text()
    assert readme.index("## Findings") < readme.index("## Deussen")
    check_page(copy / "index.html", tmp_path)
