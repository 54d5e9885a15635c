"""springbench calibrate with bad flags and bad meshes: each is exit 2 and one line
naming the flag, or the user's mesh file (never calibrate's temporary copy), with the fix;
nothing is written. Every mesh here fails before any FEM solve, so the table is fast."""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np
import pytest

from harness import cli
from tests.commands.inputs import cube_tets
from tests.run.test_robustness import names_a_fix

BASE = "MESH --E 1e5 --nu 0.3 --method rule --out OUT"
FLAG_CASES = [  # (extra argv, text the line must hold)
    ("--seed -1", "--seed"),
    ("--seed x", "--seed"),
    ("--k-ratio 0.5", "--k-ratio"),
    ("--k-ratio nan", "--k-ratio"),
    ("--k-ratio inf", "--k-ratio"),
    ("--prior-weight -1", "--prior-weight"),
    ("--prior-weight nan", "--prior-weight"),
    ("--prior-weight inf", "--prior-weight"),
    ("--prior-weight 0.1", "--prior-weight"),  # --method rule: no prior
    ("--damping-ratio 1", "--damping-ratio"),
    ("--damping-ratio -0.1", "--damping-ratio"),
    ("--damping-ratio nan", "--damping-ratio"),
    ("--E nan", "--E"),
    ("--E -1", "--E"),
    ("--E 0", "--E"),
    ("--E abc", "--E"),
    ("--E 1e308", "--E"),
    ("--E 1e-40", "--E"),
    ("--E inf", "--E"),
    ("--nu 0.5", "--nu"),
    ("--nu -1", "--nu"),
    ("--nu nan", "--nu"),
    ("--nu 0.3.1", "--nu"),
    ("--density inf", "--density"),
    ("--density 0", "--density"),
    ("--density 1e40", "--density"),
    ("--density -1000", "--density"),
    ("--magnitude 0", "--magnitude"),
    ("--magnitude -5", "--magnitude"),
    ("--magnitude 1e300", "--magnitude"),
    ("--length-unit km", "--length-unit"),
    ("--rule foo", "--rule"),
    ("--masses foo", "--masses"),
    ("--method foo", "--method"),
    ("--init foo", "--init"),
    ("--method sa --init equilibrium-gap", "--init"),
    ("--budget 0", "--budget"),
    ("--budget nan", "--budget"),
    ("--tol 0", "--tol"),
    ("--tol nan", "--tol"),
    ("--max-refine -1", "--max-refine"),
    ("--out model.txt", "--out"),
    ("--heldout some", "--heldout"),
    ("--loads all", "--loads"),
    ("--solver lu", "--solver"),
    ("--plane membrane", "--plane"),
    ("--format nosuchformat", "nosuchformat"),
    ("--format bc2000", "cube.vtu"),
    ("--frobnicate", "--frobnicate"),
    ("--peak-strain 0", "--peak-strain"),
    ("--peak-strain nan", "--peak-strain"),
    ("--peak-strain 1", "--peak-strain"),
    ("--peak-strain inf", "--peak-strain"),
    ("--budget inf", "--budget"),
    ("--budget -1", "--budget"),
    ("--tol inf", "--tol"),
    ("--tol 1e-40", "--tol"),
    ("--tol 1", "--tol"),
    ("--tol -1", "--tol"),
    ("--max-refine 1.5", "--max-refine"),
    ("--nu 0.4999999999", "--nu"),
    ("--model foo", "--model"),
    ("--damping-ratio inf", "--damping-ratio"),
    ("--magnitude nan", "--magnitude"),
    ("--magnitude inf", "--magnitude"),
    ("--density nan", "--density"),
    ("--k-ratio -1", "--k-ratio"),
    ("--seed 1.5", "--seed"),
    ("--clamp nosuch", "--clamp"),
    ("--load-region nosuch", "--load-region"),
    ("--clamp x --heldout none", "--clamp"),
    ("--load-region x --heldout none", "--load-region"),
    ("--E", "--E"),
    ("--rule", "--rule"),
    ("--out OUT --out MESH", "--out"),
    ("--prior-weight x", "--prior-weight"),
]
MISSING = [
    ("MESH --nu 0.3 --out OUT", "--E"),
    ("MESH --E 1e5 --out OUT", "--nu"),
    ("MESH --E 1e5 --nu 0.3", "--out"),
    ("--E 1e5 --nu 0.3 --out OUT", "MESH"),
]


def cli_run(argv, capsys):
    try:
        code = cli.main([str(a) for a in argv])
    except SystemExit as exc:  # argparse
        code = exc.code
    err = capsys.readouterr().err
    return code, err, [ln for ln in err.splitlines() if ln.startswith("springbench")]


@pytest.fixture(scope="module")
def cube(tmp_path_factory):
    d = tmp_path_factory.mktemp("mesh")
    pts, tets = cube_tets()
    meshio.write(d / "cube.vtu", meshio.Mesh(pts, [("tetra", tets)]))
    return d / "cube.vtu"


