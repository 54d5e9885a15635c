"""calibrate on a curved gmsh body with no groups: a box, a sphere and a node file as clamp
and load region run (``--method rule``), print each region's area and node count, and the
FEM, the springs and the exported forces hold and load exactly the facets an independent
predicate picks; a mesh in mm takes its box in mm. Units: one warning line (not an error)
for an E, a density or a size no SI body has, naming the unit and the flag; --E -5e3 is
'E must be positive' naming --E; printed lengths carry their unit."""

from __future__ import annotations

import json
import re

import meshio
import numpy as np
import pytest

from harness import cli
from harness.io.meshfile import read_mesh
from tests import meshes
from tests.case.test_selectors import AXES, BOX, SPHERE, TOP, surface

gmsh = pytest.importorskip("gmsh")


@pytest.fixture(scope="module")
def body(tmp_path_factory):
    d = tmp_path_factory.mktemp("regions")
    path = meshes.ellipsoid(d, axes=AXES, size=0.06)
    m = read_mesh(path)
    meshio.write(d / "mm.vtu", meshio.Mesh(m.points * 1e3, [("tetra", m.cells["tetra"])]))
    return path, m, d / "mm.vtu"


def nodes_of(points, tris, inside) -> set:
    """The vertices of the triangles all of whose vertices are ``inside`` (n,) -> bool."""
    return set(np.unique(tris[inside(points)[tris].all(axis=1)]).tolist())


def in_box(b):
    return lambda x: np.all((x >= b[:3]) & (x <= b[3:]), axis=1)


def in_sphere(s):
    return lambda x: np.linalg.norm(x - np.array(s[:3]), axis=1) <= s[3]


def calibrate(argv, capsys):
    code = cli.main(["calibrate", *map(str, argv)])
    out = capsys.readouterr()
    assert code == 0, out.err
    return out


def test_box_clamp_and_node_file_load_region_hold_the_predicates_facets(body, tmp_path, capsys):
    """The JSON's clamped nodes are the box's facets' nodes, the torsion's loaded nodes the
    node file's facets' nodes; the FEM's displacement is zero at the clamped nodes and at no
    other; both regions print their area (m^2) and node count, the clamp its centroid in m."""
    import reference
    from harness.case.reader import load_case

    path, m, _ = body
    tris = surface(m.cells["tetra"])
    tip_ids = np.flatnonzero(m.points[:, 0] > 0.22)
    (tmp_path / "tip.txt").write_text("\n".join(map(str, tip_ids)) + "\n")
    box = "box:" + ",".join(map(str, BOX))
    out = tmp_path / "m.vtu"
    printed = calibrate(
        [path, "--E", "1e5", "--nu", "0.3", "--method", "rule", "--max-refine", "0"]
        + ["--clamp", box, "--load-region", f"nodes:{tmp_path / 'tip.txt'}"]
        + ["--out", out, "--save-case", tmp_path / "c.toml"],
        capsys,
    ).out
    held = nodes_of(m.points, tris, in_box(np.array(BOX)))
    loaded = nodes_of(m.points, tris, lambda x: np.isin(np.arange(len(x)), tip_ids))
    first = printed.splitlines()[0]
    assert re.search(rf"the facets of the {len(tip_ids)} nodes of tip.txt \([\d.e-]+ m\^2, ", first)
    assert f"{len(loaded)} nodes)" in first and "m, normal (-" in first
    assert re.search(
        rf"clamped \([\d.e-]+ m\^2, .*centroid \([^)]*\) m, .*{len(held)} nodes", first
    )
    data = json.loads(out.with_suffix(".json").read_text())
    assert set(data["clamped_nodes"]["tip"]["nodes"]) == held
    assert set(data["loaded_nodes"]["torsion"]) == loaded
    case = load_case(tmp_path / "c.toml")
    u = reference.solve(case, cache=False).displacement(m.points, "tip")
    still = np.abs(u).max(axis=1) <= 1e-12 * np.abs(u).max()  # held, to interpolation's rounding
    assert set(np.flatnonzero(still).tolist()) == held


