"""springbench bench tets judges calibrate's tetrahedral exports, so its own parts are checked
here: the judge's linear tetrahedra equal scikit-fem's P1 (stiffness, tractions, gravity,
solve), an export is read by its tetrahedra whatever their row and corner order and refused
when they are not the body's, a plain export's ratio is exactly 1 through the study's own
wiring, and the summary and verdict on hand-made frames."""

import math

import numpy as np
import pandas as pd
import pytest

from harness.bench import heldout_bodies as B
from harness.bench import heldout_judge as J
from harness.bench import tets as T
from harness.registry import BENCHES
from tests.bench.bodies import BAR

pytest.importorskip("gmsh")


@pytest.fixture(scope="module")
def bar(tmp_path_factory):
    path = tmp_path_factory.mktemp("bar") / "bar.msh"
    B.make_body(BAR, path, 400)
    points, tets, groups = B.read_body(path)
    return path, points, tets, groups


def _materials(m):
    """Three (E, nu) classes by tet index: per-tet arrays that are not constant."""
    c = np.arange(m) % 3
    return np.array([1e5, 3e5, 5e4])[c], np.array([0.3, 0.45, 0.1])[c], c


def _skfem_p1(points, tets, groups, loads, E, nu, c):
    """{load: u (n, 3)} of scikit-fem's ElementTetP1 with the materials of classes c, the
    tractions through FacetBasis on the load facets, gravity its consistent load rho g."""
    from skfem import (
        Basis,
        ElementTetP1,
        ElementVector,
        FacetBasis,
        LinearForm,
        MeshTet,
        asm,
        condense,
        solve,
    )
    from skfem.helpers import dot
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    mesh = MeshTet(np.ascontiguousarray(points.T), np.ascontiguousarray(tets.T))
    e = ElementVector(ElementTetP1())
    basis = Basis(mesh, e, intorder=2)
    K = sum(
        asm(
            linear_elasticity(*lame_parameters(E[c == k][0], nu[c == k][0])),
            Basis(mesh, e, intorder=2, elements=np.flatnonzero(c == k)),
        )
        for k in np.unique(c)
    )
    bf = mesh.boundary_facets()
    keys = J._key(mesh.facets[:, bf].T, len(points))
    out = {}
    for load in loads:
        held = np.unique(np.concatenate([groups[g].ravel() for g in load.held]))
        D = basis.nodal_dofs[:, held].ravel()
        if load.traction is not None:
            facets = bf[np.isin(keys, J._key(groups["load"], len(points)))]
            fb = FacetBasis(mesh, e, facets=facets, intorder=4)
            b = asm(LinearForm(lambda v, w, t=load.traction: dot(t(w.x), v)), fb)
        else:
            g = J.RHO * np.asarray(load.gravity, float)
            b = asm(LinearForm(lambda v, w, g=g: g[0] * v[0] + g[1] * v[1] + g[2] * v[2]), basis)
        u = solve(*condense(K, b, D=D))
        out[load.name] = u[basis.nodal_dofs].T
    return out


def _loads(points, groups):
    return J.study_loads(BAR, points, groups)


def test_judge_p1_equals_scikit_fem(bar):
    """Per-tet materials, every study load: the judge's answer is scikit-fem's P1 to 1e-10."""
    _, points, tets, groups = bar
    loads = _loads(points, groups)
    E, nu, c = _materials(len(tets))
    mine = J.tet_solve(points, tets, groups, loads, {ld.name: 1.0 for ld in loads}, E, nu)
    theirs = _skfem_p1(points, tets, groups, loads, E, nu, c)
    for ld in loads:
        scale = np.abs(theirs[ld.name]).max()
        assert scale > 0 and np.abs(mine[ld.name] - theirs[ld.name]).max() <= 1e-10 * scale, ld


