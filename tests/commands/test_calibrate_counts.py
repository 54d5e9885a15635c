"""calibrate's validated fit runs the counts harness/optimize/select_counts.py chooses for the
mesh and says so in the JSON: on a small mesh the case's own (level 0), with a budget the
mesh's work exceeds the cheapest level (two candidates, two folds, one start), end to end."""

from __future__ import annotations

import json

import pytest

from harness import cli
from harness.case.sections import SELECT_DEFAULT
from harness.optimize import select_counts
from tests import meshes

pytest.importorskip("gmsh")


def _calibrate(mesh, out) -> dict:
    argv = ["calibrate", str(mesh), "--E", "1e5", "--nu", "0.45", "--max-refine", "0"]
    assert cli.main(argv + ["--quiet", "--out", str(out)]) == 0
    return json.loads(out.with_suffix(".json").read_text())


@pytest.mark.slow
def test_the_fit_runs_the_counts_its_mesh_affords(tmp_path, monkeypatch, capsys):
    mesh = meshes.cylinder(tmp_path)
    data = _calibrate(mesh, tmp_path / "a.vtu")
    assert "Validation (each family of training states left out in turn" in capsys.readouterr().out
    counts = data["fit_counts"]
    assert counts["level"] == 0 and counts["candidates"] == list(SELECT_DEFAULT)
    assert (counts["folds"], counts["maxiter"], counts["starts"], counts["final_maxiter"]) == (
        "families",
        30,
        1,
        300,
    )
    assert 0 < counts["work_gflop"] <= counts["budget_gflop"] == select_counts.FLOOR_GFLOP
    assert [r["model"] for r in data["validation"]] == ["rule", *SELECT_DEFAULT]
    # a budget nothing fits: the cheapest level, and the validation ran exactly it
    monkeypatch.setattr(select_counts, "FLOOR_GFLOP", 0.0)
    monkeypatch.setattr(select_counts, "BUDGET", 0.0)
    cheap = _calibrate(mesh, tmp_path / "b.vtu")
    said = capsys.readouterr().out
    assert "Validation at level 4 of the fit's counts for a mesh this size" in said
    c = cheap["fit_counts"]
    assert c["level"] == 4 and c["candidates"] == ["scale", "scale+node-volume"]
    assert cheap["candidates"] == c["candidates"] and data["candidates"] == list(SELECT_DEFAULT)
    assert (c["folds"], c["maxiter"], c["starts"], c["final_maxiter"]) == ("two", 2, 1, 3)
    assert c["budget_gflop"] == 0.0 and c["work_gflop"] > 0
    table = cheap["validation"]
    assert [r["model"] for r in table] == ["rule", "scale", "scale+node-volume"]
    assert all({"free", "clamped"} <= set(r) for r in table)
    assert cheap["G_heldout_mean"] > 0
