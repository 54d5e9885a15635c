"""springbench bench engines: one small study end to end (the coarse beam at nu = 0.3),
checked against what is independent of its bookkeeping: Newton's and MuJoCo's tetrahedra
are two implementations of the same linear P1 model, so their scores agree; springbench's
rule export run in Newton scores what springbench's own statics of that export scores;
the mean rows are the means of the load rows."""

import numpy as np
import pandas as pd
import pytest

from harness.bench import BENCHES
from harness.bench import engines as B
from pack_solve import held_solve

pytest.importorskip("gmsh")


@pytest.mark.slow
def test_one_study_runs_every_engine_and_scores_it(tmp_path):
    pytest.importorskip("newton")
    pytest.importorskip("mujoco")
    assert BENCHES["engines"] == "harness.bench.engines"
    mesh = tmp_path / "beam.msh"
    n = B.make_body(B.BEAM, mesh, 300)
    df = B.summarise(pd.DataFrame(B.study_one(B.BEAM, "coarse", mesh, n, 0.3, tmp_path / "s", budget=2.0)))
    loads = df[df.load != "mean"]
    assert set(loads.engine) == {"newton-tets", "mujoco-flex", "newton-springs"}
    assert (loads.status == "settled").all(), loads[["engine", "model", "load", "status", "note"]]
    own = loads[loads.model == "own (E, nu)"].pivot(index="load", columns="engine", values="G_norm")
    assert np.allclose(own["newton-tets"], own["mujoco-flex"], rtol=0.02), own      # the same P1, two engines
    rule = loads[loads.model.str.startswith("springbench rule")].set_index("load").G_norm
    from harness.export.pack import read_pack
    from harness.export.vtu import read_vtu
    from harness.models.springs import incidence, stiffness_matrix
    pack = read_pack(tmp_path / "s" / "pack")
    net, _ = read_vtu(tmp_path / "s" / "rule.vtu")
    K = stiffness_matrix(incidence(net.points, net.springs), net.k).tocsr()
    for name in B.HELD:                          # linear statics of the export, solved here
        ld = pack.load(name)
        u = held_solve(K, ld, pack.points.shape)
        g = np.linalg.norm(u - ld.u_fem) / np.linalg.norm(ld.u_fem)
        assert rule[name] == pytest.approx(g, rel=0.02, abs=6 * pack.meta["peak_strain"] * g), name
    means = df[df.load == "mean"].set_index(["engine", "model"]).G_norm
    for (engine, model), g in loads.groupby(["engine", "model"]).G_norm:
        assert means[(engine, model)] == pytest.approx(g.mean())
    table = B.summary_table(df)
    assert len(table) == 1 and table.filter(like="newton-tets").iloc[0, 0] == pytest.approx(own["newton-tets"].mean())
