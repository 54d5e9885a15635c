"""The engines suite (cases/engines/, harness/stages/engines.py): its case files are what
their committed generator writes, and one case end to end (the coarse beam at nu = 0.3)
is checked against what is independent of its bookkeeping: Newton's and MuJoCo's
tetrahedra are two implementations of the same linear P1 model, so their scores agree;
springbench's rule export run in Newton scores what the export's own linear statics,
solved here, score; the mean rows are the means of the load rows. An engine that is not
installed leaves rows that say which extra installs it."""

import numpy as np
import pandas as pd
import pytest

from harness.case.reader import load_case
from harness.paths import ROOT
from harness.registry import STAGES
from harness.stages import engines as S
from tests.generator import generator
from tests.pack_solve import held_solve

FOLDER = ROOT / "cases" / "engines"


def test_case_files_are_the_generators_output_and_valid():
    gen = generator("engines")
    assert (
        len(list(FOLDER.glob("*.toml")))
        == len(gen.DESCRIPTIONS) * len(gen.SIZES) * len(gen.NUS)
        == 24
    )
    for body in gen.DESCRIPTIONS:
        tets = []
        for resolution in gen.SIZES:
            for nu in gen.NUS:
                p = FOLDER / f"{gen.case_name(body, resolution, nu)}.toml"
                assert p.read_text() == gen.case_text(body, resolution, nu), p.name
                case = load_case(p)
                assert S.applies(case) and case.material.nu == nu and case.body.file.exists()
                assert load_case(p, "quick").section("model")["exports"] == ("rule",)
            tets.append(S.n_tets(case.body.file))
        assert tets[1] > 2 * tets[0] > 0, body  # two resolutions, the fine one > 2x the tets


@pytest.mark.slow
def test_one_case_runs_every_engine_and_scores_it_as_an_independent_solve(tmp_path):
    pytest.importorskip("newton")
    pytest.importorskip("mujoco")
    assert STAGES.target("engines") == "harness.stages.engines"
    case = load_case(FOLDER / "beam-coarse_nu0.30.toml", "full")
    spec = dict(case.section("model"), engines=("newton-tets", "mujoco-flex"), exports=("rule",))
    df = S.case_rows(case, tmp_path, spec)
    loads = df[df.load != "mean"]
    assert set(loads.engine) == {"newton-tets", "mujoco-flex", "newton-springs", "mujoco-springs"}
    assert (loads.engine_status == "settled").all(), loads[
        ["engine", "model", "load", "engine_status", "note"]
    ]
    own = loads[loads.model == S.OWN].pivot(index="load", columns="engine", values="G_norm")
    # the same P1, two engines
    assert np.allclose(own["newton-tets"], own["mujoco-flex"], rtol=0.02), own
    rules = loads[loads.model.str.startswith("springbench rule")]
    rule = rules.pivot(index="load", columns="engine", values="G_norm")
    from harness.export.pack import read_pack
    from harness.export.vtu import read_vtu
    from harness.models.springs import incidence, stiffness_matrix

    pack = read_pack(tmp_path / "pack")
    net, _ = read_vtu(tmp_path / "exports" / "rule.vtu")
    K = stiffness_matrix(incidence(net.points, net.springs), net.k).tocsr()
    for name in spec["loads"]:  # linear statics of the export, solved here
        ld = pack.load(name)
        u = held_solve(K, ld, pack.points.shape)
        g = np.linalg.norm(u - ld.u_fem) / np.linalg.norm(ld.u_fem)
        for engine in ("newton-springs", "mujoco-springs"):  # the rule export in both
            assert rule[engine][name] == pytest.approx(
                g, rel=0.02, abs=6 * pack.meta["peak_strain"] * g
            ), (engine, name)
    means = df[df.load == "mean"].set_index(["engine", "model"]).G_norm
    for (engine, model), g in loads.groupby(["engine", "model"]).G_norm:
        assert means[(engine, model)] == pytest.approx(g.mean())
    assert set(df.n_tets) == {S.n_tets(case.body.file)} and set(df.body) == {"beam"}


