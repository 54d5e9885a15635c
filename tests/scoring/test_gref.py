"""The reference's own error beside every score (docs/design.md, same title): G_ref by hand, the
"ref-coarse" status of sms rows (stand-in and real reference), and ref-coarse rows kept
and flagged in summary.md."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from harness.case.reader import load_case
from harness.report import build as report
from harness.scoring import g_arrays, g_ref_arrays, ref_error_max, ref_status, reference_error
from tests.models.springcases import TINY, ClosedFormRef

# -- the function ---------------------------------------------------------------------------


def test_g_ref_by_hand():
    # two loads, three nodes (inner, border, corner), weights 1:2:4
    u_ref = np.array([[[1.0, 0.0], [0.0, 2.0], [0.0, 0.0]], [[0.0, 0.0], [1.0, 1.0], [0.0, 1.0]]])
    e = np.array([[0.1, 0.2, 0.0], [0.0, 0.1, 0.3]])
    classes = np.array([0, 1, 2])
    g, per = g_ref_arrays(u_ref, e, classes, (1, 2, 4))
    # sum w e^2: 0.01 + 2*0.04 = 0.09 and 2*0.01 + 4*0.09 = 0.38; sum w |u|^2: 1 + 2*4 = 9 and 2*2
    # + 4*1 = 8
    assert g == pytest.approx(math.sqrt(0.47 / 17), rel=1e-14)
    assert per == pytest.approx([0.1, math.sqrt(0.38 / 8)], rel=1e-14)
    assert ref_error_max(u_ref, e) == pytest.approx(0.3 / 2.0)
    # the weights matter: 1:1:1 gives another number
    # (1 + 4) + (2 + 1)
    assert g_ref_arrays(u_ref, e, classes, (1, 1, 1))[0] == pytest.approx(math.sqrt(0.15 / 8))
    # an estimate equal to |u_ref - u| gives exactly the normalised G of g_arrays
    rng = np.random.default_rng(0)
    u_ref = rng.normal(size=(3, 7, 2))
    u = u_ref + 0.1 * rng.normal(size=u_ref.shape)
    cls = rng.integers(0, 3, 7)
    sc = g_arrays(u_ref, u, cls, (1, 3, 15))
    g, per = g_ref_arrays(u_ref, np.linalg.norm(u_ref - u, axis=2), cls, (1, 3, 15))
    assert g == pytest.approx(sc.G_norm, rel=1e-12)
    assert per == pytest.approx(list(sc.per_load_norm.values()), rel=1e-12)
    # no estimate: NaN, never a number
    e_nan = np.full((3, 7), np.nan)
    assert math.isnan(g_ref_arrays(u_ref, e_nan, cls, (1, 1, 1))[0]) and math.isnan(
        ref_error_max(u_ref, e_nan)
    )
    with pytest.raises(ValueError):
        g_ref_arrays(u_ref, e_nan[:, :3], cls, (1, 1, 1))


def test_ref_status_rules():
    assert ref_status(0.005, 0.1, True) == "ok"
    assert ref_status(0.011, 0.1, True) == "ref-coarse"  # above 10 % of the normalised G
    assert ref_status(0.005, 0.1, False) == "ref-coarse"  # missed its tol
    assert ref_status(math.nan, 0.1, False) == "ref-coarse"  # no estimate, missed tol
    assert ref_status(1e-9, 0.0, True) == "ref-coarse"  # a perfect fit is below the FEM's error
    assert ref_status(math.nan, 0.1, None) == "ok"  # a stand-in that says nothing


class _Estimate(dict):
    """{load: relative} that is also callable (points, load) -> (n,), as ReferenceSolution's."""

    def __init__(self, values, point):
        super().__init__(values)
        self._point = point

    def __call__(self, points, load):
        return self._point(np.asarray(points, float), load)


class EstimatedRef(ClosedFormRef):
    """The closed-form stand-in with an error estimate e(p) = eps |u_ref(p)| (not uniform)
    and ``met_tol``: then G_ref = eps whatever the weights, and ref_error_max = eps."""

    def __init__(self, case, eps, met_tol=True):
        super().__init__(case)
        self.met_tol = met_tol
        self.error_estimate = _Estimate(
            {l.name: eps for l in case.loads},
            lambda p, load: eps * np.linalg.norm(self.displacement(p, load), axis=1),
        )