def _export(points, tets, E, nu, seed=0, shuffle=True):
    """A tet export of (E, nu) per body tet: particles, rows and corners shuffled (shuffle)."""
    rng = np.random.default_rng(seed)
    n, m = len(points), len(tets)
    perm = rng.permutation(n) if shuffle else np.arange(n)  # particle p is vertex perm[p]
    particle = np.empty(n, int)
    particle[perm] = np.arange(n)
    rows = rng.permutation(m) if shuffle else np.arange(m)
    t = particle[tets[rows]]
    if shuffle:
        t = np.array([np.roll(r, k) for r, k in zip(t, rng.integers(0, 4, m))])
    E, nu = np.broadcast_to(E, (m,))[rows], np.broadcast_to(nu, (m,))[rows]
    return {
        "particle_q": points[perm].tolist(),
        "tet_indices": t.tolist(),
        "tet_E": E.tolist(),
        "tet_nu": nu.tolist(),
    }


def test_permuted_export_same_answer_mismatched_refused(bar):
    _, points, tets, groups = bar
    loads = _loads(points, groups)
    scale = {ld.name: 1.0 for ld in loads}
    E, nu, _ = _materials(len(tets))
    direct = J.tet_solve(points, tets, groups, loads, scale, E, nu)
    data = _export(points, tets, E, nu)
    Et, nut = J.export_materials(data, points, tets, "x.json")
    assert np.array_equal(Et, E) and np.array_equal(nut, nu)
    u = J.tet_solve(points, tets, groups, loads, scale, Et, nut)
    for ld in loads:
        assert np.abs(u[ld.name] - direct[ld.name]).max() <= 1e-12 * np.abs(direct[ld.name]).max()
    bad = dict(data, tet_indices=data["tet_indices"][:1] + data["tet_indices"][:-1])  # a repeat
    with pytest.raises(ValueError, match=r"x\.json: tet_indices .* not the mesh's"):
        J.export_materials(bad, points, tets, "x.json")
    with pytest.raises(ValueError, match=r"x\.json: tet_indices .* not the mesh's"):
        J.export_materials(dict(data, tet_indices=data["tet_indices"][1:]), points, tets, "x.json")
    with pytest.raises(ValueError, match=r"x\.json: tet_E must hold one finite value per"):
        J.export_materials(dict(data, tet_E=data["tet_E"][1:]), points, tets, "x.json")
    with pytest.raises(ValueError, match=r"x\.json: tet_nu must hold one finite value per"):
        J.export_materials(dict(data, tet_nu=[None] * len(tets)), points, tets, "x.json")
    with pytest.raises(ValueError, match=r"x\.json: no tet_indices"):
        J.export_materials({"particle_q": data["particle_q"]}, points, tets, "x.json")


def test_plain_export_ratio_one_and_failed_run_noted(bar, tmp_path, monkeypatch):
    """Through study_one and summarise: a p1-global export of the plain material has
    ratio_to_plain exactly 1 on every load; a p1 run that fails leaves NaN rows saying why."""
    path, points, tets, _ = bar

    def fake(mesh, out, nu, cache, *extra):
        if "p1" in extra:  # --model p1
            raise RuntimeError("calibrate --model p1: invalid choice")
        data = _export(points, tets, J.E, nu, shuffle=False)
        return dict(data, E_effective=J.E, nu_effective=nu), "rule", "p1", 1.5

    monkeypatch.setattr(T, "calibrate", fake)
    df = T.summarise(pd.DataFrame(T.study_one(BAR, path, 0.3, tmp_path)))
    g = df[df.model == "p1-global"]
    assert len(g) == 5 + 1 + 1 and (g.ratio_to_plain == 1.0).all()
    assert (g[g.body == "bar"].choice == "rule").all() and (g.E_effective.dropna() == J.E).all()
    per = df[(df.model == "plain") & (df.load != "geomean")]
    assert len(per) == 5 and (per.err > 0).all() and (per.err < 1).all()
    p1 = df[(df.model == "p1") & (df.body == "bar")]
    assert p1.err.isna().all() and p1.note.str.contains("invalid choice").all()
    v = T.verdict(df)
    assert v.startswith("FAIL") and "p1 not judged (calibrate --model p1: invalid choice)" in v
    assert "p1-global / plain = 1 overall" in v


