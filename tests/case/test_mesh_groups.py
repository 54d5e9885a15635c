"""Boundary parts from a mesh's named groups: gmsh physical groups and meshio
point sets read as parts, selecting the same points for the FEM (refined, P2) and the
spring model; a clamped group holds u = 0 in both; a traction on a group carries its
area times the traction, and the FEM's clamp reaction balances it; an unknown group is a
one-line error naming the mesh and the groups it has."""

import textwrap

import meshio
import numpy as np
import pytest

from harness import cli
from harness.case.parts import part_predicate
from harness.case.reader import load_case
from harness.io.mesh_groups import GroupPart, group_predicate
from harness.io.meshfile import read_groups, read_mesh
from tests import meshes

pytest.importorskip("gmsh")
R, L = 0.1, 0.5
T = (0.0, 40.0, -30.0)  # the tip traction (Pa)


@pytest.fixture(scope="module")
def cyl(tmp_path_factory):
    return meshes.cylinder_groups(tmp_path_factory.mktemp("groups"), radius=R, length=L, size=0.05)


def case_file(folder, mesh, parts='clamp = { group = "clamp" }\ntip = { group = "tip" }', extra=""):
    p = folder / "g.toml"
    p.write_text(
        textwrap.dedent(f"""
        name = "groups"
        dim = 3
        [body]
        shape = "mesh"
        file = "{mesh}"
        [body.parts]
        """)
        + parts
        + textwrap.dedent(f"""
        [material]
        E = 1e5
        nu = 0.3
        density = 1000.0
        [[loads.case]]
        name = "pull"
        gravity = [0.0, 0.0, -9.81]
        [[loads.case.constraint]]
        part = "clamp"
        components = "all"
        [[loads.case.traction]]
        part = "tip"
        vector = {list(T)}
        [reference]
        max_refine = 0
        [model]
        kind = "sms"
        placement = "mesh"
        """)
        + extra
    )
    return p


def tip_area(m):
    x = m.points[m.groups["tip"].cells["triangle"]]
    return 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1).sum()


def test_physical_groups_are_read_and_select_their_points(cyl):
    m = read_mesh(cyl)
    assert set(m.groups) == {"clamp", "tip", "side", "body"}
    raw = meshio.read(cyl)
    assert len(m.groups["clamp"].cells["triangle"]) == sum(len(i) for i in raw.cell_sets["clamp"])
    raw.cell_sets = {}  # the same groups from gmsh's physical tags alone
    again = read_groups(raw)
    assert {n: {c: a.tolist() for c, a in g.cells.items()} for n, g in again.items()} == {
        n: {c: a.tolist() for c, a in g.cells.items()} for n, g in m.groups.items()
    }
    tol = 1e-9
    P = m.points
    r = np.hypot(P[:, 1], P[:, 2])
    on = lambda g, x: group_predicate(GroupPart(g, cyl), tol)(np.asarray(x).T)  # noqa: E731
    # by hand: the plane x = 0
    np.testing.assert_array_equal(on("clamp", P), np.abs(P[:, 0]) < 1e-12)
    np.testing.assert_array_equal(on("side", P), np.abs(r - R) < 1e-9)  # the nodes on the circle
    assert on("body", P).all()
    # what refinement and P2 add: mid-edges and centroids of the group's facets are on it,
    # points just inside the body are not
    tri = P[m.groups["side"].cells["triangle"]]
    mids = np.concatenate(
        [(tri[:, i] + tri[:, (i + 1) % 3]) / 2 for i in range(3)] + [tri.mean(axis=1)]
    )
    assert on("side", mids).all()
    inside = mids.copy()
    inside[:, 1:] *= 0.99
    assert not on("side", inside).any()
    face = P[m.groups["tip"].cells["triangle"]].mean(axis=1)
    assert on("tip", face).all() and not on("clamp", face).any()