def test_reference_error_reads_the_estimate(tmp_path):
    case = load_case(_tiny(tmp_path))
    pts = np.array([[2.0, 1.0], [1.0, 1.0], [0.0, 0.0]])
    names = [l.name for l in case.loads]
    e = reference_error(EstimatedRef(case, 0.5), pts, names)
    assert e.shape == (4, 3)
    assert e[0] == pytest.approx(
        0.5 * np.linalg.norm(ClosedFormRef(case).displacement(pts, names[0]), axis=1)
    )
    assert np.isnan(reference_error(ClosedFormRef(case), pts, names)).all()  # no estimate: NaN


def test_met_tol_at_by_hand():
    """Per load: largest estimate at the points < tol x largest |u_ref| there."""
    from harness.scoring import met_tol_at

    u_ref = np.array(
        [
            [[3.0, 4.0], [0.0, 1.0]],  # max |u| 5
            [[0.0, 0.0], [0.0, 0.0]],
        ]
    )  # a load that does not move these points
    e = np.array([[4.9e-4, 1e-6], [0.0, 0.0]])
    assert met_tol_at(u_ref, e, 1e-4)  # 4.9e-4 < 5e-4
    assert not met_tol_at(u_ref, np.array([[5.1e-4, 0.0], [0.0, 0.0]]), 1e-4)
    # error where nothing moves
    assert not met_tol_at(u_ref, np.array([[1e-6, 0.0], [1e-9, 0.0]]), 1e-4)
    assert not met_tol_at(u_ref, np.array([[1e-6, np.nan], [0.0, 0.0]]), 1e-4)  # no estimate


class _HandRef:
    """A stand-in reference: u = (1, 0) everywhere, an estimate set by hand per point
    (1e-3 at x < 0.5, near a 'clamped edge', 1e-6 elsewhere) and a whole-body verdict."""

    def __init__(self, met_tol, tol=1e-4):
        import types

        self.case = types.SimpleNamespace(reference=types.SimpleNamespace(tol=tol))
        self.met_tol = met_tol
        self.error_estimate = _Estimate(
            {"a": 1e-3}, lambda p, load: np.where(p[:, 0] < 0.5, 1e-3, 1e-6)
        )

    def displacement(self, points, load):
        return np.tile([1.0, 0.0], (len(points), 1))


@pytest.mark.parametrize("body", [False, True])
def test_ref_met_tol_is_decided_at_the_rows_points(body):
    from harness.scoring import ref_columns

    ref = _HandRef(body)
    far = np.array([[0.6, 0.0], [1.0, 1.0]])  # away from the edge: 1e-6 < 1e-4
    near = np.array([[0.2, 0.0], [1.0, 1.0]])  # one node near it: 1e-3 > 1e-4
    for pts, met in ((far, True), (near, False)):
        u_ref = np.array([ref.displacement(pts, "a")])
        cols = ref_columns(ref, pts, ["a"], u_ref, np.zeros(2, int), (1, 1, 1))
        assert cols["ref_met_tol"] is met and cols["ref_met_tol_body"] is body
        assert ref_status(cols["G_ref"], 1.0, cols["ref_met_tol"]) == (
            "ok" if met else "ref-coarse"
        )
    # a looser tol is met near the edge too
    cols = ref_columns(
        _HandRef(body, tol=2e-3),
        near,
        ["a"],
        np.array([ref.displacement(near, "a")]),
        np.zeros(2, int),
        (1, 1, 1),
    )
    assert cols["ref_met_tol"] is True


# -- the sms stage ----------------------------------------------------------------------------


def _tiny(tmp_path, optimizer='method = "none"', reference=""):
    text = TINY.format(placement="grid", extra='grid = [3, 3]\nstructure = "structure1"')
    text = text.replace('[optimizer]\nmethod = "none"\n', f"[optimizer]\n{optimizer}\n")
    text = text.replace("modes = 0", "modes = 0\n" + reference)
    f = tmp_path / "tiny.toml"
    f.write_text(text)
    return f


def _run_sms(
    tmp_path, monkeypatch, ref_of, optimizer='method = "lbfgs"\noptions = { maxiter = 5 }'
):
    from harness.stages import StageContext
    from harness.stages import sms as stage

    case = load_case(_tiny(tmp_path, optimizer))
    monkeypatch.setattr(stage, "_reference", lambda case, ctx: (ref_of(case), ""))
    return stage.run(case, StageContext(out_dir=tmp_path / "out"))


