"""One load, one clamp, for both systems: calibrate's default clamps and load regions are
end faces (boundary facets at an end of the axis whose outward normals point along it),
or named mesh groups; the springs' nodal forces are the consistent load of the same
traction on the same facets as the FEM's, and the clamp holds the same nodes in both."""

import argparse

import numpy as np
import pytest

from harness.case.default_loads import end_loads
from harness.case.reader import load_case
from harness.errors import CaseError
from harness.io.end_faces import end_facets
from harness.io.meshfile import boundary_facets, read_mesh
from harness.mechanics import statics
from tests import meshes

gmsh = pytest.importorskip("gmsh")

E, NU, RHO = 1e5, 0.3, 1000.0
RO, RI, LEN = 0.1, 0.05, 0.5  # the tube: outer and bore radius, length (along x)


def tube(folder, size=0.035):
    """A hollow cylinder along x (a part with a hole through its ends)."""

    def build(occ):
        a = occ.addCylinder(0, 0, 0, LEN, 0, 0, RO)
        b = occ.addCylinder(-0.1, 0, 0, LEN + 0.2, 0, 0, RI)
        occ.cut([(3, a)], [(3, b)])

    return meshes._mesh(folder / "tube.vtu", build, size, 3)


@pytest.fixture(scope="module")
def bodies(tmp_path_factory):
    d = tmp_path_factory.mktemp("ends")
    return {
        "tube": tube(d),
        "ellipsoid": meshes.ellipsoid(d),
        "holed_plate": meshes.holed_plate(d),
        "groups": meshes.cylinder_groups(d),
    }


def calibrate_case(tmp_path, mesh, groups=False):
    """The case calibrate builds for a mesh (its default end loads, or the groups 'clamp'
    and 'tip'), with the reference on the user's mesh itself (P2, no refinement)."""
    from harness.commands import calibrate as cal
    from harness.commands.calibrate_case import case_text

    m = read_mesh(mesh)
    p = argparse.ArgumentParser()
    cal.add_arguments(p)
    args = p.parse_args(
        (
            [str(mesh), "--E", str(E), "--nu", str(NU), "--density", str(RHO)]
            + ["--method", "rule", "--max-refine", "0"]
            + ["--out", str(tmp_path / "m.vtu")]
        )
    )
    ends = end_loads(m.points, m.cells, *(("clamp", "tip", m.groups) if groups else ()))
    (tmp_path / "c.toml").write_text(case_text(args, m.dim, m.cells, ends=ends))
    return load_case(tmp_path / "c.toml"), m, ends


def fem_load(case, load):
    """The FEM's load vector (ns, dim) and dof locations (ns, dim) on the P2 mesh."""
    from harness.case.elasticity import densities
    from reference.fem import Discretisation
    from reference.mesh import file_mesh
    from reference.problem import body_bbox, load_vector

    sk = file_mesh(case.body, case.reference.cell)
    d = Discretisation(sk, case.reference.cell, "P2")
    F = load_vector(d, case, load, body_bbox(case, sk), densities(case.material, d.centroids()))
    return F.reshape(-1, d.dim), d.doflocs.T, d


def test_an_end_face_is_the_flat_end_without_the_bore_or_the_walls(bodies):
    m = read_mesh(bodies["tube"])
    facets, inside = boundary_facets(m.cells, m.points)
    for side, x0 in ((0, 0.0), (1, LEN)):
        got = end_facets(m.points, facets, inside, 0, side)
        # by coordinates
        flat = [f[np.all(np.abs(m.points[f, 0] - x0) < 1e-9, axis=1)] for f in facets]
        assert sorted(map(tuple, np.sort(got[0], axis=1))) == sorted(
            map(tuple, np.sort(flat[0], axis=1))
        )
        x = m.points[got[0]]
        area = 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1).sum()
        assert area == pytest.approx(np.pi * (RO**2 - RI**2), rel=0.02)  # the annulus, not the disc
        r = np.linalg.norm(x[..., 1:], axis=2)
        assert r.min() == pytest.approx(RI, rel=1e-6) and r.max() == pytest.approx(RO, rel=1e-6)