def test_node_sets_are_groups_with_their_boundary_facets(tmp_path):
    """A meshio point set (e.g. an Abaqus NSET) selects its nodes and the boundary facets
    they span, so a refined mesh's new vertices there belong to it too."""
    g = np.linspace(0.0, 1.0, 3)
    P = np.array(np.meshgrid(g, g, g, indexing="ij")).reshape(3, -1).T
    from scipy.spatial import Delaunay

    tets = Delaunay(P).simplices
    face = np.flatnonzero(P[:, 0] == 0.0)
    mm = meshio.Mesh(P, [("tetra", tets)], point_sets={"left": face})
    groups = read_groups(mm)
    assert set(groups) == {"left"} and sorted(groups["left"].nodes) == sorted(face)
    path = tmp_path / "cube.vtu"
    meshio.write(path, meshio.Mesh(P, [("tetra", tets)]))
    from harness.io.mesh_groups import group_simplices
    from harness.io.meshfile import Mesh

    mesh = Mesh(P, {"tetra": tets}, np.zeros(len(P), int), str(path), groups)
    simp = group_simplices(mesh, "left")
    assert len(simp[3]) == 8  # the face x = 0: 2 x 2 squares, 2 triangles each
    x = np.random.default_rng(0).random((200, 3))
    x[:100, 0] = 0.0  # on the face: selected; off it: not
    from harness.io.mesh_groups import on_simplices

    sel = on_simplices(x, simp[3], 1e-9) | on_simplices(x, simp[1], 1e-9)
    np.testing.assert_array_equal(sel, np.arange(200) < 100)


def test_clamp_and_traction_on_groups_in_fem_and_model(tmp_path, cyl):
    """u = 0 on the clamp group in the FEM (P2, refined once) and the spring model; the
    tip group's traction is T times its area (by hand) in the model's forces and the
    FEM's load vector, and the FEM's reaction on the clamp balances it and the weight."""
    import dataclasses

    import reference
    from harness.case.elasticity import densities, element_stiffness
    from harness.mechanics import statics
    from harness.models.sms import build_network
    from reference.fem import Discretisation
    from reference.mesh import base_mesh
    from reference.problem import body_bbox, fixed_dofs, load_vector, solve_mesh

    c = load_case(case_file(tmp_path, cyl))
    m = read_mesh(cyl)
    P = m.points
    clamp = np.abs(P[:, 0]) < 1e-12  # the face x = 0, by hand
    A = tip_area(m)
    u = reference.solve(c, cache=False).displacement(P, "pull")
    # interpolated
    assert np.abs(u[clamp]).max() <= 1e-12 * np.abs(u).max() and np.abs(u[~clamp]).max() > 1e-6
    net = build_network(c)
    um = statics.solve(net, c).displacement("pull")
    on = np.abs(net.points[:, 0]) < 1e-12
    assert on.sum() == clamp.sum() and np.abs(um[on]).max() == 0.0 and np.abs(um[~on]).max() > 1e-6
    g = np.array([0.0, 0.0, -9.81])
    f = statics.force_vector(net, c, c.loads[0]) - net.masses[:, None] * g
    np.testing.assert_allclose(
        f.sum(axis=0), np.array(T) * A, rtol=1e-12, atol=1e-12 * np.abs(T).max() * A
    )
    assert np.abs(f[net.points[:, 0] < L - 1e-12]).max() == 0.0  # only the tip's nodes carry it
    # FEM (level 0): the load vector, and the clamp's reaction R = K u - F on the fixed dofs
    mesh = base_mesh(c)
    d = Discretisation(mesh, c.reference.cell, c.reference.element)
    cent = d.centroids()
    rho = densities(c.material, cent)
    bbox = body_bbox(c, mesh)
    F = load_vector(d, c, c.loads[0], bbox, rho)
    no_g = load_vector(d, c, dataclasses.replace(c.loads[0], gravity=None), bbox, rho)
    np.testing.assert_allclose(
        no_g.reshape(-1, 3).sum(axis=0),
        np.array(T) * A,
        rtol=1e-10,
        atol=1e-10 * np.abs(T).max() * A,
    )
    fixed = fixed_dofs(d, c, c.loads[0], bbox)
    # refined: the same
    for disc in (d, Discretisation(mesh.refined(), c.reference.cell, c.reference.element)):
        on_face = np.abs(disc.doflocs[0]) < 1e-12  # face, by hand
        assert len(fixed_dofs(disc, c, c.loads[0], bbox)) == 3 * on_face.sum()
        bf = disc.mesh.boundary_facets()
        by_hand = bf[(np.abs(disc.mesh.p[0, disc.mesh.facets[:, bf]] - L) < 1e-12).all(axis=0)]
        np.testing.assert_array_equal(
            disc.part_facets(part_predicate("tip", bbox, c.body.parts)), by_hand
        )
    uf = solve_mesh(c, mesh, disc=d)["pull"]
    assert np.all(uf[fixed] == 0.0)
    K = d.stiffness(element_stiffness(c.material, cent))
    reaction = np.zeros(d.ndof)
    reaction[fixed] = (K @ uf - F)[fixed]
    x = P[m.cells["tetra"]]
    V = np.abs(np.linalg.det(x[:, 1:] - x[:, :1])).sum() / 6  # the mesh's volume, by hand
    total = np.array(T) * A + 1000.0 * V * g
    np.testing.assert_allclose(
        -reaction.reshape(-1, 3).sum(axis=0), total, rtol=1e-8, atol=1e-10 * np.abs(total).max()
    )