def expand(text: str, mesh: Path, out: Path) -> list[str]:
    return [
        "calibrate",
        *[str(mesh) if a == "MESH" else str(out) if a == "OUT" else a for a in text.split()],
    ]


def one_flag_line(argv, must, folder, capsys):
    code, err, lines = cli_run(argv, capsys)
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert must in lines[0] and names_a_fix(lines[0]), lines[0]
    assert not any(folder.iterdir())  # nothing written


@pytest.mark.parametrize("extra, must", FLAG_CASES, ids=[c for c, _ in FLAG_CASES])
def test_bad_flag_is_one_line(extra, must, cube, tmp_path, capsys):
    one_flag_line(expand(f"{BASE} {extra}", cube, tmp_path / "m.vtu"), must, tmp_path, capsys)


@pytest.mark.parametrize("argv, must", MISSING, ids=[m for _, m in MISSING])
def test_missing_argument_is_one_line(argv, must, cube, tmp_path, capsys):
    one_flag_line(expand(argv, cube, tmp_path / "m.vtu"), must, tmp_path, capsys)


# -- meshes ---------------------------------------------------------------------------------


def _tri_square(n=3):
    g = np.linspace(0.0, 1.0, n + 1)
    pts = np.array([[x, y, 0.0] for y in g for x in g])
    tris = []
    for j in range(n):
        for i in range(n):
            a, b, c, d = (
                j * (n + 1) + i,
                j * (n + 1) + i + 1,
                (j + 1) * (n + 1) + i + 1,
                (j + 1) * (n + 1) + i,
            )
            tris += [[a, b, c], [a, c, d]]
    return pts, np.array(tris)


def _mixed3d():
    """Six tetrahedra of the unit cube and a hexahedron beside it, sharing the face x = 0."""
    pts, tets = cube_tets(1)  # node x + 2 y + 4 z
    layer = np.array([[-1.0, y, z] for z in (0, 1) for y in (0, 1)])  # nodes 8 + y + 2 z
    hexa = np.array([[8, 0, 2, 9, 10, 4, 6, 11]])  # VTK order, x from -1 to 0
    return np.vstack([pts, layer]), [("tetra", tets), ("hexahedron", hexa)]


def meshes():
    """name -> (cells/points writer, text the line must hold). Each writes one file."""
    pts, tets = cube_tets()
    tri_p, tris = _tri_square()
    far = pts * 1e-3 + [1e4, 0.0, 0.0]
    inverted = tets.copy()
    inverted[0, [1, 2]] = inverted[0, [2, 1]]
    flat = np.vstack([tets, [[0, 1, 3, 4]]])  # nodes 0, 1, 3, 4 lie on z = 0
    nan = pts.copy()
    nan[5, 1] = np.nan
    mixed_p, mixed_c = _mixed3d()
    quads = np.array([[0, 1, 5, 4]])  # a quad beside the triangles of the rest
    out_of_range = tets.copy()
    out_of_range[3, 2] = 999
    return {
        "inverted_tet": ((pts, [("tetra", inverted)]), "inverted"),
        "zero_volume_tet": ((pts, [("tetra", flat)]), "degenerate"),
        "floating_node": (
            (np.vstack([pts, [[3.0, 3.0, 3.0]]]), [("tetra", tets)]),
            "belong to no cell",
        ),
        "two_pieces": (
            (np.vstack([pts, pts + 3.0]), [("tetra", np.vstack([tets, tets + len(pts)]))]),
            "disconnected",
        ),
        "mixed_tet_hex": ((mixed_p, mixed_c), "mixes"),
        "mixed_tri_quad": ((tri_p, [("triangle", tris[2:]), ("quad", quads)]), "mixes"),
        "nan_coordinate": ((nan, [("tetra", tets)]), "non-finite"),
        "coordinates_1e200": ((pts * 1e200, [("tetra", tets)]), "too large"),
        "body_1e-40_across": ((pts * 1e-40, [("tetra", tets)]), "too small"),
        "tiny_body_far_away": ((far, [("tetra", tets)]), "from the origin"),
        "duplicate_node": ((np.vstack([pts, pts[:1]]), [("tetra", tets)]), "duplicate nodes"),
        "duplicate_cell": ((pts, [("tetra", np.vstack([tets, tets[:1]]))]), "twice"),
        "index_out_of_range": ((pts, [("tetra", out_of_range)]), "do not exist"),
        "collapsed_cell": ((pts, [("tetra", np.vstack([tets, [[0, 0, 1, 3]]]))]), "repeat a node"),
        "vertices_only": (
            (pts, [("vertex", np.arange(len(pts))[:, None])]),
            "no triangle, quad, tetra",
        ),
        "one_triangle": (
            (np.array([[0.0, 0, 0], [1, 0, 0], [0, 0.5, 0]]), [("triangle", [[0, 1, 2]])]),
            "clamped",
        ),
    }


