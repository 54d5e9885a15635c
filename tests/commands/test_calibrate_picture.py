"""calibrate's picture of the fit: MODEL-heldout.vtu holds, per held-out load, the FEM's and
the model's displacement, the error |u_model - u_FEM| per node and the held and loaded
nodes; each field is checked against an independent source (the reference evaluated here,
a dense solve of MODEL.json's springs written here, the cylinder's end faces found by their
coordinate), and MODEL-heldout.png opens and draws the worst held-out load."""

import contextlib
import dataclasses
import io
import json
import re

import numpy as np
import pytest

from harness import cli
from tests import meshes

pytest.importorskip("gmsh")

LENGTH = 0.5  # the cylinder of tests/meshes.py: along x from 0 to LENGTH
FIELDS = ("u_fem", "u_model", "error", "held", "loaded")


def calibrate(mesh, out, *extra) -> tuple[dict, str]:
    """MODEL.json and the printed text of a rule's calibration of ``mesh``."""
    argv = ["calibrate", str(mesh), "--E", "1e5", "--nu", "0.3", "--method", "rule", *extra]
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert cli.main(argv + ["--max-refine", "0", "--quiet", "--out", str(out)]) == 0
    return json.loads(out.with_suffix(".json").read_text()), printed.getvalue()


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """The reference cache of this module's calibrations (and of the checks' own solve)."""
    d = tmp_path_factory.mktemp("cache")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("SPRINGBENCH_CACHE", str(d))
        yield d


@pytest.fixture(scope="module")
def run(tmp_path_factory, cache):
    """A small tet cylinder calibrated: (mesh, MODEL.vtu, MODEL.json, printed, the held-out
    VTU as meshio reads it)."""
    import meshio

    d = tmp_path_factory.mktemp("picture")
    mesh = meshes.cylinder(d)
    data, printed = calibrate(mesh, d / "m.vtu")
    return mesh, d / "m.vtu", data, printed, meshio.read(d / "m-heldout.vtu")


def _field(vtu, name: str, load: str, dim: int = 3) -> np.ndarray:
    a = np.asarray(vtu.point_data[f"{name}/{load}"])
    return a[:, :dim] if a.ndim == 2 else a


def test_every_held_out_load_has_its_fields_and_the_error_is_their_difference(run):
    """FIELD/<load> for every held-out load of the JSON and nothing else; the points are the
    exported network's; error = |u_model - u_FEM| per node, recomputed from the two fields."""
    import meshio

    _, out, data, _, vtu = run
    loads = data["loads_heldout"]
    assert len(loads) == 5
    assert set(vtu.point_data) == {f"{f}/{n}" for n in loads for f in FIELDS}
    np.testing.assert_array_equal(vtu.points, meshio.read(out).points)
    for n in loads:
        err = np.linalg.norm(_field(vtu, "u_model", n) - _field(vtu, "u_fem", n), axis=1)
        np.testing.assert_allclose(_field(vtu, "error", n), err, rtol=1e-12, atol=0)
        assert err.max() > 1e-3 * np.linalg.norm(_field(vtu, "u_fem", n), axis=1).max()


def test_the_fem_field_is_the_reference_at_the_nodes(run, tmp_path):
    """u_fem/<load> is reference.solve(case)'s displacement evaluated here at the VTU's
    points, load by load (a field of another load fails)."""
    import reference
    from harness.commands.calibrate_case import mesh_case
    from harness.commands.calibrate_settings import Settings
    from harness.io.meshfile import read_mesh

    mesh, _, data, _, vtu = run
    s = Settings(mesh, 1e5, 0.3, tmp_path / "n.vtu", method="rule")
    case = mesh_case(dataclasses.replace(s, max_refine=0), read_mesh(mesh), tmp_path)
    ref = reference.solve(case)
    for n in data["loads_heldout"]:
        want = ref.displacement(np.asarray(vtu.points, float), n)
        scale = np.abs(want).max()
        np.testing.assert_allclose(_field(vtu, "u_fem", n), want, rtol=0, atol=1e-9 * scale)


def _dense_solve(data: dict, load: str) -> np.ndarray:
    """The springs of MODEL.json solved densely under its held nodes and forces of ``load``
    (K = sum_e k_e d d^T on each spring's dofs, d its unit direction)."""
    x = np.asarray(data["particle_q"], float)
    n, dim = x.shape
    K = np.zeros((n * dim, n * dim))
    for (i, j), k in zip(data["spring_indices"], data["spring_stiffness"]):
        d = (x[j] - x[i]) / np.linalg.norm(x[j] - x[i])
        b = k * np.outer(d, d)
        for a, c, sign in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
            K[a * dim : (a + 1) * dim, c * dim : (c + 1) * dim] += sign * b
    f = np.zeros((n, dim))
    f[data["loaded_nodes"][load]] = data["forces"][load]
    free = np.ones((n, dim), bool)
    held = data["clamped_nodes"][load]
    for node, comps in zip(held["nodes"], held["components"]):
        free[node, comps] = False
    free = free.ravel()
    u = np.zeros(n * dim)
    u[free] = np.linalg.solve(K[np.ix_(free, free)], f.ravel()[free])
    return u.reshape(n, dim)