def test_an_engine_not_installed_leaves_rows_naming_the_extra(monkeypatch, tmp_path):
    monkeypatch.setattr(S, "_installed", lambda engine: False)
    calls = []
    monkeypatch.setattr(
        S, "cli", lambda *argv: calls.append(argv[0]) or type("P", (), {"returncode": 0})()
    )
    monkeypatch.setattr(S, "read_pack", lambda folder: None)
    spec = dict(load_case(FOLDER / "beam-coarse_nu0.30.toml").section("model"), loads=("tip",))
    rows = S.study(tmp_path / "m.msh", 1e5, 0.3, 1e3, spec, tmp_path)
    assert calls == ["pack"]  # no export made for an engine that is missing
    assert [(r["engine"], r["engine_status"]) for r in rows] == [
        ("newton-tets", "not-installed"),
        ("mujoco-flex", "not-installed"),
        ("pybullet-fem", "not-installed"),
        ("drake-fem", "not-installed"),
        ("newton-springs", "not-installed"),  # the rule export, in each engine that runs it
        ("mujoco-springs", "not-installed"),
    ]
    rows = S.engine_rows(None, tmp_path, "mujoco-flex", ["tip", "sag"], tmp_path / "run")
    assert [r["load"] for r in rows] == ["tip", "sag"]
    assert all(r["engine_status"] == "not-installed" and '".[engines]"' in r["note"] for r in rows)
    df = S.with_means(
        pd.DataFrame(
            [
                dict(
                    r,
                    engine="mujoco-flex",
                    model=S.OWN,
                    G_norm=np.nan,
                    max_error=np.nan,
                    G_ref=np.nan,
                    steps=np.nan,
                    wall_s=np.nan,
                )
                for r in rows
            ]
        )
    )
    assert df.iloc[-1]["load"] == "mean" and df.iloc[-1]["engine_status"] == "see loads"


def test_the_bench_is_the_suite_with_the_engine_status_as_status(monkeypatch):
    from harness.bench import engines as B
    from harness.registry import BENCHES

    assert BENCHES.target("engines") == "harness.bench.engines"
    seen = []

    def fake(case, scratch, spec=None, status=None):
        seen.append((case.name, spec))
        return pd.DataFrame(
            [
                dict(
                    body="beam",
                    load="mean",
                    engine="e",
                    model="m",
                    G_norm=0.1,
                    n_tets=1,
                    nu=0.3,
                    engine_status="settled",
                )
            ]
        )

    monkeypatch.setattr(B, "case_rows", fake)
    df = B.run(quick=True)
    assert seen == [("beam-coarse_nu0.30", seen[0][1])] and seen[0][1]["budget"] == B.QUICK_BUDGET
    assert list(df.columns) == B.COLUMNS and df.status.tolist() == ["settled"]


def test_an_engine_that_takes_only_some_loads_has_their_mean_and_says_which():
    """Gravity-only engines: the mean row is the mean over the loads they ran (sag 0.4 and
    bridge 0.2: 0.3), settled when those settled, its note naming them; the engine table's
    cell shows them and the finding does not count the loads not run as unsettled."""
    from harness.report.engines import engines_finding, engines_summary

    rows = [
        dict(engine="pybullet-fem", model=S.OWN, load=n, G_norm=g, engine_status=st)
        for n, g, st in (
            ("sag", 0.4, "settled"),
            ("tip", float("nan"), "unsupported-load"),
            ("bridge", 0.2, "settled"),
        )
    ]
    base = dict(body="b", resolution="coarse", n_tets=9, nu=0.3, max_error=0.1, G_ref=0.01)
    df = S.with_means(pd.DataFrame([dict(base, steps=1, wall_s=1.0, note="", **r) for r in rows]))
    mean = df[df.load == "mean"].iloc[0]
    assert mean.G_norm == pytest.approx(0.3) and mean.engine_status == "settled"
    assert mean.note == "the mean over sag, bridge"
    cell = engines_summary(df).iloc[0]["pybullet-fem: own (E, nu)"]
    assert cell == "0.300 (sag, bridge)"
    text = engines_finding(df)
    assert (
        "2 of 2 engine runs settled" in text and "takes the gravity loads only (1 not run)" in text
    )
