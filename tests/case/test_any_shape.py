"""Loads and masses for bodies that are not boxes: the homogeneous stress
states on gmsh meshes (cylinder, ellipsoid, holed block, holed plate), their closed
form, their nodal forces, lumped masses, the held-out end loads."""

import signal
import textwrap
from pathlib import Path

import meshio
import numpy as np
import pytest
import skfem

import reference
from harness.case.elasticity import isotropic_compliance, plane
from harness.case.linear_states import linear_closed_form as homogeneous_closed_form
from harness.case.loadsets import ANCHORS, stress_tensor
from harness.case.reader import load_case
from harness.errors import CaseError
from harness.io.meshfile import boundary_facets, read_mesh
from tests import meshes

gmsh = pytest.importorskip("gmsh")


@pytest.fixture(scope="module")
def bodies(tmp_path_factory):
    d = tmp_path_factory.mktemp("bodies")
    return {
        "cylinder": meshes.cylinder(d),
        "ellipsoid": meshes.ellipsoid(d),
        "holed_block": meshes.holed_block(d),
        "holed_plate": meshes.holed_plate(d),
    }


def mesh_case(tmp_path, mesh, dim, nu=0.45, loads="", extra=""):
    p = tmp_path / "c.toml"
    p.write_text(
        textwrap.dedent(f"""
        name = "h"
        dim = {dim}
        [body]
        shape = "mesh"
        file = "{mesh}"
        {extra}
        [material]
        E = 1e5
        nu = {nu}
        density = 1000.0
        [loads]
        set = "homogeneous{dim}d"
        magnitude = 100.0
        """)
        + textwrap.dedent(loads)
        + "[reference]\nmax_refine = 0\n"
    )
    return load_case(p)


def compliance(case):
    S = isotropic_compliance(case.material.E, case.material.nu)
    if case.dim == 2:
        return np.linalg.inv(plane(np.linalg.inv(S)[None], "stress")[0])
    return S


@pytest.mark.parametrize("name,nu", [("cylinder", 0.45), ("holed_plate", 0.3), ("ellipsoid", 0.49)])
def test_fem_meets_the_closed_form_on_curved_meshes(tmp_path, bodies, name, nu, monkeypatch):
    """A real FEM solve (the closed-form shortcut of reference/problem.py switched off)
    meets the closed form: what the shortcut relies on."""
    import reference.problem

    monkeypatch.setattr(reference.problem, "homogeneous_field", lambda *a: None)
    dim = 2 if name == "holed_plate" else 3
    case = mesh_case(tmp_path, bodies[name], dim, nu)
    assert [l.name for l in case.loads] == (
        ["sxx", "syy", "sxy"] if dim == 2 else ["sxx", "syy", "szz", "syz", "sxz", "sxy"]
    )
    sol = reference.solve(case, cache=False)
    anchors = np.array([case.body.parts[a][0] for a in ANCHORS[:dim]])
    x = sol.disc.doflocs.T
    for load in case.loads:
        want = homogeneous_closed_form(load, x, compliance(case), anchors)
        got = sol.nodal(load.name).reshape(-1, dim)
        assert np.abs(got - want).max() <= 1e-10 * np.abs(want).max(), load.name


def test_the_reference_takes_the_closed_form_only_where_it_is_exact(tmp_path, bodies):
    """Homogeneous loads on one elastic tensor: the reference returns the closed form
    without a solve (no solver record), equal to the solved field; with a stiffer region
    the field is not linear, so it is solved."""
    case = mesh_case(tmp_path, bodies["holed_block"], 3)
    sol = reference.solve(case, cache=False)
    assert sol.solver == []
    import dataclasses

    from harness.case.reader import Region

    stiff = dataclasses.replace(
        case,
        material=dataclasses.replace(
            case.material, regions=(Region((0.0, 0.0, 0.0), (0.2, 0.3, 0.2), 3e5),)
        ),
    )
    solved = reference.solve(stiff, cache=False)
    assert len(solved.solver) == 1  # the six loads share the anchors: one factorisation
    anchors = np.array([case.body.parts[a][0] for a in ANCHORS])
    x = solved.disc.doflocs.T
    want = homogeneous_closed_form(case.loads[0], x, compliance(case), anchors)
    got = solved.nodal("sxx").reshape(-1, 3)
    assert np.abs(got - want).max() > 1e-3 * np.abs(want).max()


def test_anchor_constraints_remove_exactly_the_rigid_motions(tmp_path, bodies):
    case = mesh_case(tmp_path, bodies["holed_block"], 3)
    cons = case.loads[0].constraints
    assert [len(c.components) for c in cons] == [3, 2, 1]
    pts = np.array([case.body.parts[a][0] for a in ANCHORS])
    # rigid motions a + w x x restricted to the constrained components: full rank 6
    rows = []
    for c, x in zip(cons, pts):
        R = np.hstack([np.eye(3), [[0, x[2], -x[1]], [-x[2], 0, x[0]], [x[1], -x[0], 0]]])
        rows += [R[k] for k in c.components]
    assert np.linalg.matrix_rank(np.array(rows)) == 6
    m = read_mesh(bodies["holed_block"])
    on_surface = np.unique(np.concatenate([f.ravel() for f in boundary_facets(m.cells)]))
    for p in pts:  # anchors are boundary vertices of the mesh
        assert np.min(np.linalg.norm(m.points[on_surface] - p, axis=1)) == 0.0


