"""springbench bench heldout judges calibrate, so its own parts are checked here: its P2
truth meets closed forms where P2 is exact, its statics of an exported network equals
springbench's (harness.mechanics.statics on the network read back from the VTU), its
bodies' groups are the ones calibrate reads, and one small study runs end to end."""

import json
import textwrap

import numpy as np
import pytest

from harness import cli
from harness.bench import heldout as H
from harness.bench import heldout_bodies as B
from harness.bench import heldout_judge as J
from harness.registry import BENCHES
from tests.bench.bodies import BAR, L

pytest.importorskip("gmsh")


@pytest.fixture(scope="module")
def bar(tmp_path_factory):
    path = tmp_path_factory.mktemp("bar") / "bar.msh"
    B.make_body(BAR, path, 400)
    return path


@pytest.mark.parametrize("refine", [False, True])
def test_truth_meets_closed_forms(bar, refine):
    """nu = 0, x = 0 clamped: a pull s e_x on x = L gives u = (s x / E, 0, 0); the bar
    hanging under rho g e_x gives u_x = rho g (L x - x^2 / 2) / E (both exact in P2)."""
    points, tets, groups = B.read_body(bar)
    loads = [
        J.Load("pull", ("clamp",), J.constant((1.0, 0, 0))),
        J.Load("hang", ("clamp",), gravity=(1.0, 0, 0)),
    ]
    fem = J.truth(points, tets, groups, loads, nu=0.0, refine=refine)
    x, zero = points[:, 0], np.zeros(len(points))
    exact = {
        "pull": np.c_[x / J.E, zero, zero],
        "hang": np.c_[J.RHO * (L * x - x**2 / 2) / J.E, zero, zero],
    }
    for name, u in exact.items():
        assert np.abs(fem[name][0] - u).max() <= 1e-10 * np.abs(u).max(), name
    assert fem["pull"][1] == pytest.approx(1 / J.E, rel=1e-8)  # the strain peak: s / E everywhere


def test_a_refined_truth_with_a_wrong_solve_stops(bar, monkeypatch):
    """The refined truth's solutions are checked by their residual: a Cholesky that returns
    a wrong solution (here half the right one) stops the study with one line."""
    from harness.linalg import multifrontal

    right = multifrontal.MultifrontalCholesky.solve
    monkeypatch.setattr(multifrontal.MultifrontalCholesky, "solve", lambda s, b: right(s, b) / 2)
    points, tets, groups = B.read_body(bar)
    loads = [J.Load("hang", ("clamp",), gravity=(1.0, 0, 0))]
    with pytest.raises(RuntimeError, match="relative residual"):
        J.truth(points, tets, groups, loads, nu=0.3, refine=True)


def test_bodies_groups_are_what_calibrate_reads(tmp_path):
    from harness.io.meshfile import read_mesh

    for body in B.BODIES:
        path = tmp_path / f"{body.name}.msh"
        n = B.make_body(body, path, 800)
        points, tets, groups = B.read_body(path)
        m = read_mesh(path)
        assert (
            len(tets) == n
            and np.array_equal(m.points, points)
            and np.array_equal(m.cells["tetra"], tets)
        )
        for g in ("clamp", "load"):
            assert np.array_equal(m.groups[g].cells["triangle"], groups[g]), (body.name, g)
            assert len(groups[g]) > 10


def _case(folder, mesh, normal):
    p = folder / "statics.toml"
    hold = '[[loads.case.constraint]]\npart = "{}"\ncomponents = "all"\n'
    p.write_text(
        textwrap.dedent(f"""
        name = "heldout-statics"
        dim = 3
        [body]
        shape = "mesh"
        file = "{mesh}"
        [body.parts]
        clamp = {{ group = "clamp" }}
        load = {{ group = "load" }}
        [material]
        E = 1e5
        nu = 0.3
        density = 1000.0
        [[loads.case]]
        name = "shear"
        [[loads.case.traction]]
        part = "load"
        vector = [0.0, -1.0, 0.0]
        """)
        + hold.format("clamp")
        + textwrap.dedent(f"""
        [[loads.case]]
        name = "twist"
        [[loads.case.traction]]
        part = "load"
        twist = {list(map(float, normal))}
        """)
        + hold.format("clamp")
        + textwrap.dedent("""
        [[loads.case]]
        name = "gravity"
        gravity = [0.0, 0.0, -1.0]
        """)
        + hold.format("clamp")
        + textwrap.dedent("""
        [[loads.case]]
        name = "gravity_2"
        gravity = [0.0, 0.0, -1.0]
        """)
        + hold.format("clamp")
        + hold.format("load")
        + textwrap.dedent("""
        [reference]
        max_refine = 0
        [model]
        kind = "sms"
        placement = "mesh"
        """)
    )
    return p


