"""Spring/mass systems: builders, stiffness rules, statics (vs an independent dense solve),
loads, mechanisms, modal analysis, VTU files, the build/score CLI and the sms stage.
No FEM reference is needed: a closed-form stand-in replaces it where a test scores."""

import numpy as np
import pytest

from harness import cli
from harness.case.loadsets import basic2d, basic3d
from harness.case.reader import Body, Case, Material, load_case
from harness.errors import ModelError
from harness.export.vtu import read_vtu, write_vtu
from harness.geometry import grid_points
from harness.mechanics import statics
from harness.mechanics.modal import frequencies_arrays
from harness.models.sms import build_network, make_network
from harness.models.stiffness_rules import spring_constants
from harness.models.topology import grid_structure, mesh_edges
from tests.models.springcases import ClosedFormRef, case_file, dense_solve


def test_build_network_from_case(tmp_path):
    case = load_case(case_file(tmp_path))
    net = build_network(case)
    assert (net.n_nodes, net.n_springs) == (9, 20)
    assert net.classes.tolist() == [2, 1, 2, 1, 0, 1, 2, 1, 2]
    assert np.isclose(net.masses.sum(), 4.0) and net.info["mass_residual"] < 1e-12
    assert np.allclose(net.k[net.groups == 0], 100 * 1 / 4)  # Deussen: E s0 / 4
    assert np.allclose(net.k[net.groups == 2], 100 * np.sqrt(2) / 4)
    rnd = load_case(case_file(tmp_path, "lloyd", "n_points = 20\nlloyd_iterations = 3\nseed = 4"))
    a, b = build_network(rnd), build_network(rnd)
    assert np.array_equal(a.points, b.points) and len(a.info["lloyd_std_distance"]) == 4
    assert not np.array_equal(a.points, build_network(rnd, seed=1).points)


def test_stiffness_rule_closed_forms_equilateral_triangle():
    p = np.array([[0, 0], [1, 0], [0.5, np.sqrt(3) / 2]]) * 2.0
    top = mesh_edges({"triangle": np.array([[0, 1, 2]])})
    mat = Material(E=3.0, nu=1 / 3)
    # Lloyd et al.: sqrt(3)/4 E t per triangle (exact at nu = 1/3, any size)
    assert np.allclose(
        spring_constants("lloyd", p, top.springs, top.cells, mat), np.sqrt(3) / 4 * 3.0
    )
    # van Gelder: E |T| / |c|^2 = E sqrt(3)/4 for one equilateral triangle
    assert np.allclose(
        spring_constants("vangelder", p, top.springs, top.cells, mat), np.sqrt(3) / 4 * 3.0
    )
    assert np.allclose(spring_constants("deussen", p, top.springs, top.cells, mat), 3.0 * 2.0 / 4)
    # anisotropy: Deussen's rule uses the modulus along the spring (fibre along x: E_fibre)
    from harness.case.reader import Fibre

    fib = Material(E=1.0, nu=0.3, fibre=Fibre(4.0, 1.0, 0.3, 0.3, 1.0, direction=(1.0, 0.0)))
    g = grid_points([0, 0], [1, 1], (2, 2))
    t = grid_structure((2, 2), "edges")
    k = spring_constants("deussen", g, t.springs, t.cells, fib)
    assert np.allclose(k[t.groups == 0], 4.0 / 4) and np.allclose(k[t.groups == 1], 1.0 / 4)