@pytest.mark.parametrize("name", ["holed_block", "holed_plate"])
def test_nodal_forces_of_a_stress_are_the_p1_consistent_load(tmp_path, bodies, name):
    """statics.stress_forces against scikit-fem's P1 facet assembly of sigma . n (an
    independent code path): equal for flat facets, and self-equilibrated."""
    from harness.mechanics.statics import stress_forces

    dim = 2 if name == "holed_plate" else 3
    case = mesh_case(tmp_path, bodies[name], dim)
    m = read_mesh(bodies[name])
    voigt = (3.0, -1.0, 0.5) if dim == 2 else (3.0, -1.0, 2.0, 0.7, -0.4, 0.5)
    f = stress_forces(m.points, case, voigt)
    sk = (skfem.MeshTri if dim == 2 else skfem.MeshTet)(
        m.points.T, m.cells["triangle" if dim == 2 else "tetra"].T
    )
    fb = skfem.FacetBasis(
        sk, skfem.ElementVector(skfem.ElementTriP1() if dim == 2 else skfem.ElementTetP1())
    )
    sig = stress_tensor(voigt)
    F = skfem.asm(
        skfem.LinearForm(
            lambda v, w: sum(v[i] * sum(sig[i, j] * w.n[j] for j in range(dim)) for i in range(dim))
        ),
        fb,
    )
    np.testing.assert_allclose(f.ravel(), F, atol=1e-12 * np.abs(F).max())
    assert np.abs(f.sum(axis=0)).max() <= 1e-12 * np.abs(f).sum()
    if dim == 3:
        assert np.abs(np.cross(m.points, f).sum(axis=0)).max() <= 1e-12 * np.abs(f).sum()


def test_lumped_masses_are_positive_and_carry_the_body(tmp_path, bodies):
    from harness.geometry.bodies import mesh_body
    from harness.models.masses import compute_masses

    m = read_mesh(bodies["cylinder"])
    case = mesh_case(tmp_path, bodies["cylinder"], 3)
    r = compute_masses("lumped", m.points, mesh_body(m.points, m.cells), case.material)
    p = m.points[m.cells["tetra"]]
    vol = (
        np.abs(
            np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0])
        )
        / 6
    )
    assert r.n_negative == 0 and r.masses.min() > 0
    assert r.masses.sum() == pytest.approx(1000.0 * vol.sum(), rel=1e-12)
    one = compute_masses(
        "lumped", p[0], mesh_body(p[0], {"tetra": np.array([[0, 1, 2, 3]])}), case.material
    )
    # by hand: rho V / 4
    np.testing.assert_allclose(one.masses, np.full(4, 1000.0 * vol[0] / 4), rtol=1e-12)
    moments = compute_masses("moments", m.points, mesh_body(m.points, m.cells), case.material)
    assert moments.n_negative > 0  # why lumped is calibrate's default


def test_end_loads_clamp_the_low_end_of_the_longest_axis(tmp_path, bodies):
    from harness.case.default_loads import end_loads
    from harness.case.regions import SHARE
    from harness.io.end_faces import end_facets

    m = read_mesh(bodies["cylinder"])  # along x, length 0.5, radius 0.1
    e = end_loads(m.points, m.cells)
    assert e.axis == 0 and e.across in (1, 2) and e.band == pytest.approx(0.05) and e.cos == 0.5
    # a 2-D apex end: no face looks along -x, so any facet that faces -x, the band grown
    # until the two sides hold SHARE of the mean width (0.3): at x >= SHARE * 0.3 / 0.6
    m = read_mesh(meshes.wedge(tmp_path))
    e = end_loads(m.points, m.cells)
    assert e.axis == 0 and e.across == 1 and e.cos == 0.0
    assert e.band == pytest.approx(0.05 * 1.5**4)  # the first band from 5 % past 0.25
    facets, inside = boundary_facets(m.cells, m.points)
    held = np.unique(
        np.concatenate(
            [f.ravel() for f in end_facets(m.points, facets, inside, 0, 0, e.band, e.cos)]
        )
    )
    x = m.points[held]
    assert np.all(x[:, 0] <= e.band + 0.1 + 1e-12)  # the two sides at the apex
    assert np.ptp(x[:, 1]) >= SHARE * 0.3 and e.regions[0].share >= SHARE
    # and no face
    assert not any(len(f) for f in end_facets(m.points, facets, inside, 0, 0, 0.5, 0.5))


