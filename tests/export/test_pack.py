"""Benchmark packs (springbench pack) and scoring any engine's displacements on them
(springbench score --displacements): the pack's loads against totals computed here
(rho g V, self-equilibrated tractions), a round trip, G against numpy, the CI gate's exit
codes, a JUnit report a standard parser reads, one line for every bad input, and the
pack's scores of springbench's own statics against calibrate's own held-out scores."""

import json
from xml.etree import ElementTree as ET

import meshio
import numpy as np
import pytest

from harness import cli
from harness.export.pack import read_pack, write_pack
from tests import meshes
from tests.pack_solve import held_solve

pytest.importorskip("gmsh")
E, NU, RHO = 1e5, 0.3, 1000.0


@pytest.fixture(scope="module")
def packed(tmp_path_factory):
    d = tmp_path_factory.mktemp("pack")
    mesh = meshes.holed_block(d, size=0.09)
    assert (
        cli.main(
            (
                ["pack", str(mesh), "--E", str(E), "--nu", str(NU), "--loads", "all"]
                + ["--density", str(RHO), "--out", str(d / "p")]
            )
        )
        == 0
    )
    return d, mesh, read_pack(d / "p")


def test_pack_loads_carry_the_right_totals(packed):
    d, mesh, pack = packed
    m = meshio.read(mesh)
    tets = m.cells_dict["tetra"]
    e = m.points[tets[:, 1:]] - m.points[tets[:, :1]]
    volume = float(np.abs(np.linalg.det(e)).sum() / 6)
    man = json.loads((d / "p" / "problem.json").read_text())
    assert man["format"] == "springbench-pack" and man["n_nodes"] == len(m.points) == pack.n_nodes
    assert {ld["name"] for ld in man["loads"] if ld["role"] == "heldout"} == {
        "sag",
        "tip",
        "tip2",
        "torsion",
        "bridge",
    }
    for ld in pack.loads:
        total = ld.force.sum(axis=0)
        if ld.gravity is not None and ld.kind == "gravity":  # sag, bridge: m g summed
            assert total == pytest.approx(RHO * volume * ld.gravity, rel=1e-9, abs=1e-12)
        elif ld.kind in ("stress", "linear-stress"):  # self-equilibrated: no net force or moment
            scale = np.abs(ld.force).sum()
            assert np.abs(total).max() <= 1e-9 * scale
            c = pack.points.mean(axis=0)
            moment = np.cross(pack.points - c, ld.force).sum(axis=0)
            assert np.abs(moment).max() <= 1e-9 * scale * np.ptp(pack.points)
        held = np.zeros(pack.points.shape, bool)
        held[ld.held_nodes] = ld.held_components
        # the FEM holds what the pack says
        assert np.abs(ld.u_fem[held]).max() <= 1e-12 * np.abs(ld.u_fem).max()
    assert pack.load("sag").u_fem_error.max() > 0


def test_pack_round_trip_is_exact(packed, tmp_path):
    _, _, pack = packed
    write_pack(pack, tmp_path / "again")
    back = read_pack(tmp_path / "again")
    assert np.array_equal(back.points, pack.points) and back.E == pack.E and back.nu == pack.nu
    for a, b in zip(pack.loads, back.loads):
        for key in ("held_nodes", "held_components", "force", "u_fem", "u_fem_error"):
            assert np.array_equal(
                getattr(a, key), getattr(b, key), equal_nan=key == "u_fem_error"
            ), (a.name, key)


