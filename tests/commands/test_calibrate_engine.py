"""calibrate --engine: the validated fit chooses only among candidates whose volume term the
engine runs natively (harness/registry.py EXPORT_TERMS), a --model with a term it cannot run
is refused in one line, and the JSON says which engine and candidates; a mujoco-springs
export then runs in mujoco-springs (which refuses any volume term)."""

from __future__ import annotations

import json
from pathlib import Path

import meshio
import numpy as np
import pytest

from harness import cli, registry
from tests import meshes
from tests.commands.inputs import cube_tets
from tests.commands.test_bad_calibrate import cli_run
from tests.run.test_robustness import names_a_fix

pytest.importorskip("gmsh")


def _candidates(mesh: Path, tmp: Path, engine: str | None) -> tuple[str, ...]:
    """The [optimizer.select] candidates of calibrate's in-memory case for ``engine``."""
    from harness.case.default_loads import end_loads
    from harness.case.elasticity import isotropic
    from harness.case.reader import case_of
    from harness.commands.calibrate_case import case_table, regions
    from harness.commands.calibrate_settings import Settings
    from harness.io.meshfile import read_mesh

    s = Settings(mesh, 1e5, 0.45, tmp / "m.vtu", max_refine=0, engine=engine)
    m = read_mesh(mesh)
    ends = end_loads(m.points, m.cells, *regions(s, m), m.groups)
    table = case_table(s, 3, m.cells, mesh, ends)
    case = case_of(table, mesh, material=isotropic(1e5, 0.45, 1000.0, "stress"))
    return tuple(case.section("optimizer")["select"]["candidates"])


def _volumes() -> dict[str, str]:
    from harness.optimize.select import CANDIDATES

    return {c.name: c.volume for c in CANDIDATES}


def test_mujoco_springs_validates_springs_only_candidates(tmp_path):
    """mujoco-springs: only the default candidates without a volume term; newton-springs and
    no --engine: every default candidate (a node-volume one among them)."""
    from harness.case.sections import SELECT_DEFAULT

    mesh = meshes.cylinder(tmp_path)
    volume = _volumes()
    mujoco = _candidates(mesh, tmp_path, "mujoco-springs")
    assert mujoco and all(volume[n] == "" for n in mujoco), mujoco
    assert mujoco == tuple(n for n in SELECT_DEFAULT if volume[n] == "")
    for engine in (None, "newton-springs"):
        every = _candidates(mesh, tmp_path, engine)
        assert every == SELECT_DEFAULT and any(volume[n] == "node" for n in every), engine


REFUSED = [
    (engine, model)
    for engine in registry.EXPORT_ENGINES
    for model, term in registry.CLASS_TERMS.items()
    if term not in registry.EXPORT_TERMS[engine]
]


@pytest.mark.parametrize("engine, model", REFUSED, ids=[f"{e}-{m}" for e, m in REFUSED])
def test_a_model_the_engine_cannot_run_is_refused_in_one_line(engine, model, tmp_path, capsys):
    pts, tets = cube_tets()
    meshio.write(tmp_path / "cube.vtu", meshio.Mesh(pts, [("tetra", tets)]))
    out = tmp_path / "out" / "m.vtu"
    out.parent.mkdir()
    argv = ["calibrate", tmp_path / "cube.vtu", "--E", "1e5", "--nu", "0.3", "--out", out]
    code, err, lines = cli_run(argv + ["--engine", engine, "--model", model], capsys)
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert "--engine" in lines[0] and f"--model {model}" in lines[0] and names_a_fix(lines[0])
    assert "--model springs" in lines[0]  # the fix names a model the engine runs
    assert not any(out.parent.iterdir())


def test_every_model_an_engine_runs_is_accepted():
    from harness.commands.calibrate_engine import check
    from harness.commands.calibrate_settings import Settings

    for engine, terms in registry.EXPORT_TERMS.items():
        for model, term in registry.CLASS_TERMS.items():
            if term in terms:
                check(Settings(Path("m.vtu"), 1e5, 0.3, Path("o.vtu"), model=model, engine=engine))


@pytest.mark.slow
def test_a_mujoco_springs_calibration_runs_in_mujoco_springs(tmp_path, capsys):
    """The end to end run: the first line says what --engine restricted, the JSON names the
    engine and its springs-only candidates, has no volume term, and mujoco-springs runs it."""
    mesh = meshes.cylinder(tmp_path)
    out = tmp_path / "m.vtu"
    argv = ["calibrate", str(mesh), "--E", "1e5", "--nu", "0.45", "--max-refine", "0"]
    assert cli.main(argv + ["--engine", "mujoco-springs", "--quiet", "--out", str(out)]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert first.startswith("--engine mujoco-springs: candidates without a volume term (")
    data = json.loads(out.with_suffix(".json").read_text())
    volume = _volumes()
    assert data["engine"] == "mujoco-springs"
    assert data["candidates"] and all(volume[n] == "" for n in data["candidates"])
    chose_among = [r["model"] for r in data["validation"]]
    assert chose_among[0] == "rule" and set(chose_among[1:]) == set(data["candidates"])
    assert not [k for k in data if k.startswith(("volume_", "node_volume_", "kn_"))]
    pytest.importorskip("mujoco")
    pack = tmp_path / "pack"
    made = ["pack", str(mesh), "--E", "1e5", "--nu", "0.45", "--max-refine", "0"]
    assert cli.main(made + ["--out", str(pack)]) == 0
    u = tmp_path / "u.npz"
    run = ["engines", "run", "mujoco-springs", str(pack), "--model", str(out.with_suffix(".json"))]
    assert cli.main(run + ["--loads", "sag", "--out", str(u)]) == 0
    assert np.isfinite(np.load(u)["sag"]).all()