@pytest.mark.parametrize("model", ["springs", "springs+volume-element", "springs+kn"])
def test_network_statics_equals_springbench(bar, tmp_path, model):
    from scipy.spatial import cKDTree

    from harness.case.reader import load_case
    from harness.export.vtu import read_vtu
    from harness.mechanics import statics

    out = tmp_path / "model.vtu"
    assert (
        cli.main(
            (
                ["calibrate", str(bar), "--E", "1e5", "--nu", "0.3", "--method", "rule"]
                + ["--rule", "lloyd", "--model", model, "--max-refine", "0"]
                + ["--heldout", "none", "--out", str(out)]
            )
        )
        == 0
    )
    data = json.loads(out.with_suffix(".json").read_text())
    points, tets, groups = B.read_body(bar)
    c, n, _ = J.face_frame(points, groups["load"])
    loads = [
        J.Load("shear", ("clamp",), J.constant((0, -1.0, 0))),
        J.Load("twist", ("clamp",), J.twisting(n, c)),
        J.Load("gravity", ("clamp",), gravity=(0, 0, -1.0)),
        J.Load("gravity_2", ("clamp", "load"), gravity=(0, 0, -1.0)),
    ]
    mine = J.model_answers(data, points, groups, loads, {ld.name: 1.0 for ld in loads})
    net, _ = read_vtu(out)
    if model == "springs+volume-element":  # the term as harness.models.volume saves it
        from harness.models import volume

        np.savez(
            tmp_path / "v.npz",
            elements=data["volume_indices"],
            kv=data["volume_stiffness"],
            shared=data["volume_shared"],
        )
        net = volume.load(tmp_path / "v.npz", net)
    if model == "springs+kn":
        from harness.models import kn

        np.savez(
            tmp_path / "kn.npz",
            nodes=data["kn_nodes"],
            V=data["kn_node_volume"],
            springs=data["spring_indices"],
            kv=data["kn_stiffness"],
            shared=data["kn_shared"],
        )
        net = kn.load(tmp_path / "kn.npz", net)
    res = statics.solve(net, load_case(_case(tmp_path, bar, n)))
    order = cKDTree(net.points).query(points)[1]
    for ld in loads:
        theirs = res.displacement(ld.name)[order]
        assert np.abs(mine[ld.name] - theirs).max() <= 1e-10 * np.abs(theirs).max(), ld.name


def test_registered():
    assert BENCHES.target("heldout") == "harness.bench.heldout"


@pytest.mark.slow
def test_small_study_end_to_end(tmp_path):
    """One small body, one nu, calibrate and two rules: every row finite, the
    best rule's ratio 1, the summary and the verdict well formed."""
    import pandas as pd

    body = B.BODIES[0]
    mesh = tmp_path / "bracket.msh"
    B.make_body(body, mesh, 600)
    df = H.summarise(
        pd.DataFrame(
            H.study_one(
                body, mesh, 0.3, tmp_path, rules=("lloyd", "deussen"), extra=("--max-refine", "1")
            )
        )
    )
    per = df[df.load != "geomean"]
    assert (
        len(per) == 3 * 5
        and np.isfinite(per.err).all()
        and (per.err > 0).all()
        and (per.err < 2).all()
    )
    summary = df[(df.load == "geomean") & (df.body == body.name)].set_index("model")
    best = summary.best_rule.iloc[0]
    assert best in ("lloyd", "deussen") and summary.ratio_to_best_rule[best] == pytest.approx(1.0)
    assert df[df.body == "all"].ratio_to_best_rule.iloc[0] == pytest.approx(
        summary.ratio_to_best_rule["calibrate"]
    )
    assert summary.rule["lloyd"] == "lloyd" and summary.seconds["calibrate"] > 0
    # the truth is P2 on the mesh refined once; P2 on the mesh itself differs from it by a
    # small, nonzero amount per load, the largest on each geomean row
    assert ((per.truth_error > 0) & (per.truth_error < 0.1)).all()
    assert summary.truth_error["calibrate"] == pytest.approx(per.truth_error.max())
    assert H.verdict(df).startswith(("PASS", "FAIL")) and len(H.summary_table(df)) == 1