@pytest.mark.parametrize("dim", [2, 3])
def test_statics_matches_independent_dense_solve(dim):
    rng = np.random.default_rng(dim)
    shape = (4, 3) if dim == 2 else (3, 3, 3)
    hi = np.array([3.0, 2.0, 2.0][:dim])
    p = grid_points(np.zeros(dim), hi, shape)
    inner = np.all((p > 1e-9) & (p < hi - 1e-9), axis=1)
    p[inner] += rng.normal(scale=0.1, size=(inner.sum(), dim))  # an irregular interior
    top = grid_structure(shape, "structure1" if dim == 2 else "edges+face+body")
    k = rng.uniform(0.5, 2.0, len(top.springs))
    case = Case(
        path=None,
        name="t",
        dim=dim,
        body=Body("rectangle" if dim == 2 else "box", (0.0,) * dim, tuple(hi)),
        material=Material(1.0, 0.3),
        loads=basic2d(1.0) if dim == 2 else basic3d(1.0),
        reference=None,
    )
    net = make_network(p, top.springs, k)
    res = statics.solve(net, case)
    for i, load in enumerate(case.loads):
        free, f = statics.load_arrays(net, case, load)
        u = dense_solve(p, top.springs, k, np.flatnonzero(free), f)
        assert np.allclose(res.u[i].ravel(), u, rtol=1e-10, atol=1e-12 * np.abs(u).max())
        # the traction's total force is s times the loaded length / area
        if load.name.startswith("stretch"):
            assert np.isclose(f.sum(), 1.0 * np.prod(hi) / hi["xyz".index(load.name[-1])])


def _measure(points, on_part):
    """Per node, the length (2-D) or area (3-D) of a flat part it carries: the forces of a
    unit traction along x."""
    from harness.case.facet_loads import planar_forces

    return planar_forces(points, on_part, [1.0] + [0.0] * (points.shape[1] - 1))[:, 0]


def test_tractions_tributary_2d_and_3d():
    p = grid_points([0, 0], [4, 2], (5, 3))
    t = _measure(p, lambda x: np.isclose(x[0], 4))
    assert np.allclose(t[np.isclose(p[:, 0], 4)], [0.5, 1.0, 0.5])
    # 3-D, scattered nodes on the face z = 1 of the unit cube: Delaunay area/3, total = area
    rng = np.random.default_rng(0)
    face = np.column_stack([rng.uniform(size=30), rng.uniform(size=30), np.ones(30)])
    corners = np.array([[0, 0, 1], [1, 0, 1], [0, 1, 1], [1, 1, 1.0]])
    q = np.vstack([corners, face, rng.uniform(size=(10, 3)) * [1, 1, 0.9]])
    a = _measure(q, lambda x: np.isclose(x[2], 1))
    assert np.isclose(a.sum(), 1.0) and np.all(a[-10:] == 0)
    from scipy.spatial import Delaunay

    on = np.flatnonzero(np.isclose(q[:, 2], 1))
    tri = on[Delaunay(q[on, :2]).simplices]  # by hand: each triangle's area / 3 to its corners
    e1, e2 = q[tri[:, 1], :2] - q[tri[:, 0], :2], q[tri[:, 2], :2] - q[tri[:, 0], :2]
    hand = np.zeros(len(q))
    np.add.at(
        hand, tri.ravel(), np.repeat(0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) / 3, 3)
    )
    assert np.allclose(a, hand, rtol=0, atol=1e-14)
    # tensor grid face: bilinear tributaries (corner 1/4 h^2, edge 1/2, interior 1)
    g = grid_points([0, 0, 0], [2, 2, 1], (3, 3, 2))
    b = _measure(g, lambda x: np.isclose(x[2], 1))
    assert np.allclose(sorted(b[b > 0]), [0.25] * 4 + [0.5] * 4 + [1.0])


def test_mechanism_and_floating_node_name_the_nodes():
    p = grid_points([0, 0], [2, 2], (3, 3))
    case = Case(
        path=None,
        name="t",
        dim=2,
        body=Body("rectangle", (0.0, 0.0), (2.0, 2.0)),
        material=Material(1.0, 0.3),
        loads=basic2d(1.0),
        reference=None,
    )
    edges = grid_structure((3, 3), "edges")  # squares without diagonals shear freely
    with pytest.raises(ModelError, match="mechanism.*nodes that move freely: .*at \\("):
        statics.solve(
            make_network(p, edges.springs, np.ones(len(edges.springs))), case, ["shear-x"]
        )
    s1 = grid_structure((3, 3), "structure1")
    keep = ~np.any(s1.springs == 4, axis=1)  # node 4 (the centre) loses its springs
    with pytest.raises(ModelError, match="floating nodes without springs: 4 at \\(1, 1\\)"):
        statics.solve(make_network(p, s1.springs[keep], np.ones(keep.sum())), case)
    # a spring with no stiffness left (k -> 0) is a mechanism, not a traceback
    k = np.ones(len(s1.springs))
    k[np.all(np.isin(s1.springs, [0, 1, 3, 4]), axis=1)] = 0
    with pytest.raises(ModelError, match="mechanism"):
        statics.solve(make_network(p, s1.springs, k), case, ["stretch-x"])


