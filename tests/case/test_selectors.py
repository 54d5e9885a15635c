"""Regions a user picks (harness/case/selectors.py): on a curved gmsh body a box, a sphere and
a node file select exactly the boundary facets an independent predicate picks (the facets are
found here from the tetrahedra, a facet is in when all its vertices are: inside the box, the
sphere, the node set); the same facets reach the case (``[body.parts] name = { facets = ...}``),
the springs' forces and the printed region; the torsion turns about the load region's mean
outward normal; a bad spelling is one line naming the key, the value and the right form."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from harness.case.default_loads import end_loads
from harness.case.selectors import facet_masks, parse
from harness.errors import CaseError, SpringbenchError
from harness.io.meshfile import boundary_facets, read_mesh
from tests import meshes

gmsh = pytest.importorskip("gmsh")

AXES = (0.3, 0.2, 0.15)  # the ellipsoid's half-axes, centred at the origin
BOX = (-0.31, -0.21, -0.16, -0.17, 0.21, 0.16)  # the low end of x
SPHERE = (0.3, 0.0, 0.0, 0.13)  # about the high end of x
TOP = (-0.32, -0.22, 0.09, 0.32, 0.22, 0.16)  # the top cap (z > 0.09): its normal is +z


@pytest.fixture(scope="module")
def body(tmp_path_factory):
    d = tmp_path_factory.mktemp("selectors")
    path = meshes.ellipsoid(d, axes=AXES, size=0.06)
    m = read_mesh(path)
    ids = np.flatnonzero(m.points[:, 1] > 0.12)  # the side y > 0.12, as a user's node file
    lines = ["node"] + [",".join(map(str, ids[i : i + 5])) for i in range(0, len(ids), 5)]
    (d / "side.csv").write_text("\n".join(lines) + "\n")
    return path, m, d / "side.csv", set(ids.tolist())


def surface(tets: np.ndarray) -> np.ndarray:
    """The triangles that belong to one tetrahedron only, from the tetrahedra alone."""
    faces = np.concatenate([tets[:, list(f)] for f in itertools.combinations(range(4), 3)])
    key, count = np.unique(np.sort(faces, axis=1), axis=0, return_counts=True)
    return key[count == 1]


def expected(kind: str, points: np.ndarray, tris: np.ndarray, ids=None) -> set:
    """The test's own predicate: the triangles all of whose vertices are inside."""
    x = points[tris]  # (m, 3, 3)
    if kind == "box":
        lo, hi = np.array(BOX[:3]), np.array(BOX[3:])
        inside = np.all((x >= lo) & (x <= hi), axis=(1, 2))
    elif kind == "sphere":
        inside = np.all(np.linalg.norm(x - np.array(SPHERE[:3]), axis=2) <= SPHERE[3], axis=1)
    else:
        inside = np.isin(tris, sorted(ids)).all(axis=1)
    return set(map(tuple, tris[inside]))


def spelling(kind: str, node_file) -> str:
    numbers = {"box": BOX, "sphere": SPHERE}.get(kind)
    return f"nodes:{node_file}" if numbers is None else f"{kind}:" + ",".join(map(str, numbers))


def raise_it(message, fix):
    raise SpringbenchError(message, field="--clamp", fix=fix)


def picked(masks, facets) -> set:
    return set(map(tuple, np.sort(np.concatenate([f[m] for f, m in zip(facets, masks)]), axis=1)))


@pytest.mark.parametrize("kind", ["box", "sphere", "nodes"])
def test_a_selector_picks_the_facets_of_the_test_predicate(kind, body):
    """The selector's facets are the predicate's, several of them and not the whole surface;
    as a clamp the printed region counts their facets and nodes."""
    path, m, node_file, ids = body
    want = expected(kind, m.points, surface(m.cells["tetra"]), ids)
    assert 10 <= len(want) < len(surface(m.cells["tetra"])) / 3
    sel = parse(spelling(kind, node_file), raise_it, 3)
    facets = boundary_facets(m.cells)
    assert picked(facet_masks(sel, m.points, facets), facets) == want
    e = end_loads(m.points, m.cells, spelling(kind, node_file), None)
    clamp = e.regions[0]
    assert clamp.facets == len(want) and clamp.nodes == len({v for t in want for v in t})
    assert "m^2" in e.describe() and f"{clamp.nodes} nodes" in e.describe()


