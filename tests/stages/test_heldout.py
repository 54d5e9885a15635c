"""Fitted and held-out loads in the sms stage (docs/design.md, "Fitted and held-out loads"):
a held-out load never reaches the optimiser, G is on the fitted loads and G_heldout on the
held-out ones, both recomputed here from the stored displacements."""

import numpy as np
import pandas as pd
import pytest

from harness.case.reader import load_case
from harness.export.vtu import read_vtu
from harness.optimize import problem as fit_problem
from harness.stages import StageContext
from harness.stages import sms as stage
from tests.plate_case import plate_case

WEIGHTS = (1.0, 3.0, 15.0)


def case(tmp_path):
    p = tmp_path / "h.toml"
    p.write_text(
        plate_case(
            "held",
            f"""
        [reference]
        divisions = 4
        max_refine = 1
        modes = 4
        [model]
        kind = "sms"
        placement = "grid"
        grid = [5, 3]
        structure = "structure1"
        stiffness = ["deussen"]
        [score]
        weights = {list(WEIGHTS)}
        [optimizer]
        method = "lbfgs"
        options = {{ maxiter = 40 }}
        """,
            loads='heldout = ["shear-y", "stretch-y"]',
        )
    )
    return load_case(p)


def g_norm(npz, names, classes):
    w = np.array(WEIGHTS)[classes]
    err = sum(np.sum(w[:, None] * (npz[f"u_ref_{n}"] - npz[f"u_{n}"]) ** 2) for n in names)
    ref = sum(np.sum(w[:, None] * npz[f"u_ref_{n}"] ** 2) for n in names)
    return np.sqrt(err / ref)


def test_heldout_loads_are_scored_not_fitted(tmp_path, monkeypatch):
    c = case(tmp_path)
    assert c.fit_loads == ("stretch-x", "shear-x") and c.heldout == ("stretch-y", "shear-y")
    seen = []
    original = fit_problem.FitProblem.from_network.__func__

    def spy(cls, *args, **kw):
        seen.append(list(args[7]))  # the load names the optimiser is given
        return original(cls, *args, **kw)

    monkeypatch.setattr(fit_problem.FitProblem, "from_network", classmethod(spy))
    ctx = StageContext(out_dir=tmp_path / "out")
    rows = stage.run(c, ctx)
    assert seen == [["stretch-x", "shear-x"]]
    for row in rows:
        tag = (
            row["stiffness"]
            if row["optimizer"] == "none"
            else f"{row['stiffness']}-{row['optimizer']}"
        )
        npz = np.load(ctx.out_dir / f"deformed-{tag}.npz")
        net, _ = read_vtu(ctx.out_dir / f"model-{tag}.vtu")
        assert row["G_norm_final"] == pytest.approx(
            g_norm(npz, c.fit_loads, net.classes), rel=1e-10
        )
        assert row["G_heldout"] == pytest.approx(g_norm(npz, c.heldout, net.classes), rel=1e-10)
        # every held-out load counts alike
        each = [g_norm(npz, [n], net.classes) for n in c.heldout]
        for n, g in zip(c.heldout, each):
            assert row[f"G_heldout_{n}"] == pytest.approx(g, rel=1e-10)
        assert row["G_heldout_mean"] == pytest.approx(np.mean(each), rel=1e-10)
        assert np.isfinite(row["G_ref_heldout"]) and np.isfinite(row["freq_error_heldout"])
    fit = rows[-1]
    assert fit["optimizer"] == "lbfgs" and fit["G_norm_final"] < fit["G_norm_initial"]
    assert fit["G_heldout_initial"] == pytest.approx(rows[0]["G_heldout"], rel=1e-12)
    assert fit["G_heldout_mean_initial"] == pytest.approx(rows[0]["G_heldout_mean"], rel=1e-12)
    # no mode was fitted
    assert fit["freq_error_heldout"] == pytest.approx(fit["freq_error_final"], rel=1e-12)
    assert set(pd.DataFrame(rows).columns) >= {"G_heldout", "G_ref_heldout", "ref_error_heldout"}