def test_modal_closed_forms():
    # one spring, one free dof: f = sqrt(k/m) / (2 pi)
    p = np.array([[0.0, 0], [1.0, 0]])
    f = frequencies_arrays(
        p, np.array([[0, 1]]), [4.0], [1.0, 0.25], np.array([False, False, True, False]), 1
    )
    assert f[0] == pytest.approx(np.sqrt(16.0) / (2 * np.pi))
    # fixed-free chain of 3 equal springs and masses: lambda_j = 4 k/m sin^2((2j-1) pi / 14)
    p = np.array([[0.0, 0], [1, 0], [2, 0], [3, 0]])
    free = np.zeros(8, bool)
    free[[2, 4, 6]] = True
    f = frequencies_arrays(p, np.array([[0, 1], [1, 2], [2, 3]]), [2.0] * 3, [1.0] * 4, free, 3)
    lam = 4 * 2.0 * np.sin((2 * np.arange(1, 4) - 1) * np.pi / 14) ** 2
    assert np.allclose(f, np.sqrt(lam) / (2 * np.pi))
    with pytest.raises(ModelError, match="masses"):
        frequencies_arrays(p, np.array([[0, 1]]), [1.0], [1.0, -1.0, 1, 1], free, 1)


def test_vtu_round_trip(tmp_path):
    case = load_case(case_file(tmp_path))
    net = build_network(case)
    res = statics.solve(net, case)
    path = write_vtu(tmp_path / "m.vtu", net, dict(zip(res.names, res.u)))
    back, disp = read_vtu(path)
    assert back.dim == 2 and np.array_equal(back.springs, net.springs)
    assert np.allclose(back.points, net.points) and np.allclose(back.k, net.k)
    assert np.allclose(back.masses, net.masses) and np.array_equal(back.classes, net.classes)
    assert set(disp) == set(res.names) and np.allclose(disp["shear-x"], res.displacement("shear-x"))
    import meshio

    m = meshio.read(path)
    assert m.cells[0].type == "line" and "stiffness" in m.cell_data and "mass" in m.point_data


def test_build_and_score_cli(tmp_path, monkeypatch, capsys):
    import reference

    f = case_file(tmp_path)
    out = tmp_path / "model.vtu"
    assert cli.main(["build", str(f), "--out", str(out)]) == 0
    monkeypatch.setattr(reference, "solve", lambda case, **kw: ClosedFormRef(case))
    csv = tmp_path / "score.csv"
    assert cli.main(["score", str(out), str(f), "--out", str(csv)]) == 0
    import pandas as pd

    df = pd.read_csv(csv)
    assert df["load"].tolist() == ["stretch-x", "stretch-y", "shear-x", "shear-y", "total"]
    case = load_case(f)
    net = build_network(case)
    from harness.scoring import score

    direct = score(net, case, ClosedFormRef(case))
    assert df["G_1:3:15"].iloc[-1] == pytest.approx(direct.G)
    assert df["G_norm"].iloc[-1] == pytest.approx(direct.G_norm)
    assert "G_1:3:15" in capsys.readouterr().out
    assert cli.main(["score", str(tmp_path / "missing.vtu"), str(f)]) == 2
    assert cli.main(["build", str(f), "--out", str(out), "--stiffness", "nonsense"]) == 2