def test_score_gate_junit_and_g_against_numpy(packed, tmp_path, capsys):
    d, _, pack = packed
    rng = np.random.default_rng(0)
    fields = {
        ld.name: ld.u_fem * (1 + 0.05 * rng.standard_normal(ld.u_fem.shape)) for ld in pack.loads
    }
    np.savez(tmp_path / "u.npz", **fields)
    code = cli.main(
        (
            ["score", "--displacements", str(tmp_path / "u.npz"), str(d / "p")]
            + ["--max-g-norm", "0.5", "--max", "tip=0.001"]
            + ["--out", str(tmp_path / "g.csv"), "--junit", str(tmp_path / "j.xml")]
        )
    )
    assert code == 1  # tip misses its own gate
    import pandas as pd

    table = pd.read_csv(tmp_path / "g.csv").set_index("load")
    for ld in pack.loads:
        want = np.linalg.norm(fields[ld.name] - ld.u_fem) / np.linalg.norm(ld.u_fem)
        assert table.loc[ld.name, "G_norm"] == pytest.approx(want, rel=1e-12)
    assert (
        table.loc["tip", "status"] == "miss"
        and (table.drop(index=["tip", "total"]).status != "miss").all()
    )
    root = ET.parse(tmp_path / "j.xml").getroot()
    cases = root.findall(".//testcase")
    assert [c.get("name") for c in cases] == [ld.name for ld in pack.loads]
    assert [c.get("name") for c in cases if c.find("failure") is not None] == ["tip"]
    assert (
        cli.main(
            (
                ["score", "--displacements", str(tmp_path / "u.npz"), str(d / "p")]
                + ["--max-g-norm", "0.5"]
            )
        )
        == 0
    )
    np.savez(tmp_path / "fem.npz", **{ld.name: ld.u_fem for ld in pack.loads})
    assert (
        cli.main(
            (
                ["score", "--displacements", str(tmp_path / "fem.npz"), str(d / "p")]
                + ["--max-g-norm", "0"]
            )
        )
        == 0
    )


@pytest.mark.parametrize(
    "make, flags, says",
    [
        (lambda p: {ld.name: ld.u_fem[:-1] for ld in p.loads}, [], "shape"),
        (
            lambda p: {
                ld.name: np.where(np.arange(len(ld.u_fem))[:, None] == 3, np.nan, ld.u_fem)
                for ld in p.loads
            },
            [],
            "NaN",
        ),
        (
            lambda p: {ld.name: ld.u_fem for ld in p.loads[1:]},
            ["--require-all"],
            "no displacements for load",
        ),
        (
            lambda p: {**{ld.name: ld.u_fem for ld in p.loads}, "nope": p.loads[0].u_fem},
            [],
            "not in the pack",
        ),
        (lambda p: {ld.name: 1000 * ld.u_fem for ld in p.loads}, [], "in mm"),
        (lambda p: {ld.name: ld.u_fem for ld in p.loads}, ["--max", "tip"], "--max"),
        (lambda p: {ld.name: ld.u_fem for ld in p.loads}, ["--max-g-norm", "-1"], "--max-g-norm"),
        (lambda p: {ld.name: ld.u_fem for ld in p.loads}, ["--loads", "sag,nope"], "--loads"),
    ],
)
def test_bad_displacements_are_one_line(packed, tmp_path, capsys, make, flags, says):
    d, _, pack = packed
    np.savez(tmp_path / "u.npz", **make(pack))
    capsys.readouterr()
    assert (
        cli.main(["score", "--displacements", str(tmp_path / "u.npz"), str(d / "p"), *flags]) == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0], err


def test_a_folder_that_is_not_a_pack_is_one_line(tmp_path, capsys):
    np.savez(tmp_path / "u.npz", a=np.zeros((2, 3)))
    assert cli.main(["score", "--displacements", str(tmp_path / "u.npz"), str(tmp_path)]) == 2
    assert "problem.json" in capsys.readouterr().err


@pytest.mark.slow
def test_scoring_springbench_statics_on_a_pack_gives_calibrates_own_heldout_g(packed, tmp_path):
    """Two paths to one number: calibrate's own per-load held-out G of its export, and the
    pack's score of that export's linear statics computed here (K assembled spring by
    spring, the pack's holds and forces)."""
    import scipy.sparse as sp

    d, mesh, pack = packed
    assert (
        cli.main(
            (
                ["calibrate", str(mesh), "--E", str(E), "--nu", str(NU)]
                + ["--density", str(RHO), "--method", "rule", "--rule", "vangelder"]
                + ["--out", str(tmp_path / "m.vtu")]
            )
        )
        == 0
    )
    data = json.loads((tmp_path / "m.json").read_text())
    q = np.asarray(data["particle_q"])
    n = len(q)
    rows, cols, vals = [], [], []
    for (i, j), k in zip(data["spring_indices"], data["spring_stiffness"]):
        b = (q[j] - q[i]) / np.linalg.norm(q[j] - q[i])
        blk = k * np.outer(b, b)
        for a, c, s in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
            for r in range(3):
                rows += [3 * a + r] * 3
                cols += [3 * c + t for t in range(3)]
                vals += list(s * blk[r])
    K = sp.csr_matrix((vals, (rows, cols)), shape=(3 * n, 3 * n))
    fields = {}
    for ld in pack.loads:
        fields[ld.name] = held_solve(K, ld, (n, 3))
    from harness.export.pack_score import score_fields

    got = {r["load"]: r["G_norm"] for r in score_fields(pack, fields)}
    for name, want in data["G_heldout_loads"].items():
        assert got[name] == pytest.approx(want, rel=1e-6), name