def test_a_rounded_end_gives_a_cap_of_outward_facing_facets(bodies):
    """The ellipsoid's ends: facets whose analytic outward normal is within 60 degrees of
    the axis (checks the orientation of the mesh's facets independently)."""
    a = np.array([0.3, 0.2, 0.15])
    m = read_mesh(bodies["ellipsoid"])
    facets, inside = boundary_facets(m.cells, m.points)
    for side in (0, 1):
        got = end_facets(m.points, facets, inside, 0, side, band=0.1)
        c = m.points[got[0]].mean(axis=1)
        n = c / a**2
        n /= np.linalg.norm(n, axis=1)[:, None]
        sign = 1 if side else -1
        assert len(got[0]) >= 5 and np.all(sign * n[:, 0] > 0.4)
        x = m.points[:, 0]
        assert np.all(sign * c[:, 0] >= (x.max() if side else -x.min()) - 0.1 * np.ptp(x) - 1e-12)


@pytest.mark.parametrize("body", ["tube", "ellipsoid", "holed_plate", "groups"])
def test_the_springs_forces_are_the_fems_consistent_load(tmp_path, bodies, body):
    """Every traction load of calibrate's held-out set: the springs' nodal forces sum to
    the FEM's integrated traction (P2 load vector, scikit-fem's facet quadrature) to
    1e-12, with the same moment; both equal traction x the tip's area."""
    case, m, ends = calibrate_case(tmp_path, bodies[body], groups=body == "groups")
    from harness.models.sms import build_network

    net = build_network(case)
    for load in case.loads:
        if not load.tractions:
            continue
        f = statics.force_vector(net, case, load)
        F, x, _ = fem_load(case, load)
        scale = np.abs(F).sum(axis=0).max()
        assert np.abs(f.sum(axis=0) - F.sum(axis=0)).max() <= 1e-12 * scale, load.name
        if m.dim == 3:  # sum_a x_a F_a = int x t dA for both: x lies in the P1 and the P2 space
            c = net.points.mean(axis=0)
            assert (
                np.abs(
                    np.cross(net.points - c, f).sum(axis=0) - np.cross(x - c, F).sum(axis=0)
                ).max()
                <= 1e-12 * scale * LEN
            ), load.name
        t = load.tractions[0]
        if t.twist is None and t.part == "tip":
            assert np.linalg.norm(f.sum(axis=0)) == pytest.approx(
                np.linalg.norm(t.vector) * ends.section.tip_area, rel=1e-12
            )


def test_side_states_clamp_and_shear_the_faces_across_the_axis(tmp_path, bodies):
    """The tube (axis x): per other axis b the side state holds b's low end face (its
    facets facing -b on the outer wall, by the analytic normal) and shears the high one
    along each other axis with tau = 2 G eps = E / (1 + nu) 1e-3: the springs' resultant
    is tau x that face's area, the FEM's the same to 1e-12."""
    case, m, ends = calibrate_case(tmp_path, bodies["tube"])
    assert [b for b, *_ in ends.sides] == [1, 2]
    sides = ("train-y-x", "train-y-z", "train-z-x", "train-z-y")
    assert ends.training[-4:] == sides and set(sides) <= set(case.fit_loads)
    from harness.models.sms import build_network

    net = build_network(case)
    facets, inside = boundary_facets(m.cells, m.points)
    by = {l.name: l for l in case.loads}
    tau = E / (1 + NU) * 1e-3
    for name in sides:
        b, c = "xyz".index(name[6]), "xyz".index(name[8])
        band, cos = next((bd, cs) for a, bd, cs in ends.sides if a == b)
        low, high = (end_facets(m.points, facets, inside, b, side, band, cos)[0] for side in (0, 1))
        for face, sign in ((low, -1), (high, 1)):
            centre = m.points[face].mean(axis=1)
            r = np.linalg.norm(centre[:, 1:], axis=1)
            assert len(face) and np.all(sign * centre[:, b] / r > 0.5) and np.all(r > 0.9 * RO)
        held = np.flatnonzero(statics.fixed_mask(net.points, case, by[name]).all(axis=1))
        assert np.array_equal(held, np.unique(low))
        x = m.points[high]
        area = 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1).sum()
        f = statics.force_vector(net, case, by[name]).sum(axis=0)
        want = np.zeros(3)
        want[c] = tau * area
        np.testing.assert_allclose(f, want, rtol=1e-12, atol=1e-12 * tau * area)