@pytest.mark.parametrize(
    "eps, met_tol, coarse",
    [(1e-6, True, False), (10.0, True, True), (1e-6, False, False), (1e-3, True, True)],
)
def test_sms_rows_flag_a_coarse_reference(tmp_path, monkeypatch, eps, met_tol, coarse):
    """The estimate is eps |u_ref| at every point, so the reference meets the case's tol
    (1e-4) at the row's nodes exactly when eps < 1e-4, whatever its whole-body verdict
    ``met_tol`` (kept as ref_met_tol_body); eps = 1e-3 misses it with G_ref below 10 % of G."""
    rows = _run_sms(tmp_path, monkeypatch, lambda case: EstimatedRef(case, eps, met_tol))
    assert [r["optimizer"] for r in rows] == ["none"] * 4 + ["lbfgs"]  # baselines and the fit
    for r in rows:
        assert r["G_ref"] == pytest.approx(eps, rel=1e-9)
        assert r["ref_error_max"] == pytest.approx(eps, rel=1e-9)
        assert r["ref_met_tol"] is (eps < 1e-4)
        assert r["ref_met_tol_body"] is met_tol
        assert 1e-4 < r["G_norm_final"] < 50
        assert r["status"] == ("ref-coarse" if coarse else "ok")  # the runner's setdefault keeps it


def test_sms_rows_without_estimate_and_missed_tol_are_ref_coarse(tmp_path, monkeypatch):
    rows = _run_sms(
        tmp_path, monkeypatch, lambda case: EstimatedRef(case, math.nan, False), 'method = "none"'
    )
    assert all(math.isnan(r["G_ref"]) and r["status"] == "ref-coarse" for r in rows)
    # a stand-in that says nothing about its error: no flag, NaN columns
    rows = _run_sms(tmp_path, monkeypatch, ClosedFormRef, 'method = "none"')
    assert all(
        math.isnan(r["G_ref"]) and r["status"] == "ok" and "ref_met_tol" not in r for r in rows
    )


def test_sms_rows_with_the_real_reference(tmp_path, monkeypatch):
    """The FEM reference itself (P1, one refinement, tol 0.05: its shear loads miss the tol,
    so every row is ref-coarse); then its estimate made small and the tol met: ok."""
    import reference
    from harness.stages import StageContext
    from harness.stages import sms as stage

    monkeypatch.setenv("SPRINGBENCH_CACHE", str(tmp_path / "cache"))
    case = load_case(_tiny(tmp_path, reference='element = "P1"\ntol = 0.05\nmax_refine = 1'))
    sol = reference.solve(case, cache=False)
    monkeypatch.setattr(stage, "_reference", lambda case, ctx: (sol, ""))
    rows = stage.run(case, StageContext(out_dir=tmp_path / "out"))
    assert not sol.met_tol
    for r in rows:
        assert np.isfinite(r["G_ref"]) and r["G_ref"] > 0 and r["status"] == "ref-coarse"
        assert r["ref_met_tol"] is False
        assert 0 < r["ref_error_max"] < 2 * max(sol.error_estimate.values())
    # the same reference with a tiny estimate that meets the tol: plain ok
    est = _Estimate({n: 1e-9 for n in sol.error_estimate}, lambda p, load: np.full(len(p), 1e-12))
    monkeypatch.setattr(sol, "error_estimate", est, raising=False)
    monkeypatch.setattr(type(sol), "met_tol", property(lambda self: True))
    rows = stage.run(case, StageContext(out_dir=tmp_path / "out2"))
    assert all(r["status"] == "ok" and r["G_ref"] < 1e-9 for r in rows)


# -- the report -------------------------------------------------------------------------------


def _manifest(folder: Path, case: str, rows, expect=None, seed=0):
    folder.mkdir(parents=True, exist_ok=True)
    m = {
        "case": case,
        "seed": seed,
        "status": "ok",
        "mode": "quick",
        "rows": rows,
        "expect": expect or {},
    }
    (folder / f"result-seed{seed}.json").write_text(json.dumps(m))