def test_a_case_file_with_a_mesh_body_packs_every_load_of_the_case(tmp_path, capsys):
    """The original Bourguignon & Cani cube as a case: the pack holds the case's loads,
    its held-out ones marked, on the mesh's own nodes in the case's units; a box body is
    one line (an engine needs a mesh)."""
    from pathlib import Path

    from harness.case.reader import load_case

    root = Path(__file__).resolve().parents[2]
    case_file = root / "cases" / "bourguignon2000" / "fem_cube333_tetra.toml"
    case = load_case(case_file)
    if not case.body.file or not Path(case.body.file).exists():
        pytest.skip("../shared/reference-data is not beside the repository")
    assert cli.main(["pack", str(case_file), "--out", str(tmp_path / "p")]) == 0
    pack = read_pack(tmp_path / "p")
    assert [ld.name for ld in pack.loads] == [ld.name for ld in case.loads]
    assert pack.meta["load_set"] == "all"  # a case's loads are the user's choice
    assert {ld.name for ld in pack.loads if ld.role == "heldout"} == set(case.heldout)
    assert (pack.E, pack.nu) == (case.material.E, case.material.nu)
    capsys.readouterr()
    assert (
        cli.main(
            [
                "pack",
                str(root / "cases" / "deussen1995" / "sec6_box3d.toml"),
                "--out",
                str(tmp_path / "q"),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "mesh" in err[0] and not (tmp_path / "q").exists()


def _broken(src, dst, edit_manifest=None, edit_load=None):
    """A copy of the pack at ``src`` with its manifest or its first load's arrays edited."""
    import shutil

    shutil.copytree(src, dst)
    man = json.loads((dst / "problem.json").read_text())
    if edit_manifest is not None:
        man = edit_manifest(man)
        (dst / "problem.json").write_text(json.dumps(man))
    if edit_load is not None:
        f = dst / man["loads"][0]["file"]
        z = dict(np.load(f))
        edit_load(z)
        np.savez(f, **z)
    return dst


@pytest.mark.parametrize(
    "name, manifest, load, says",
    [
        ("nojson", lambda m: None, None, "format is None"),
        ("format", lambda m: {**m, "format": "other"}, None, "not 'springbench-pack'"),
        ("version", lambda m: {**m, "format_version": 99}, None, "format_version 99"),
        ("incomplete", lambda m: {k: v for k, v in m.items() if k != "material"}, None, "material"),
        ("nodes", lambda m: {**m, "n_nodes": m["n_nodes"] + 1}, None, "the manifest says"),
        ("shape", None, lambda z: z.update(force=z["force"][:-1]), "force has shape"),
        ("nan", None, lambda z: z["u_fem"].__setitem__((0, 0), np.nan), "u_fem holds NaN"),
        ("held", None, lambda z: z["held_nodes"].__setitem__(0, 10**6), "held_nodes outside"),
        ("gone", None, lambda z: z.pop("u_fem"), "unreadable"),
    ],
)
def test_a_broken_pack_is_one_line_naming_its_file(packed, tmp_path, name, manifest, load, says):
    """Each broken manifest or load array: one SpringbenchError line naming the file and the
    fix (write the pack again)."""
    from harness.errors import SpringbenchError

    d, _, pack = packed
    if name == "nojson":
        (tmp_path / "p").mkdir()
        (tmp_path / "p" / "problem.json").write_text("null")
        broken = tmp_path / "p"
    else:
        broken = _broken(d / "p", tmp_path / "p", manifest, load)
    with pytest.raises(SpringbenchError) as err:
        read_pack(broken)
    line = str(err.value)
    assert says in line and "\n" not in line and str(broken) in line, line
    assert "pack" in line