@pytest.mark.parametrize("kind", ["box", "sphere", "nodes"])
def test_the_case_holds_and_loads_the_same_facets(kind, body, tmp_path):
    """``{ facets = ... }`` in a case file (a node file relative to it): the springs' forces
    of a traction there sit on exactly the predicate's facets' nodes and sum to its area."""
    from harness.case.facet_loads import facet_forces, part_facets
    from harness.case.parts import part_predicate
    from harness.case.reader import load_case

    path, m, node_file, ids = body
    (tmp_path / node_file.name).write_text(node_file.read_text())
    value = spelling(kind, node_file.name)
    case = load_case(write_case(tmp_path, path, value))
    on = part_predicate("held", case.body.bbox(), case.body.parts)
    facets = part_facets(m.points, case, on)
    want = expected(kind, m.points, surface(m.cells["tetra"]), ids)
    assert set(map(tuple, np.sort(np.concatenate(facets), axis=1))) == want
    f = facet_forces(m.points, facets, [0.0, 0.0, 1.0])
    x = m.points[np.array(sorted(want))]
    area = 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1).sum()
    assert set(np.flatnonzero(f[:, 2])) == {v for t in want for v in t}
    assert f[:, 2].sum() == pytest.approx(area, rel=1e-12)
    assert on(m.points.T).sum() == len({v for t in want for v in t})  # no other node


@pytest.mark.parametrize("kind", ["box", "sphere"])
def test_a_node_on_the_edge_is_in_or_out_as_the_predicate_says(kind, body):
    """The edge set 1e-7 m beyond a surface node, then 1e-7 m short of it (well above the
    selector's rounding tolerance, 1e-8 of the body's diagonal): the node's facets come in
    and go out exactly as the test's predicate says."""
    path, m, *_ = body
    tris = surface(m.cells["tetra"])
    x = m.points[np.unique(tris)]
    centre = np.array(SPHERE[:3])
    reach = np.sort(np.linalg.norm(x - centre, axis=1) if kind == "sphere" else x[:, 0])[12]
    facets, got = boundary_facets(m.cells), []
    for eps in (1e-7, -1e-7):
        edge = float(reach + eps)
        if kind == "sphere":
            text, inside = (
                f"sphere:0.3,0,0,{edge!r}",
                lambda p: np.linalg.norm(p - centre, axis=2) <= edge,
            )
        else:
            text, inside = f"box:-1,-1,-1,{edge!r},1,1", lambda p: p[..., 0] <= edge
        want = set(map(tuple, tris[inside(m.points[tris]).all(axis=1)]))
        got.append(picked(facet_masks(parse(text, raise_it, 3), m.points, facets), facets))
        assert got[-1] == want, (text, len(got[-1]), len(want))
    assert got[0] != got[1]  # the node's facets were on the edge


def write_case(folder, mesh, value: str):
    text = f"""name = "sel"
dim = 3
[body]
shape = "mesh"
file = "{mesh}"
[body.parts]
held = {{ facets = "{value}" }}
[material]
E = 1e5
nu = 0.3
[loads]
set = "homogeneous3d"
"""
    (folder / "c.toml").write_text(text)
    return folder / "c.toml"


def test_the_torsion_turns_about_the_load_regions_mean_normal(body):
    """A load region on the top cap twists about +z (its mean outward normal, computed here
    from the triangles' cross products), a default end face about the long axis x."""
    path, m, *_ = body
    e = end_loads(m.points, m.cells, None, "box:" + ",".join(map(str, TOP)))
    tris = np.array(sorted(expected_top(m)))
    x = m.points[tris]
    n = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])  # |n| = 2 area
    n *= np.sign(np.einsum("ij,ij->i", n, x.mean(axis=1)))[:, None]  # outward: from the centre
    normal = n.sum(axis=0) / np.linalg.norm(n.sum(axis=0))
    np.testing.assert_allclose(e.tip_twist, normal, atol=1e-12)
    assert normal[2] > 0.99
    mags = e.magnitudes(1e5, 0.3, 1000.0)
    (torsion,) = [c for c in e.tables(mags)[1] if c["name"] == "torsion"]
    np.testing.assert_allclose(torsion["traction"][0]["twist"], mags["torsion"] * normal)
    assert "mean normal (" in e.describe()
    default = end_loads(m.points, m.cells)
    (torsion,) = [c for c in default.tables(mags)[1] if c["name"] == "torsion"]
    assert default.tip_twist is None and torsion["traction"][0]["twist"][1:] == [0.0, 0.0]


def expected_top(m) -> set:
    tris = surface(m.cells["tetra"])
    x = m.points[tris]
    return set(map(tuple, tris[np.all((x >= TOP[:3]) & (x <= TOP[3:]), axis=(1, 2))]))


