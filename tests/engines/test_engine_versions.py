"""The provenance of an engine run (harness/provenance.py, harness/run/store.py): a result
the engines stage made records the version of every engine package of the registry
(ENGINES.about's packages and PIP_NAMES, by pip name) as importlib.metadata reports it,
null for one not installed; the suite's provenance.json and the report's line carry them.
The engines themselves are not run: the stage's table is a fixed one."""

from __future__ import annotations

import json
from importlib import metadata

import pandas as pd

from harness import provenance
from harness.paths import ROOT
from harness.registry import ENGINES, PIP_NAMES
from harness.stages import engines as S

CASE = ROOT / "cases" / "engines" / "beam-coarse_nu0.30.toml"
MISSING = "drake"  # reported as not installed


def engine_dists() -> set[str]:
    """The pip names of the registry's engine packages, read here from the registry."""
    imports = {package for package, _ in ENGINES.about.values()} | set(PIP_NAMES)
    return {PIP_NAMES.get(name, name) for name in imports}


def fake_metadata(monkeypatch) -> dict:
    """importlib.metadata.version made to report "9.<i>" for each engine package but
    MISSING, which it reports as not installed; the expected record."""
    real = metadata.version
    dists = sorted(engine_dists())
    said = {d: None if d == MISSING else f"9.{i}" for i, d in enumerate(dists)}

    def version(dist):
        if dist not in said:
            return real(dist)
        if said[dist] is None:
            raise metadata.PackageNotFoundError(dist)
        return said[dist]

    monkeypatch.setattr(metadata, "version", version)
    return said


def fake_table(case, scratch, spec=None, status=lambda msg: None):
    """One engine, one load and its mean row, as case_rows gives them."""
    row = dict(body="beam", resolution="coarse", n_tets=10, nu=0.3, engine="newton-tets")
    row.update(model=S.OWN, load="tip", G_norm=0.1, max_error=0.2, G_ref=0.01)
    row.update(engine_status="settled", steps=10, wall_s=0.1, note="")
    return S.with_means(pd.DataFrame([row]))


def test_the_registry_names_the_engine_packages():
    assert {"newton", "warp-lang", "mujoco", "pybullet", "drake"} <= engine_dists()


def test_an_engine_run_records_every_engine_package_version(tmp_path, monkeypatch):
    from harness.report.origin import lines
    from harness.run.runner import run_suite

    said = fake_metadata(monkeypatch)
    monkeypatch.setattr(S, "case_rows", fake_table)
    res = tmp_path / "results"
    report = run_suite([CASE], results=res, jobs=1, progress=False, figures=False)
    assert not report.failed
    stored = json.loads((res / "engines" / CASE.stem / "result-seed0.json").read_text())
    assert {r["stage"] for r in stored["rows"]} == {S.NAME}
    versions = stored["provenance"][provenance.ENGINE_VERSIONS]
    assert versions == said and versions[MISSING] is None
    assert set(versions) == engine_dists()
    gathered = json.loads((res / "engines" / "provenance.json").read_text())
    assert [r["provenance"][provenance.ENGINE_VERSIONS] for r in gathered["runs"]] == [said]
    line = lines(res / "engines")[0]
    assert f"{MISSING} not installed" in line
    assert all(f"{d} {v}" in line for d, v in said.items() if v)
