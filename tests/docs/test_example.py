"""The shipped example (examples/lug.msh, examples/make_lug.py) and README's calibrate example
on it: the mesh is small, valid and has its groups; the script makes it; README's command
runs, prints what README shows (line for line, numbers aside) and writes a JSON whose every
key docs/calibrate.md documents."""

import json
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
MESH = ROOT / "examples" / "lug.msh"
README = ROOT / "README.md"
CAL_BEGIN, CAL_END = (
    "<!-- calibrate output: pasted from the command above -->",
    "<!-- end of the calibrate output -->",
)


def test_example_mesh_is_small_valid_and_has_its_groups():
    from harness.case.mesh_checks import check_mesh
    from harness.io.meshfile import read_mesh

    assert MESH.stat().st_size < 300_000
    mesh = read_mesh(MESH)
    check_mesh(mesh, str(MESH))  # raises on anything calibrate would refuse
    assert set(mesh.cells) == {"tetra"}
    assert 1000 <= len(mesh.cells["tetra"]) <= 3000
    assert {"body", "base", "bore"} <= set(mesh.groups)
    lo, hi = mesh.points.min(0), mesh.points.max(0)
    np.testing.assert_allclose(lo, [0, -0.015, 0], atol=1e-12)  # the lug of make_lug.py, in metres
    np.testing.assert_allclose(hi, [0.095, 0.015, 0.01], atol=1e-12)


def test_the_script_makes_the_example(tmp_path):
    pytest.importorskip("gmsh", reason="gmsh is not installed: pip install -e '.[test]'")
    sys.path.insert(0, str(ROOT / "examples"))
    try:
        import make_lug
    finally:
        sys.path.remove(str(ROOT / "examples"))
    from harness.io.meshfile import read_mesh

    made, shipped = read_mesh(make_lug.main(tmp_path / "lug.msh")), read_mesh(MESH)
    assert set(made.groups) == set(shipped.groups)
    np.testing.assert_allclose(made.points.min(0), shipped.points.min(0), atol=1e-12)
    np.testing.assert_allclose(made.points.max(0), shipped.points.max(0), atol=1e-12)
    # the same mesh with this gmsh; another gmsh version may place a few nodes differently
    assert abs(len(made.cells["tetra"]) / len(shipped.cells["tetra"]) - 1) < 0.1


def _readme_command() -> list[str]:
    (line,) = [
        ln
        for ln in README.read_text(encoding="utf-8").splitlines()
        if ln.startswith("springbench calibrate examples/")
    ]
    return shlex.split(line)


def _pasted() -> list[str]:
    text = README.read_text(encoding="utf-8")
    block = text[text.index(CAL_BEGIN) + len(CAL_BEGIN) : text.index(CAL_END)]
    return block.strip().splitlines()[1:-1]  # inside the ``` fence


def _numbers_masked(line: str) -> str:
    return " ".join(re.sub(r"[-+]?\d[\d.]*(?:e[-+]?\d+)?", "#", line).split())


def _documented_json_keys() -> set[str]:
    text = (ROOT / "docs" / "calibrate.md").read_text(encoding="utf-8")
    section = text[text.index("## What it writes") : text.index("## In an engine")]
    return {
        k
        for row in re.findall(r"^\| (.+?) \|", section, flags=re.M)
        for k in re.findall(r"`([^`]+)`", row)
    }


@pytest.mark.slow
def test_readme_calibrate_example_runs_and_prints_what_readme_shows(tmp_path):
    """README's command exactly (the output path aside): the same lines, numbers aside, and a
    table within 100 characters a line."""
    cmd = _readme_command()
    assert cmd[:3] == ["springbench", "calibrate", "examples/lug.msh"]
    out = tmp_path / "model.vtu"
    readme_out, cmd[cmd.index("--out") + 1] = cmd[cmd.index("--out") + 1], str(out)
    res = subprocess.run(
        [sys.executable, "-m", "harness", *cmd[1:]], cwd=ROOT, capture_output=True, text=True
    )
    assert res.returncode == 0, res.stderr[-3000:]
    got, want = (
        res.stdout.strip().splitlines(),
        [
            line.replace(readme_out, str(out)).replace(
                readme_out.replace(".vtu", "-heldout"), str(out).replace(".vtu", "-heldout")
            )
            for line in _pasted()
        ],
    )
    assert len(got) == len(want), "README's pasted output has a different number of lines"
    # every line as README shows it, numbers aside: where it clamps and loads, the table's
    # columns, each row's model, choice and status, the sentences
    for g, w in zip(got, want):
        assert _numbers_masked(g) == _numbers_masked(w), (g, w)
    rows = [i for i, line in enumerate(want) if line.lstrip().startswith("sms-")]
    assert len(rows) >= 2 and max(len(want[i]) for i in [rows[0] - 1, *rows]) <= 100
    data = json.loads(out.with_suffix(".json").read_text())
    documented = _documented_json_keys()
    assert sorted(set(data) - documented) == [], "MODEL.json keys missing from docs/calibrate.md"
    # keys of other models: the volume and kn terms, and --model p1-global's material
    optional = {k for k in documented if k.startswith(("volume_", "kn_", "tet_"))}
    optional |= {"E_effective", "nu_effective"}
    assert sorted(documented - optional - set(data)) == [], (
        "docs/calibrate.md documents keys MODEL.json lacks"
    )