def test_sms_stage_rows(tmp_path, monkeypatch):
    from harness.stages import StageContext
    from harness.stages import sms as stage

    case = load_case(case_file(tmp_path))
    assert stage.applies(case)
    monkeypatch.setattr(stage, "_reference", lambda case, ctx: (ClosedFormRef(case), ""))
    rows = stage.run(case, StageContext(out_dir=tmp_path / "out"))
    assert [r["stiffness"] for r in rows] == ["deussen", "vangelder", "lloyd", "uniform"]
    need = {
        "case",
        "model",
        "optimizer",
        "n_nodes",
        "n_springs",
        "weights",
        "G_initial",
        "G_final",
        "G_norm_initial",
        "G_norm_final",
        "seconds",
        "seed",
        "paper_G_initial",
        "paper_G_final",
    }
    assert all(need <= set(r) for r in rows)
    assert rows[0]["weights"] == "1:3:15" and rows[0]["optimizer"] == "none"
    assert all(np.isfinite(r["G_final"]) and r["G_final"] > 0 for r in rows)
    assert (tmp_path / "out" / "model-deussen.vtu").exists() and (
        tmp_path / "out" / "deformed-lloyd.npz"
    ).exists()


@pytest.mark.parametrize(
    "dim,nu,structure", [(2, 1 / 3, "structure1"), (3, 0.25, "edges+face+body")]
)
def test_cauchy_rule_reproduces_the_stretch_closed_form(dim, nu, structure):
    """At the Cauchy Poisson ratio the cell-wise Cauchy-Born constants make the grid's
    stretch response the continuum closed form exactly (docs/design.md, "Load sets for boxes")."""
    n = 5 if dim == 2 else 4
    hi = (4.0,) * dim
    p = grid_points(np.zeros(dim), hi, (n,) * dim)
    top = grid_structure((n,) * dim, structure)
    case = Case(
        path=None,
        name="t",
        dim=dim,
        body=Body("rectangle" if dim == 2 else "box", (0.0,) * dim, hi),
        material=Material(3.0, nu),
        loads=(basic2d(0.1) if dim == 2 else basic3d(0.1))[:dim],
        reference=None,
    )
    k = spring_constants("cauchy", p, top.springs, top.cells, case.material)
    net = make_network(p, top.springs, k)
    res = statics.solve(net, case)
    ref = ClosedFormRef(case)
    for name in res.names:
        assert np.allclose(res.displacement(name), ref.displacement(p, name), rtol=0, atol=1e-12)


def test_sms_stage_calls_the_optimiser_contract(tmp_path, monkeypatch):
    """The stage hands FitProblem.from_network plain arrays and re-scores the result."""
    from types import SimpleNamespace

    from harness.stages import StageContext
    from harness.stages import sms as stage

    f = case_file(tmp_path)
    f.write_text(
        f.read_text().replace('method = "none"', 'method = "sa"\noptions = { temperatures = 2 }')
    )
    case = load_case(f)
    seen = {}

    def fake_optimize(problem, method, options, seed, status=None):
        seen.update(method=method, options=options, n=problem.n_springs, blocks=len(problem.blocks))
        k = problem.k0 * 2.0
        return SimpleNamespace(
            k=k,
            G_initial=problem.G(problem.k0),
            G_final=problem.G(k),
            trace=np.array([[0, 1.0], [1, 0.5]]),
            seconds=0.0,
            n_steps=1,
            accepted=1,
        )

    monkeypatch.setattr(stage, "_reference", lambda case, ctx: (ClosedFormRef(case), ""))
    monkeypatch.setattr(stage, "optimize", fake_optimize)
    rows = stage.run(case, StageContext(out_dir=tmp_path / "out"))
    opt = rows[-1]
    assert opt["optimizer"] == "sa" and seen == {
        "method": "sa",
        "options": {"temperatures": 2},
        "n": 20,
        "blocks": 4,
    }
    assert opt["G_initial"] == rows[0]["G_initial"]
    # our own re-score of the returned constants agrees with the problem's G
    # (docs/design.md, "The G criteria", computed twice)
    assert opt["G_final"] == pytest.approx(opt["G_final_optimizer"], rel=1e-9)
    import pandas as pd

    assert list(pd.read_csv(tmp_path / "out" / "trace.csv").columns[:2]) == ["step", "G"]