def test_unknown_group_is_one_line_error(tmp_path, cyl, capsys):
    p = case_file(tmp_path, cyl, parts='clamp = { group = "nope" }\ntip = { group = "tip" }')
    code = cli.main(["validate", str(p)])
    err = [line for line in capsys.readouterr().err.strip().splitlines() if "g.toml" in line]
    assert code == 2 and len(err) == 1
    assert (
        "body.parts.clamp.group" in err[0]
        and cyl.name in err[0]
        and "body, clamp, side, tip" in err[0]
    )
    box = tmp_path / "box.toml"
    box.write_text(p.read_text().replace('shape = "mesh"', 'shape = "box"\nsize = [1.0, 1.0, 1.0]'))
    code = cli.main(["validate", str(box)])
    err = [line for line in capsys.readouterr().err.strip().splitlines() if "box.toml" in line]
    assert code == 2 and len(err) == 1 and "body.parts.clamp.group" in err[0]
    code = cli.main(
        (
            ["calibrate", str(cyl), "--E", "1e5", "--nu", "0.3", "--clamp", "nope"]
            + ["--out", str(tmp_path / "m.vtu")]
        )
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        code == 2
        and len(err) == 1
        and "--clamp" in err[0]
        and cyl.name in err[0]
        and "clamp, side" in err[0]
    )


def test_scaled_copy_keeps_the_groups(tmp_path, cyl):
    """calibrate --length-unit hands the body over in metres: the copy (meshio would
    write a '.msh' as ANSYS) keeps the gmsh groups, the points scaled."""
    from harness.io.mesh_groups import scaled_copy

    a = read_mesh(cyl)
    b = read_mesh(scaled_copy(cyl, None, 1e-3, tmp_path))
    np.testing.assert_allclose(b.points, 1e-3 * a.points, rtol=1e-15)
    assert set(b.groups) == set(a.groups)
    for name in a.groups:
        for ctype, cells in a.groups[name].cells.items():
            np.testing.assert_array_equal(b.groups[name].cells[ctype], cells)


@pytest.mark.parametrize(
    "traction,dim,field",
    [("twist = [1.0, 0.0, 0.0]", 2, "traction[0].twist"), ("", 3, "traction[0]")],
)
def test_twist_and_empty_tractions_are_one_line_errors(tmp_path, capsys, traction, dim, field):
    p = tmp_path / "t.toml"
    size = "[1.0, 1.0]" if dim == 2 else "[1.0, 1.0, 1.0]"
    p.write_text(
        textwrap.dedent(f"""
        name = "t"
        dim = {dim}
        [body]
        shape = "{"rectangle" if dim == 2 else "box"}"
        size = {size}
        [material]
        E = 1.0
        nu = 0.3
        [[loads.case]]
        name = "turn"
        [[loads.case.constraint]]
        part = "x0"
        [[loads.case.traction]]
        part = "x1"
        """)
        + traction
        + "\n"
    )
    code = cli.main(["validate", str(p)])
    err = [line for line in capsys.readouterr().err.strip().splitlines() if "t.toml" in line]
    assert code == 2 and len(err) == 1 and f"loads.case[0].{field}" in err[0]