def test_2d_box_and_circle_select_edges(tmp_path):
    """In 2-D a box takes 4 numbers and a circle 3; the selected edges are the predicate's."""
    m = read_mesh(meshes.ellipse(tmp_path))
    tri = m.cells["triangle"]
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    key, count = np.unique(np.sort(edges, axis=1), axis=0, return_counts=True)
    outer = key[count == 1]
    facets = boundary_facets(m.cells)
    for text, inside in (
        ("box:-0.5,-0.3,-0.2,0.3", lambda x: np.all((x >= [-0.5, -0.3]) & (x <= [-0.2, 0.3]), 2)),
        ("sphere:0.4,0,0.15", lambda x: np.linalg.norm(x - [0.4, 0.0], axis=2) <= 0.15),
    ):
        want = set(map(tuple, outer[inside(m.points[outer]).all(axis=1)]))
        got = picked(facet_masks(parse(text, raise_it, 2), m.points, facets), facets)
        assert len(want) >= 3 and got == want, text


BAD = [  # (spelling, text the one line must hold)
    ("box:0,0,0,1,1", "has 5 numbers, a 3-D box 6"),
    ("box:1,0,0,0,1,1", "minimum above its maximum"),
    ("box:0,0,0,a,1,1", "is not a list of numbers"),
    ("box:nan,0,0,1,1,1", "is not a list of numbers"),
    ("sphere:0,0,0,-1", "radius that is not positive"),
    ("sphere:0,0,1", "has 3 numbers, a 3-D sphere 4"),
    ("nodes:no_such.txt", "names no such file"),
    ("nodes:words.txt", "line 3: 'x' is not a node id"),
    ("nodes:far.txt", "node id 100000 is not a node of the mesh"),
    ("box:5,5,5,6,6,6", "holds no boundary facet"),
]


@pytest.mark.parametrize("value, must", BAD, ids=[b for b, _ in BAD])
def test_a_bad_spelling_is_one_line_naming_flag_value_and_form(value, must, body, tmp_path):
    """calibrate's --load-region and a case file's facets key: the line names where, the value
    and the right form."""
    from harness.case.reader import load_case

    path, *_ = body
    (tmp_path / "words.txt").write_text("0\n1,2\n3, x\n")
    (tmp_path / "far.txt").write_text("0\n100000\n")
    form = {"box": "box:XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX", "sphere": "sphere:X,Y,Z,R"}
    form = form.get(value.split(":")[0], "nodes:FILE of node ids, 0-based")
    with pytest.raises(CaseError) as err:
        load_case(write_case(tmp_path, path, value))
    line = str(err.value)
    assert "body.parts.held.facets" in line and must in line and form in line, line
    assert "\n" not in line
    argv = ["calibrate", str(path), "--E", "1e5", "--nu", "0.3", "--method", "rule"]
    out = tmp_path / "m.vtu"
    value = value.replace("nodes:", f"nodes:{tmp_path}/")
    with pytest.raises(SpringbenchError) as err:  # the command line prints it as one line
        run_calibrate(argv + ["--load-region", value], out)
    line = str(err.value)
    assert "--load-region" in line and value in line and must in line and form in line, line
    assert not out.exists()


def run_calibrate(argv, out):
    from harness.cli import build_parser

    args = build_parser().parse_args(argv + ["--out", str(out)])
    return args._main(args)


def test_an_engines_case_spells_its_regions_as_the_flags_do(body, tmp_path):
    """``[model] clamp`` of an engines case (passed to pack and calibrate) is read as a
    spelling: a box of the wrong count is one line naming model.clamp and the form."""
    from harness.case.reader import load_case

    path, *_ = body
    text = write_case(tmp_path, path, "box:-1,-1,-1,0,1,1").read_text()
    engines = '[model]\nkind = "engines"\nclamp = "{}"\nload_region = "sphere:0.3,0,0,0.1"\n'
    (tmp_path / "ok.toml").write_text(text + engines.format("box:-1,-1,-1,0,1,1"))
    assert load_case(tmp_path / "ok.toml").section("model")["clamp"] == "box:-1,-1,-1,0,1,1"
    (tmp_path / "bad.toml").write_text(text + engines.format("box:1,2"))
    with pytest.raises(CaseError) as err:
        load_case(tmp_path / "bad.toml")
    assert "model.clamp" in str(err.value) and "box:XMIN,YMIN,ZMIN" in str(err.value)