def test_model_mesh_file_gives_nodes_and_edges(tmp_path):
    import meshio

    p = np.array([[0, 0], [1, 0], [2, 0], [0, 1], [1, 1.2], [2, 1], [0, 2], [1, 2], [2, 2.0]])
    tri = np.array(
        [[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4], [3, 4, 7], [3, 7, 6], [4, 5, 8], [4, 8, 7]]
    )
    meshio.write(
        tmp_path / "net.vtu", meshio.Mesh(np.column_stack([p, np.zeros(9)]), [("triangle", tri)])
    )
    f = case_file(tmp_path, "mesh", 'mesh = "net.vtu"')
    case = load_case(f)
    net = build_network(case, stiffness="vangelder")
    assert net.n_nodes == 9 and net.n_springs == 16
    assert net.classes[4] == 0 and net.classes[0] == 2 and net.classes[1] == 1
    res = statics.solve(net, case)
    assert np.isfinite(res.u).all()
    with pytest.raises(ModelError, match="model.mesh|placement"):
        build_network(load_case(case_file(tmp_path, "mesh", "")))


def test_read_minimal_foreign_vtu(tmp_path):
    import meshio

    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]])
    lines = np.array([[0, 1], [1, 3], [3, 2], [2, 0], [0, 3]])
    meshio.write(
        tmp_path / "f.vtu",
        meshio.Mesh(pts, [("line", lines)], cell_data={"stiffness": [np.arange(1.0, 6)]}),
    )
    net, disp = read_vtu(tmp_path / "f.vtu")
    assert net.dim == 2 and np.allclose(net.masses, 1) and disp == {}
    assert net.classes.tolist() == [2, 2, 2, 2] and np.allclose(net.k, np.arange(1.0, 6))
    meshio.write(tmp_path / "g.vtu", meshio.Mesh(pts, [("line", lines)]))
    from harness.errors import SpringbenchError

    with pytest.raises(SpringbenchError, match="stiffness"):
        read_vtu(tmp_path / "g.vtu")


def test_large_3d_statics_use_the_multifrontal_cholesky_and_still_name_mechanisms():
    """Above MULTIFRONTAL_MIN free dofs a 3-D network is factorised by the multifrontal
    Cholesky: the same displacements as scipy's spsolve (independent), and a mechanism
    is still a ModelError naming nodes, not a traceback."""
    import scipy.sparse.linalg as spla

    from harness.geometry import grid_points
    from harness.models.springs import incidence, stiffness_matrix

    shape = (14, 14, 36)
    pts = grid_points(np.zeros(3), np.array([1.3, 1.3, 3.5]), shape)
    top = grid_structure(shape, "edges+face+body")
    k = np.exp(np.random.default_rng(3).normal(0, 0.3, len(top.springs)))
    free = np.ones(pts.size, bool)
    free[: 3 * shape[0] * shape[1]] = False  # the z = 0 layer (ids: x fastest, z slowest)
    assert np.allclose(pts[~free.reshape(-1, 3)[:, 0], 2], 0.0)
    assert free.sum() >= statics.MULTIFRONTAL_MIN
    f = np.random.default_rng(4).normal(size=pts.size)
    u = statics.solve_arrays(pts, top.springs, k, free, f)
    K = stiffness_matrix(incidence(pts, top.springs), k).tocsc()
    fd = np.flatnonzero(free)
    want = spla.spsolve(K[fd][:, fd], f[fd])
    np.testing.assert_allclose(u[fd], want, rtol=0, atol=1e-9 * np.abs(want).max())
    edges = grid_structure(shape, "edges")  # no diagonals: every cell shears freely
    with pytest.raises(ModelError, match="mechanism"):
        statics.solve_arrays(pts, edges.springs, np.ones(len(edges.springs)), free, f)