def test_a_mesh_in_mm_takes_its_sphere_and_box_in_mm(body, tmp_path, capsys):
    """--length-unit mm: the sphere clamp and the top box given in mm pick the predicate's
    facets, the case holds them in m, the load region's normal (+z) turns the torsion; --E
    50 gets its warning on stderr and the run goes on."""
    path, m, mm = body
    tris = surface(m.cells["tetra"])
    sphere = "sphere:" + ",".join(str(1e3 * v) for v in SPHERE)
    box = "box:" + ",".join(str(1e3 * v) for v in TOP)
    out = tmp_path / "m.vtu"
    res = calibrate(
        [mm, "--E", "50", "--nu", "0.3", "--method", "rule", "--max-refine", "0"]
        + ["--length-unit", "mm", "--clamp", sphere, "--load-region", box, "--out", out]
        + ["--save-case", tmp_path / "c.toml"],
        capsys,
    )
    (warning,) = [ln for ln in res.err.splitlines() if ln.startswith("warning")]
    assert "--E 50 Pa" in warning and "looks like MPa" in warning and "(--E 5e+07)" in warning
    data = json.loads(out.with_suffix(".json").read_text())
    assert set(data["clamped_nodes"]["tip"]["nodes"]) == nodes_of(m.points, tris, in_sphere(SPHERE))
    assert set(data["loaded_nodes"]["tip"]) == nodes_of(m.points, tris, in_box(np.array(TOP)))
    text = (tmp_path / "c.toml").read_text()
    assert f'facets = "sphere:{SPHERE[0] * 1e3 * 1e-3!r}' in text  # in m
    assert "mean normal (" in res.out.splitlines()[0]


def settings(E=1e5, density=1000.0, length_unit="m"):
    from harness.commands.calibrate_settings import Settings

    return Settings(mesh=None, E=E, nu=0.3, out=None, density=density, length_unit=length_unit)


@pytest.mark.parametrize(
    "given, musts",
    [
        (dict(E=0.005), ["--E 0.005 Pa", "looks like MPa", "give Pa (--E 5000)"]),
        (dict(E=70.0), ["looks like MPa", "(--E 7e+07)", "GPa (--E 7e+10)"]),
        (dict(density=1.06), ["--density 1.06 kg/m^3", "looks like g/cm^3", "(--density 1060)"]),
        (dict(density=7.85e6), ["--density 7.85e+06 kg/m^3", "denser", "(--density 7850)"]),
        (dict(scale=1e3), ["{L:.3g} m across", "looks like mm", "--length-unit mm ({f:.3g} m)"]),
        (
            dict(scale=0.1, length_unit="mm"),  # a 6 cm body read in mm
            ["{L:.3g} m across", "under 0.1 mm", "looks like m: --length-unit m ({f:.3g} m)"],
        ),
        (dict(scale=1e-5), ["{L:.3g} m across", "check the mesh's unit (--length-unit"]),
    ],
)
def test_a_value_no_si_body_has_is_one_warning_naming_unit_and_flag(given, musts, body):
    from harness.commands.calibrate_check import unit_warnings

    path, m, _ = body
    scale = given.pop("scale", 1.0)
    mesh = type(m)(m.points * scale, m.cells, m.flags, m.source, m.groups)
    (line,) = unit_warnings(settings(**given), mesh)
    assert line.startswith("warning: ") and "\n" not in line
    size = float(np.ptp(m.points, axis=0).max())  # the body in m
    unit = {"m": 1.0, "mm": 1e-3}[given.get("length_unit", "m")]
    # L: the body as read, f: as its coordinates are in m, or in mm for a huge one
    f = size * scale * (1e-3 if scale > 1 else 1.0)
    musts = [must.format(L=size * scale * unit, f=f) for must in musts]
    assert all(must in line for must in musts), (line, musts)


def test_si_values_give_no_warning(body):
    from harness.commands.calibrate_check import unit_warnings

    assert unit_warnings(settings(E=2.1e11, density=7850.0), body[1]) == []
    assert unit_warnings(settings(E=5e3, density=1060.0), body[1]) == []  # a liver


@pytest.mark.parametrize(
    "flags, must",
    [
        (["--E", "-5e3"], "--E: E must be positive (Pa), got '-5e3'"),
        (["--E=-5e3"], "--E: E must be positive"),
        (["--E", "-inf"], "--E: E must be positive"),
        (["--E", "-5e3", "--density", "1000"], "--E: E must be positive"),
        (["--E", "1e5", "--density", "-1.2e3"], "--density: density must be positive"),
    ],
)
def test_a_negative_modulus_is_one_line_naming_E(flags, must, body, tmp_path, capsys):
    argv = ["calibrate", str(body[0]), *flags, "--nu", "0.3", "--out", str(tmp_path / "m.vtu")]
    with pytest.raises(SystemExit) as exc:
        cli.main(argv)
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert exc.value.code == 2 and len(err) == 1 and must in err[0], err
    with pytest.raises(SystemExit):
        cli.main(["pack", str(body[0]), *flags, "--nu", "0.3", "--out", str(tmp_path / "p")])
    assert must in capsys.readouterr().err
