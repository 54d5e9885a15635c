"""Fixtures of the results-page tests: ``site`` (a small results folder of stored results)
and ``built`` (that folder with a fake-stage suite, rebuilt by ``springbench report``)."""

import json
import shutil
from pathlib import Path

import pytest

from harness import cli
from harness.run.runner import run_suite
from tests.fakestage import FAKE, write_case

ROOT = Path(__file__).resolve().parents[2]
STORED = ROOT / "results"
# stored results copied into the test's folder: (suite, case, data files besides the manifest)
FIXTURES = [
    ("deussen1995", "fig08_grid25_grouped", ["trace.csv", "deformed-deussen-sa.npz"]),
    ("bourguignon2000", "volume_cube343", ["volume.csv"]),
    ("bourguignon2000", "fem_cube333_tetra", ["anisotropy.csv"]),
]


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """A small results folder holding copies of a few stored results (their manifests and
    data files) and a benchmark CSV."""
    missing = [
        f"{s}/{c}" for s, c, _ in FIXTURES if not (STORED / s / c / "result-seed0.json").is_file()
    ]
    if missing:
        pytest.skip(f"stored results missing: {missing}")
    res = tmp_path_factory.mktemp("site") / "results"
    for suite, case, files in FIXTURES:
        dst = res / suite / case
        dst.mkdir(parents=True)
        m = json.loads((STORED / suite / case / "result-seed0.json").read_text())
        # the manifest names this checkout's case
        m["file"] = str(ROOT / "cases" / suite / f"{case}.toml")
        (dst / "result-seed0.json").write_text(json.dumps(m))
        for f in files:
            shutil.copy(STORED / suite / case / f, dst / f)
    (res / "bench").mkdir()
    (res / "bench" / "sa.csv").write_text("dim,ratio\n2,55.0\n")
    return res


@pytest.fixture(scope="module")
def built(site):
    """The folder with a fake-stage suite added (every figure kind, two seeds, a failing
    case), rebuilt by `springbench report`: (index.html, its text)."""
    mp = pytest.MonkeyPatch()
    from harness import registry

    mp.setattr(registry, "STAGES", registry.STAGES.with_entries({"fake": FAKE}))
    try:
        suite = site.parent / "cases" / "demo"
        write_case(suite, "a", "rows=2 files=1")
        write_case(suite, "b", "rows=1", extra="[run]\nseeds = [0, 1]")
        write_case(suite, "c", "fail=case")
        assert len(run_suite([suite], results=site, jobs=1, progress=False).failed) == 1
    finally:
        mp.undo()
    assert cli.main(["report", "--results", str(site)]) == 0
    page = site / "index.html"
    return page, page.read_text(encoding="utf-8")