def test_the_model_field_is_a_dense_solve_of_the_exported_springs(run):
    """u_model/<load> is the exported network's answer: MODEL.json's springs, held nodes and
    forces solved here with a dense matrix."""
    _, _, data, _, vtu = run
    for n in data["loads_heldout"]:
        want = _dense_solve(data, n)
        np.testing.assert_allclose(
            _field(vtu, "u_model", n), want, rtol=0, atol=1e-8 * np.abs(want).max()
        )


def test_the_region_flags_are_the_end_faces(run):
    """held/<load>: the x = 0 end face (the bridge: both end faces), as the JSON's clamped
    nodes; loaded/<load>: the x = LENGTH end face for the tip loads and the torsion, no node
    for the body-force loads (sag, bridge)."""
    _, _, data, _, vtu = run
    x = np.asarray(vtu.points, float)[:, 0]
    low, high = np.abs(x) < 1e-9, np.abs(x - LENGTH) < 1e-9
    assert low.sum() >= 10 and high.sum() >= 10
    for n in data["loads_heldout"]:
        held, loaded = _field(vtu, "held", n), _field(vtu, "loaded", n)
        assert set(np.unique(held)) | set(np.unique(loaded)) <= {0, 1}
        np.testing.assert_array_equal(held, low | high if n == "bridge" else low)
        assert np.flatnonzero(held).tolist() == sorted(data["clamped_nodes"][n]["nodes"])
        body = n in ("sag", "bridge")
        np.testing.assert_array_equal(loaded, np.zeros_like(high) if body else high)


def test_the_picture_opens_and_draws_the_worst_load(run):
    """MODEL-heldout.png is a real picture (not one colour), and the printed line names
    the held-out load with the largest error of the JSON's G_heldout_loads."""
    from matplotlib.image import imread

    _, out, data, printed, _ = run
    img = imread(out.with_name("m-heldout.png"))
    assert img.shape[0] >= 300 and img.shape[1] >= 400
    assert np.unique(img.reshape(-1, img.shape[2]), axis=0).shape[0] > 50
    per = data["G_heldout_loads"]
    (shown,) = re.findall(r"\(\+ m-heldout.png: '([^']+)', the worst, ([\d.]+) %", printed)
    assert shown[0] == max(per, key=per.get)
    assert float(shown[1]) == pytest.approx(100 * per[shown[0]], rel=1e-2)
    last = printed.strip().splitlines()[-1]
    assert last.startswith(f"-> {out} (+ .json, .csv): ")
    assert f"; the fit on the held-out loads: {out.with_name('m-heldout.vtu')} (+ m-heldout" in last


def test_the_vtu_is_the_same_every_time(run, tmp_path):
    """Same mesh and flags: MODEL-heldout.vtu byte for byte."""
    mesh, out, _, _, _ = run
    calibrate(mesh, tmp_path / "m.vtu")
    again = (tmp_path / "m-heldout.vtu").read_bytes()
    assert again == out.with_name("m-heldout.vtu").read_bytes()


def test_a_plane_mesh_gets_both_files(tmp_path, cache):
    """2-D: displacements padded to 3 components, the error their difference, the picture
    drawn."""
    import meshio
    from matplotlib.image import imread

    data, printed = calibrate(meshes.holed_plate(tmp_path), tmp_path / "p.vtu")
    vtu = meshio.read(tmp_path / "p-heldout.vtu")
    for n in data["loads_heldout"]:
        assert np.all(_field(vtu, "u_fem", n)[:, 2] == 0)
        err = np.linalg.norm(_field(vtu, "u_model", n) - _field(vtu, "u_fem", n), axis=1)
        np.testing.assert_allclose(_field(vtu, "error", n), err, rtol=1e-12, atol=0)
    assert imread(tmp_path / "p-heldout.png").shape[0] >= 300
    assert "the fit on the held-out loads: " in printed


def test_capped_constants_are_the_ones_drawn(run, tmp_path):
    """--k-ratio exports capped constants: u_model is their answer (a dense solve of the
    capped MODEL.json), not the uncapped network's."""
    import meshio

    mesh = run[0]
    data, _ = calibrate(mesh, tmp_path / "m.vtu", "--k-ratio", "2")
    vtu = meshio.read(tmp_path / "m-heldout.vtu")
    for n in data["loads_heldout"]:
        want = _dense_solve(data, n)
        np.testing.assert_allclose(
            _field(vtu, "u_model", n), want, rtol=0, atol=1e-8 * np.abs(want).max()
        )
    uncapped = _dense_solve(run[2], "tip")
    assert np.abs(_field(vtu, "u_model", "tip") - uncapped).max() > 1e-3 * np.abs(uncapped).max()


def test_no_held_out_loads_no_picture(run, tmp_path):
    """--heldout none: nothing to draw, neither file is written nor named."""
    _, printed = calibrate(run[0], tmp_path / "m.vtu", "--heldout", "none")
    assert not list(tmp_path.glob("m-heldout*")) and "heldout.vtu" not in printed
