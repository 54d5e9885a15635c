"""calibrate's verdict on a small gmsh cylinder, checked against its own CSV: the clamp it
picked is on stdout before the work (centroid, normal, node count, the flag to change it;
the node count and the face checked against the mesh here); the held-out sentence puts the
exported constants' held-out error beside the best rule's on the same loads; the JSON's
``status``, ``verdict``, ``best_rule_heldout`` and ``opt_stop`` agree with the table."""

from __future__ import annotations

import json
import math

import meshio
import numpy as np
import pandas as pd
import pytest

from harness import cli
from tests import meshes

pytest.importorskip("gmsh")


@pytest.fixture(scope="module")
def cylinder(tmp_path_factory):
    return meshes.cylinder(tmp_path_factory.mktemp("cyl"))  # r 0.1, length 0.5 along x: 477 tets


def run(mesh, out, capsys, *argv):
    code = cli.main(
        (["calibrate", str(mesh), "--E", "1e5", "--nu", "0.3"] + ["--out", str(out), *argv])
    )
    captured = capsys.readouterr()
    assert code == 0, captured.err
    return (
        captured.out,
        captured.err,
        json.loads(out.with_suffix(".json").read_text()),
        pd.read_csv(out.with_suffix(".csv")),
    )


def expected_verdict(df: pd.DataFrame):
    """The verdict worked out from the table: the exported row's mean held-out error
    against the lowest of the rule rows', a tie within the spread over starts."""
    rules = df[df.optimizer == "none"]
    best = rules.loc[rules.G_heldout_mean.idxmin()]
    row = df[df.exported].iloc[0]
    if row.optimizer == "none" or row.get("choice") == "rule":
        return "rule", best, row
    spread = row.get("G_heldout_mean_spread", math.nan)
    spread = 0.0 if not np.isfinite(spread) else spread
    fit, other = row.G_heldout_mean, best.G_heldout_mean
    return (
        (
            "tie"
            if abs(fit - other) <= spread
            else "better"
            if fit < other
            else "fit-worse-than-rule"
        ),
        best,
        row,
    )


@pytest.mark.slow
@pytest.mark.parametrize("method", ["lbfgs", "rule"])
def test_verdict_matches_the_table(cylinder, tmp_path, capsys, method):
    extra = ["--prior-weight", "1"] if method == "lbfgs" else ["--method", "rule"]
    out, err, data, df = run(cylinder, tmp_path / "m.vtu", capsys, "--max-refine", "1", *extra)
    lines = out.splitlines()
    # the clamp, first and on stdout: the flat x = 0 end face of the cylinder
    assert lines[0].startswith("held-out loads:") and "held-out loads:" not in err
    pts = meshio.read(cylinder).points
    on_face = int(np.sum(np.abs(pts[:, 0] - pts[:, 0].min()) < 1e-9))
    assert f"normal (-1, 0, 0), {on_face} nodes" in lines[0] and "centroid (0, " in lines[0], lines[
        0
    ]
    assert "--clamp / --load-region" in lines[0]
    # the verdict, worked out from the CSV
    want, best, row = expected_verdict(df)
    assert data["verdict"] == want
    assert data["best_rule_heldout"] == {
        "rule": best.stiffness,
        "G_heldout_mean": pytest.approx(best.G_heldout_mean),
    }
    assert data["status"] == row.status and data["status"] in ("ok", "ref-coarse")
    held = next(ln for ln in lines if ln.startswith("Held-out loads ("))
    assert f"the best rule ({best.stiffness}) {100 * best.G_heldout_mean:.3g} %" in held
    assert f" {100 * row.G_heldout_mean:.3g} %" in held
    if want == "fit-worse-than-rule":
        assert f"export the rule instead (--method rule --rule {best.stiffness})" in held
    ref = next(ln for ln in lines if ln.startswith("Reference "))
    assert ref.startswith(f"Reference {row.status} (")
    if method == "lbfgs":  # the optimiser's whole message, never cut at its status
        assert data["opt_stop"] == row.opt_stop and not data["opt_stop"].rstrip().endswith(":")
        assert data["opt_stops"] == [data["opt_stop"]]
    else:
        assert data["opt_stop"] is None and data["opt_stops"] == []


def test_no_heldout_loads_say_what_the_numbers_are(cylinder, tmp_path, capsys):
    out, _, data, _ = run(
        cylinder,
        tmp_path / "m.vtu",
        capsys,
        "--method",
        "rule",
        "--heldout",
        "none",
        "--max-refine",
        "0",
    )
    assert data["verdict"] is None and data["best_rule_heldout"] is None
    assert "No held-out loads (--heldout none)" in out and "clamp" not in out.splitlines()[0]