def test_cauchy_rule_on_a_tet_mesh_equals_a_cell_by_cell_least_squares():
    """The batched rule against the definition written out cell by cell: per tetrahedron
    the constants k of its six edges minimising |(1/V) sum k L^2 a a^T - C| (minimum norm;
    NNLS where that is negative), summed over the cells sharing an edge, floored."""
    from scipy.optimize import nnls
    from scipy.spatial import Delaunay

    from harness.case.elasticity import element_stiffness
    from harness.models.stiffness_rules import voigt_dyad

    rng = np.random.default_rng(3)
    p = rng.uniform(size=(40, 3))
    tets = Delaunay(p).simplices
    edges = np.unique(
        np.sort(
            np.concatenate(
                [tets[:, [i, j]] for i, j in ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))]
            ),
            axis=1,
        ),
        axis=0,
    )
    mat = Material(1.0, 0.3)
    k = spring_constants("cauchy", p, edges, {"tetra": tets}, mat)
    where = {tuple(e): i for i, e in enumerate(edges)}
    acc = np.zeros(len(edges))
    C = element_stiffness(mat, p[tets].mean(axis=1))
    for e, t in enumerate(tets):
        pairs = [(t[i], t[j]) for i, j in ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))]
        v = np.array([p[b] - p[a] for a, b in pairs])
        L = np.linalg.norm(v, axis=1)
        vol = abs(np.linalg.det(p[t[1:]] - p[t[0]])) / 6
        a = voigt_dyad(v / L[:, None])
        M = np.stack([(L[q] ** 2 * np.outer(a[q], a[q])).ravel() for q in range(6)], axis=1) / vol
        kk = np.linalg.lstsq(M, C[e].ravel(), rcond=None)[0]
        if kk.min() < 0:
            kk = nnls(M, C[e].ravel())[0]
        for (a_, b_), kq in zip(pairs, kk):
            acc[where[tuple(sorted((a_, b_)))]] += kq
    acc = np.maximum(acc, 0.01 * np.median(acc[acc > 0]))
    np.testing.assert_allclose(k, acc, rtol=1e-9, atol=1e-12 * acc.max())


@pytest.mark.parametrize("dim", [2, 3])
def test_solve_all_matches_a_dense_solve_of_each_network(dim, monkeypatch):
    """Several networks on one mesh (the stiffness rules' constants) solved together, each
    constraint set ordered and factorised symbolically once, give each network's own
    dense solve; the multifrontal path (3-D) and SuperLU (2-D) alike."""
    monkeypatch.setattr(statics, "MULTIFRONTAL_MIN", 10)
    rng = np.random.default_rng(5 + dim)
    shape = (4, 3) if dim == 2 else (3, 3, 4)
    hi = np.array([3.0, 2.0, 2.0][:dim])
    p = grid_points(np.zeros(dim), hi, shape)
    top = grid_structure(shape, "structure1" if dim == 2 else "edges+face+body")
    case = Case(
        path=None,
        name="t",
        dim=dim,
        body=Body("rectangle" if dim == 2 else "box", (0.0,) * dim, tuple(hi)),
        material=Material(1.0, 0.3),
        loads=basic2d(1.0) if dim == 2 else basic3d(1.0),
        reference=None,
    )
    ks = [rng.uniform(0.5, 2.0, len(top.springs)) for _ in range(3)]
    results = statics.solve_all([make_network(p, top.springs, k) for k in ks], case)
    assert len(results) == 3
    for k, res in zip(ks, results):
        net = make_network(p, top.springs, k)
        assert res.load_seconds.shape == (len(case.loads),) and np.all(res.load_seconds >= 0)
        for i, load in enumerate(case.loads):
            free, f = statics.load_arrays(net, case, load)
            u = dense_solve(p, top.springs, k, np.flatnonzero(free), f)
            assert np.allclose(res.u[i].ravel(), u, rtol=1e-10, atol=1e-12 * np.abs(u).max())