def test_the_clamp_holds_the_same_nodes_in_both(tmp_path, bodies):
    """The FEM fixes the P2 dofs of the clamp's facets (vertices and mid-edges), the springs
    the vertices: the same nodes, the face and nothing behind it."""
    case, m, _ = calibrate_case(tmp_path, bodies["tube"])
    from harness.models.sms import build_network
    from reference.fem import Discretisation
    from reference.mesh import file_mesh
    from reference.problem import body_bbox, fixed_dofs

    net = build_network(case)
    load = next(l for l in case.loads if l.name == "tip")
    held = np.flatnonzero(statics.fixed_mask(net.points, case, load).any(axis=1))
    assert np.all(np.abs(net.points[held, 0]) < 1e-9)
    on_face = np.flatnonzero(np.abs(net.points[:, 0]) < 1e-9)
    assert np.array_equal(held, on_face)
    sk = file_mesh(case.body, case.reference.cell)
    d = Discretisation(sk, case.reference.cell, "P2")
    fixed = np.unique(fixed_dofs(d, case, load, body_bbox(case, sk)) // 3)
    assert np.all(np.abs(d.doflocs[0, fixed]) < 1e-9)
    vertex = fixed[fixed < sk.p.shape[1]]
    assert np.allclose(
        sk.p[:, vertex].T[np.lexsort(sk.p[:, vertex])],
        net.points[held][np.lexsort(net.points[held].T)],
    )
    assert len(fixed) > len(vertex)  # and the mid-edge dofs of the face


def test_default_magnitudes_give_a_peak_strain_near_the_target(tmp_path, bodies):
    """The FEM's largest principal strain along the body (away from the clamp's edge,
    where a clamped face is singular) is within a factor 3 of the 1e-3 aimed at."""
    import reference

    case, m, _ = calibrate_case(tmp_path, bodies["tube"])
    sol = reference.solve(case, cache=False)
    vb = sol.vector_basis
    x = np.asarray(vb.global_coordinates())[0]
    keep = np.all((x > 0.15 * LEN) & (x < 0.85 * LEN), axis=1)
    for name in case.heldout:
        g = np.asarray(vb.interpolate(sol._U[name]).grad)  # (3, 3, ne, nq)
        eps = 0.5 * (g + g.transpose(1, 0, 2, 3))
        lam = np.linalg.eigvalsh(eps.transpose(2, 3, 0, 1)[keep])
        peak = np.abs(lam).max()
        assert 3e-4 <= peak <= 3e-3, (name, peak)


def test_end_parts_in_a_case_file_and_their_mistakes(tmp_path, bodies):
    mesh = bodies["tube"]
    base = f'''name = "t"
dim = 3
[body]
shape = "mesh"
file = "{mesh}"
[body.parts]
{{}}
[material]
E = 1e5
nu = 0.3
[[loads.case]]
name = "pull"
[[loads.case.constraint]]
part = "a"
components = "all"
[[loads.case.traction]]
part = "b"
vector = [100.0, 0.0, 0.0]
'''
    ok = base.replace("{}", 'a = { end = "x0" }\nb = { end = "x1", band = 0.1, cos = 0.9 }')
    (tmp_path / "ok.toml").write_text(ok)
    c = load_case(tmp_path / "ok.toml")
    assert (
        c.body.parts["b"].band == 0.1
        and c.body.parts["b"].cos == 0.9
        and c.body.parts["a"].side == 0
    )
    for bad, field in (
        ('a = { end = "x2" }', "body.parts.a.end"),
        ('a = { end = "x0", band = 0 }', "body.parts.a.band"),
        ('a = { end = "x0", cos = 1.5 }', "body.parts.a.cos"),
        ('a = { end = "x0", normal = 1 }', "body.parts.a.normal"),
    ):
        (tmp_path / "bad.toml").write_text(base.replace("{}", bad + '\nb = { end = "x1" }'))
        with pytest.raises(CaseError) as exc:
            load_case(tmp_path / "bad.toml")
        assert exc.value.field == field and "\n" not in str(exc.value)
