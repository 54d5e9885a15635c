"""calibrate runs in memory: the case is built as an object (no TOML file written and
read back), the exported network comes from the stage's result (no output found by its
file name), and ``--save-case`` writes the same case as a TOML file that reads back to an
equal Case."""

import dataclasses
import json
import tomllib

import numpy as np
import pytest

from harness import cli
from harness.case import reader
from harness.io.toml_text import dumps
from tests import meshes

pytest.importorskip("gmsh")


@pytest.fixture(scope="module")
def cylinder(tmp_path_factory):
    return meshes.cylinder(tmp_path_factory.mktemp("mesh"))


def test_toml_text_reads_back_as_the_same_table():
    """Headers, arrays of tables (nested too), inline values and keys that need quotes."""
    table = {
        "name": "c",
        "dim": 3,
        "flag": True,
        "body": {"shape": "mesh", "parts": {"side-x0": {"end": "x0", "band": 0.05}}},
        "loads": {
            "set": "linear3d",
            "magnitude": 1e-05,
            "heldout": ["sag", "tip"],
            "case": [
                {"name": "sag", "gravity": [0.0, -1.5, 0.0], "constraint": [{"part": "a"}]},
                {"name": "tip", "constraint": [{"part": "a"}, {"part": "b"}]},
            ],
        },
        "optimizer": {"method": "lbfgs", "select": {}},
    }
    assert tomllib.loads(dumps(table)) == table
    with pytest.raises(ValueError):
        dumps({"x": float("nan")})


def calibrate(mesh, out, *extra):
    argv = ["calibrate", str(mesh), "--E", "1e5", "--nu", "0.3", "--method", "rule"]
    assert cli.main(argv + ["--max-refine", "0", "--quiet", "--out", str(out), *extra]) == 0
    return json.loads(out.with_suffix(".json").read_text())


def test_calibrate_reads_no_case_file_and_no_output_back(cylinder, tmp_path, monkeypatch):
    """With TOML parsing refused and any VTU the stage writes unreadable, calibrate still
    exports: the case and the network travel as objects, and the export is the stage's
    network (the rule's constants, recomputed here from the mesh)."""
    import meshio

    from harness.case.reader import load_case
    from harness.models.sms import build_network

    read = meshio.read

    def no_toml(*a, **k):
        raise AssertionError("a TOML case was parsed")

    def no_outputs(path, *a, **k):
        if str(path).endswith(".vtu") and "springbench-calibrate-" in str(path):
            raise AssertionError(f"read back {path}")
        return read(path, *a, **k)

    monkeypatch.setattr(tomllib, "loads", no_toml)
    monkeypatch.setattr(meshio, "read", no_outputs)
    saved = tmp_path / "case.toml"
    data = calibrate(cylinder, tmp_path / "m.vtu", "--rule", "uniform", "--save-case", str(saved))
    monkeypatch.undo()
    net = build_network(load_case(saved))  # the saved case's first rule: uniform
    assert data["choice"] == "rule"
    assert np.array_equal(np.asarray(data["spring_stiffness"]), net.k)


def test_save_case_reads_back_to_the_case_that_ran(cylinder, tmp_path):
    """--save-case: springbench's own reader gives a Case equal to the one in memory
    (material, loads, held-out names, reference, model and optimizer sections)."""
    from harness.commands.calibrate_case import mesh_case
    from harness.commands.calibrate_settings import Settings
    from harness.io.meshfile import read_mesh

    saved = tmp_path / "case.toml"
    calibrate(cylinder, tmp_path / "m.vtu", "--rule", "uniform", "--save-case", str(saved))
    from_file = reader.load_case(saved)
    s = Settings(cylinder, 1e5, 0.3, tmp_path / "n.vtu", method="rule", rule="uniform")
    s = dataclasses.replace(s, max_refine=0)
    in_memory = mesh_case(s, read_mesh(cylinder), tmp_path)
    for field in ("dim", "material", "reference", "heldout", "load_set", "magnitude"):
        assert getattr(from_file, field) == getattr(in_memory, field), field
    assert [l.name for l in from_file.loads] == [l.name for l in in_memory.loads]
    assert dict(from_file.body.parts) == dict(in_memory.body.parts)
    assert dict(from_file.sections) == dict(in_memory.sections)
    assert from_file.material.nu == 0.3 and from_file.material.E == 1e5