def test_heldout_keys_are_checked(tmp_path, bodies):
    good = (
        '[[loads.case]]\nname = "pull"\ngravity = [0.0, 0.0, -9.81]\n'  # a load of zero is an error
        '[[loads.case.constraint]]\npart = "anchor-a"\ncomponents = "all"\n'
    )
    with pytest.raises(CaseError, match="no load case 'nope'"):
        mesh_case(tmp_path, bodies["cylinder"], 3, loads='heldout = ["nope"]\n')
    with pytest.raises(CaseError, match="nothing to fit"):
        mesh_case(tmp_path, bodies["cylinder"], 3, loads="fit = []\n")
    with pytest.raises(CaseError, match="in both"):
        mesh_case(tmp_path, bodies["cylinder"], 3, loads='fit = ["sxx"]\nheldout = ["sxx"]\n')
    case = mesh_case(tmp_path, bodies["cylinder"], 3, loads='fit = ["sxx", "syy"]\n' + good)
    assert case.fit_loads == ("sxx", "syy") and "pull" in case.heldout and "szz" in case.heldout
    with pytest.raises(CaseError, match="reserved"):
        mesh_case(
            tmp_path,
            bodies["cylinder"],
            3,
            extra="parts = { anchor-a = { box = [[0, 0, 0], [1, 1, 1]] } }",
        )


def test_validation_loads_are_neither_fitted_nor_held_out(tmp_path, bodies):
    """[loads] validation: named loads, never fitted, never held out, in no other list."""
    cyl = bodies["cylinder"]
    with pytest.raises(CaseError, match="no load case 'nope'") as e:
        mesh_case(tmp_path, cyl, 3, loads='validation = ["nope"]\n')
    assert e.value.field == "loads.validation"
    with pytest.raises(CaseError, match="in both validation and heldout"):
        mesh_case(tmp_path, cyl, 3, loads='heldout = ["sxx"]\nvalidation = ["sxx"]\n')
    with pytest.raises(CaseError, match="in both validation and fit"):
        mesh_case(tmp_path, cyl, 3, loads='fit = ["sxx"]\nvalidation = ["sxx"]\n')
    case = mesh_case(tmp_path, cyl, 3, loads='fit = ["sxx"]\nvalidation = ["syy"]\n')
    assert (case.fit_loads, case.validation) == (("sxx",), ("syy",))
    assert "syy" not in case.heldout and "szz" in case.heldout
    case = mesh_case(tmp_path, cyl, 3, loads='heldout = ["sxx"]\nvalidation = ["syy"]\n')
    assert "syy" not in case.fit_loads and "szz" in case.fit_loads
    with pytest.raises(CaseError, match="in neither"):  # fit and heldout still cover the rest
        mesh_case(
            tmp_path,
            cyl,
            3,
            loads='fit = ["sxx"]\nheldout = ["syy"]\nvalidation = ["szz"]\n',
        )


def test_a_box_gets_the_homogeneous_states_as_face_tractions(tmp_path):
    """On a box the set is face tractions (the graded reference of boxes applies) with
    the stretches' corner constraints; the FEM meets the closed form to rounding."""
    p = tmp_path / "b.toml"
    p.write_text(
        textwrap.dedent("""
        name = "b"
        dim = 3
        [body]
        shape = "box"
        origin = [0.5, -1.0, 2.0]
        size = [2.0, 1.0, 1.5]
        [material]
        E = 1000.0
        nu = 0.3
        [loads]
        set = "homogeneous3d"
        magnitude = 2.0
        [reference]
        max_refine = 1
        """)
    )
    case = load_case(p)
    sxy = next(l for l in case.loads if l.name == "sxy")
    assert sxy.stress is None and {t.part for t in sxy.tractions} == {"x0", "x1", "y0", "y1"}
    sol = reference.solve(case, cache=False)
    lo, hi = case.body.bbox()
    corners = np.array([lo, [hi[0], lo[1], lo[2]], [lo[0], hi[1], lo[2]]])
    x = np.random.default_rng(1).uniform(lo, hi, (40, 3))
    for load in case.loads:
        want = homogeneous_closed_form(load, x, isotropic_compliance(1000.0, 0.3), corners)
        assert np.abs(sol.displacement(x, load.name) - want).max() <= 1e-9 * np.abs(want).max(), (
            load.name
        )


def test_a_mesh_written_in_2d_reads_back(tmp_path, bodies):
    m = read_mesh(bodies["holed_plate"])
    assert m.dim == 2 and "triangle" in m.cells
    assert isinstance(meshio.read(bodies["holed_plate"]), meshio.Mesh)


def test_gmsh_meshes_leave_sigpipe_ignored(tmp_path):
    """gmsh's start resets SIGPIPE to the default (the kernel's disposition, not Python's
    cached one); tests/meshes.py puts Python's ignore back, else a later write to a closed
    pipe or socket kills the test run (exit 141)."""

    def ignored():
        with open("/proc/self/status") as fh:
            mask = next(int(l.split()[1], 16) for l in fh if l.startswith("SigIgn"))
        return bool(mask & (1 << (signal.SIGPIPE - 1)))

    if not Path("/proc/self/status").exists():
        pytest.skip("no /proc: the disposition cannot be read here")
    meshes.cylinder(tmp_path, size=0.08)
    assert ignored()