RAW = {
    "empty": (b"", "empty"),
    "truncated": (None, "cannot read"),
    "not_a_mesh": (b"hello, world\n", "cannot read"),
    "binary_junk": (bytes(range(256)) * 4, "cannot read"),
}
MESH_CASES = (
    sorted(meshes())
    + sorted(RAW)
    + ["missing", "a_folder", "two_pieces_in_mm", "one_triangle_in_mm"]
)


@pytest.fixture(scope="module")
def bad_meshes(cube, tmp_path_factory):
    d = tmp_path_factory.mktemp("bad_meshes")
    out = {}
    for name, ((pts, cells), must) in meshes().items():
        meshio.write(d / f"{name}.vtu", meshio.Mesh(pts, cells))
        out[name] = (d / f"{name}.vtu", must, [])
    for name, (data, must) in RAW.items():
        (d / f"{name}.vtu").write_bytes(cube.read_bytes()[:400] if data is None else data)
        out[name] = (d / f"{name}.vtu", must, [])
    (d / "a_folder.vtu").mkdir()
    out["a_folder"] = (d / "a_folder.vtu", "is a folder", [])
    out["missing"] = (d / "missing.vtu", "no such mesh file", [])
    out["two_pieces_in_mm"] = (out["two_pieces"][0], "disconnected", ["--length-unit", "mm"])
    out["one_triangle_in_mm"] = (out["one_triangle"][0], "clamped", ["--length-unit", "mm"])
    return out


@pytest.mark.parametrize("name", MESH_CASES)
def test_bad_mesh_names_the_users_file(name, bad_meshes, tmp_path, capsys):
    mesh, must, extra = bad_meshes[name]
    code, err, lines = cli_run(
        [
            "calibrate",
            mesh,
            "--E",
            "1e5",
            "--nu",
            "0.3",
            "--method",
            "rule",
            *extra,
            "--out",
            tmp_path / "m.vtu",
        ],
        capsys,
    )
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    line = lines[0]
    assert str(mesh) in line and must in line and names_a_fix(line), line
    # never our temp files
    assert "springbench-calibrate" not in line and "calibrate.toml" not in line, line
    assert not any(tmp_path.iterdir())


def _surface(cube: Path, folder: Path, flat: bool) -> Path:
    """The cube's boundary triangles as an STL: a closed surface in 3-D (an STL as exported
    by CAD), or one face of it moved to z = 1 (a flat mesh outside the plane z = 0)."""
    m = meshio.read(cube)
    t = m.cells_dict["tetra"]
    faces = np.sort(
        np.vstack([t[:, [0, 1, 2]], t[:, [0, 1, 3]], t[:, [0, 2, 3]], t[:, [1, 2, 3]]]), axis=1
    )
    u, c = np.unique(faces, axis=0, return_counts=True)
    tris = u[c == 1]
    if flat:
        tris = tris[np.all(m.points[tris][..., 2] == 1.0, axis=1)]
    used = np.unique(tris)
    remap = np.full(len(m.points), -1)
    remap[used] = np.arange(len(used))
    out = folder / ("flat.stl" if flat else "surface.stl")
    meshio.write(out, meshio.Mesh(m.points[used], [("triangle", remap[tris])]))
    return out


@pytest.mark.parametrize("heldout", ["ends", "none"])
@pytest.mark.parametrize(
    "flat, must", [(False, "no volume cells"), (True, "z = 0")], ids=["surface", "flat_in_z1"]
)
def test_a_surface_mesh_is_one_line(cube, tmp_path_factory, tmp_path, capsys, heldout, flat, must):
    """A surface STL says it has no volume cells, with and without the held-out loads
    (--heldout none once ended in a traceback when the body had no boundary)."""
    stl = _surface(cube, tmp_path_factory.mktemp("stl"), flat)
    code, err, lines = cli_run(
        [
            "calibrate",
            stl,
            "--E",
            "1e5",
            "--nu",
            "0.3",
            "--heldout",
            heldout,
            "--out",
            tmp_path / "m.vtu",
        ],
        capsys,
    )
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert str(stl) in lines[0] and must in lines[0] and names_a_fix(lines[0]), lines[0]
    if not flat:
        assert "tetrahedralise it first, e.g. with gmsh" in lines[0]
    assert not any(tmp_path.iterdir())


def test_the_good_mesh_passes(cube, tmp_path, capsys, monkeypatch):
    """The control: the mesh every flag case uses is fine, so each failure is its flag's."""
    monkeypatch.setenv("SPRINGBENCH_CACHE", str(tmp_path / "cache"))
    code, err, _ = cli_run(expand(BASE + " --heldout none", cube, tmp_path / "m.vtu"), capsys)
    assert code == 0, err
    assert {p.name for p in tmp_path.iterdir()} == {"m.vtu", "m.json", "m.csv", "cache"}


CALIBRATE_CASES = (
    [f"calibrate {c}" for c, _ in FLAG_CASES + MISSING]
    + [f"calibrate mesh {m}" for m in MESH_CASES]
    + ["calibrate mesh surface STL", "calibrate mesh flat in z = 1"]
)