def _frame(ratios: dict) -> pd.DataFrame:
    """Per-load rows of two loads per (body, nu): plain err 0.2 and 0.1, each model's err
    that times ratios[(body, nu)][model]."""
    rows = []
    for (body, nu), r in ratios.items():
        for model, k in {"plain": 1.0, **r}.items():
            for load, e in (("a", 0.2), ("b", 0.1)):
                rows.append(
                    dict(body=body, n_tets=10, nu=nu, model=model, choice="fit", load=load,
                         err=k * e, seconds=2.0, truth_seconds=1.0, note="",
                         E_effective=math.nan, nu_effective=math.nan)
                )  # fmt: skip
    return pd.DataFrame(rows)


def test_summarise_and_verdict_by_hand():
    good = {("a", 0.3): {"p1-global": 0.5, "p1": 0.2}, ("b", 0.45): {"p1-global": 0.8, "p1": 0.8}}
    df = T.summarise(_frame(good))
    gm = df[(df.load == "geomean") & (df.body != "all")].set_index(["body", "model"])
    assert gm.err[("a", "plain")] == pytest.approx(math.sqrt(0.2 * 0.1))
    assert gm.ratio_to_plain[("b", "p1-global")] == pytest.approx(0.8)
    overall = df[df.body == "all"].set_index("model")
    assert overall.ratio_to_plain["p1-global"] == pytest.approx(math.sqrt(0.5 * 0.8))  # 0.632
    assert overall.ratio_to_plain["p1"] == pytest.approx(0.4)
    assert overall.ratio_to_plain["plain"] == 1.0 and overall.seconds["p1"] == 4.0
    assert T.verdict(df).startswith("PASS: p1-global / plain = 0.632 overall")
    # p1 overall sqrt(0.2 * 1.1) = 0.469 <= 0.5 but worse than plain on b: FAIL
    worse = {("a", 0.3): {"p1-global": 0.5, "p1": 0.2}, ("b", 0.45): {"p1-global": 0.8, "p1": 1.1}}
    v = T.verdict(T.summarise(_frame(worse)))
    assert v.startswith("FAIL") and "p1 / plain = 0.469 overall" in v and "worst 1.1 on b" in v
    # p1-global 0.8 and 0.7 on each: overall 0.748 > 0.7: FAIL
    over = {("a", 0.3): {"p1-global": 0.8, "p1": 0.2}, ("b", 0.45): {"p1-global": 0.7, "p1": 0.2}}
    assert T.verdict(T.summarise(_frame(over))).startswith("FAIL: p1-global / plain = 0.748")


def test_registered():
    assert BENCHES.target("tets") == "harness.bench.tets"


def test_the_published_table_is_one_row_per_body_and_nu_and_one_overall():
    """bench_table('tets'): the geomean rows as they are stored (the overall row's nu is
    empty), one row each, the ratios and the fitted pair as stored."""
    import pandas as pd

    from harness.report.bench_tables import bench_table

    nan = float("nan")
    rows = [
        dict(
            body="b", n_tets=9, nu=0.3, model="plain", load="geomean", err=0.2, ratio_to_plain=1.0
        ),
        dict(
            body="b",
            n_tets=9,
            nu=0.3,
            model="p1-global",
            load="geomean",
            err=0.1,
            ratio_to_plain=0.5,
            E_effective=9e4,
            nu_effective=0.29,
        ),
        dict(body="b", n_tets=9, nu=0.3, model="p1", load="geomean", err=0.04, ratio_to_plain=0.2),
        dict(body="b", n_tets=9, nu=0.3, model="p1", load="twist", err=0.05, ratio_to_plain=0.25),
    ] + [
        dict(body="all", n_tets=nan, nu=nan, model=m, load="geomean", err=e, ratio_to_plain=r)
        for m, e, r in (("plain", 0.2, 1.0), ("p1-global", 0.1, 0.5), ("p1", 0.04, 0.2))
    ]
    table, note = bench_table("tets", pd.DataFrame(rows))
    assert list(table.body) == ["b", "all"] and "tets.csv" in note
    first = table.iloc[0]
    assert (first["p1-global / plain"], first["p1 / plain"]) == ("0.500", "0.200")
    assert first["p1-global (E', nu')"] == "90,000 Pa, 0.290" and table.iloc[1]["nu"] == ""