def test_ref_coarse_rows_stay_in_summary_flagged(tmp_path):
    suite = tmp_path / "demo"
    common = dict(stage="sms", weights="1:3:15", G_initial=2.0, G_norm_initial=0.4)
    for seed in (0, 1):
        _manifest(
            suite / "good",
            "good",
            [
                dict(
                    common,
                    case="good",
                    model="m[deussen]",
                    seed=seed,
                    status="ok",
                    optimizer="none",
                    G_final=2.0,
                    G_norm_final=0.4,
                    G_ref=1e-4,
                    ref_error_max=2e-4,
                ),
                dict(
                    common,
                    case="good",
                    model="m[deussen]",
                    seed=seed,
                    status="ok",
                    optimizer="sa",
                    objective="G",
                    G_final=1.0,
                    G_norm_final=0.2,
                    G_ref=1e-4,
                    ref_error_max=2e-4,
                ),
                dict(
                    common,
                    case="good",
                    model="m[deussen]",
                    seed=seed,
                    status="ok" if seed else "ref-coarse",
                    optimizer="lbfgs",
                    objective="G",
                    G_final=0.5,
                    G_norm_final=0.1,
                    G_ref=0.02,
                    ref_error_max=0.03,
                ),
            ],
            expect={"G_final": 0.25},
            seed=seed,
        )
    _manifest(
        suite / "coarse",
        "coarse",
        [
            dict(
                common,
                case="coarse",
                model="m[lloyd]",
                seed=0,
                status="ref-coarse",
                optimizer="none",
                G_final=3.0,
                G_norm_final=0.3,
                G_ref=0.25,
                ref_error_max=0.3,
            )
        ],
        expect={"G_final": 1.5},
    )
    _manifest(
        suite / "broken",
        "broken",
        [
            dict(
                case="broken",
                model="",
                stage="sms",
                seed=0,
                status="error",
                G_final=9.0,
                error="boom",
            )
        ],
        expect={"G_final": 1.5},
    )
    out = report.build_suite(suite, figures=False)
    df = out["table"]
    cols = list(df.columns)
    assert cols.index("G_ref") == cols.index("G_norm_final") + 1 and "ref_error_max" in cols
    md = out["md"].read_text()
    table = [line for line in md.splitlines() if line.startswith("| ")]
    head = [c.strip() for c in table[0].strip("|").split("|")]
    assert "G_ref" in head and "G_final" in head and "G_norm_final" in head
    coarse = [line for line in table if "| coarse |" in line]
    assert len(coarse) == 1 and "ref-coarse" in coarse[0] and "0.25 !" in coarse[0]
    assert "2 rows are `ref-coarse`" in md and "1 errors" in md
    # the paper comparison is kept on ref-coarse rows, not on error rows
    row = df[df["case"] == "coarse"].iloc[0]
    assert row["ratio_G_final"] == pytest.approx(2.0) and row["status"] == "ref-coarse"
    assert math.isnan(df[df["case"] == "broken"].iloc[0].get("ratio_G_final", math.nan))
    # the seed means include the ref-coarse row and count it
    seeds = report.seeds_frame(df).set_index("optimizer")
    assert (
        seeds.loc["lbfgs", "G_final_mean"] == pytest.approx(0.5)
        and seeds.loc["lbfgs", "n_ref_coarse"] == 1
    )
    assert (
        seeds.loc["lbfgs", "G_ref_mean"] == pytest.approx(0.02)
        and seeds.loc["sa", "n_ref_coarse"] == 0
    )
    # the optimisers table keeps it, flagged, with G_ref beside G_final
    opt = report.optimizer_frame(df).set_index("optimizer")
    assert opt.loc["lbfgs", "n_seeds"] == 2 and opt.loc["lbfgs", "status"] == "ref-coarse"
    assert opt.loc["sa", "status"] == "ok" and opt.loc["lbfgs", "G_ref"] == pytest.approx(0.02)
    assert (
        "## Optimisers compared" in md and "| ref-coarse |" in md.split("## Optimisers compared")[1]
    )


@pytest.mark.parametrize("eps, body", [(1e-6, False), (1e-3, True)])
def test_score_command_decides_tol_at_the_networks_nodes(tmp_path, eps, body):
    """`springbench score`'s verdict is the rows' one: the estimate eps |u_ref| at the
    network's nodes meets tol = 1e-4 exactly when eps < 1e-4, whatever the whole-body
    verdict (G_ref = eps stays below 10 % of G here, so only the tol decides)."""
    from harness.commands.score import score_table
    from harness.models.sms import build_network

    case = load_case(_tiny(tmp_path))
    net = build_network(case)
    df, sc, status = score_table(net, case, EstimatedRef(case, eps, body))
    assert float(df.iloc[-1]["G_ref"]) == pytest.approx(eps, rel=1e-9) and eps < 0.1 * sc.G_norm
    assert status == ("ok" if eps < 1e-4 else "ref-coarse")
