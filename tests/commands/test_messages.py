"""Messages that finish the thought: a gmsh v1 mesh is named with the command that converts
it, and four bad inputs name their flag (or file and field) and the fix in one line: a
network whose stiffness array is short, ``calibrate --format nosuch``, ``build --stiffness
bogus`` and ``build --out`` where the file system refuses the write."""

import shutil
from pathlib import Path

import meshio
import pytest

from harness.io.meshfile import read_mesh
from tests.commands.test_bad_commands import one_line
from tests.fs_faults import read_only

HERE = Path(__file__).resolve().parents[1]  # tests/
V1 = HERE / "bad_inputs" / "meshes" / "gmsh_v1.msh"

pytestmark = pytest.mark.usefixtures("cache")  # the reference cache of the ``made`` inputs


def test_gmsh_v1_is_named_with_its_conversion(made, tmp_path, capsys):
    """A gmsh v1 mesh: one line naming its format and the gmsh command that converts it."""
    mesh = tmp_path / "liver.msh"
    shutil.copy(V1, mesh)
    line = one_line(
        ["calibrate", mesh, "--E", "1e5", "--nu", "0.3", "--out", tmp_path / "m.vtu"],
        capsys,
        str(mesh),
        "legacy v1",
        f"gmsh {mesh} -save -format msh2 -o",
        "msh4",
    )
    assert "meshio could not read it" not in line


@pytest.mark.skipif(shutil.which("gmsh") is None, reason="gmsh's command line not on PATH")
def test_the_conversion_command_works(tmp_path):
    import subprocess

    from harness.errors import SpringbenchError

    mesh = tmp_path / "old.msh"
    shutil.copy(V1, mesh)
    with pytest.raises(SpringbenchError) as err:
        read_mesh(mesh)
    command = err.value.fix.split("convert it: ", 1)[1].split(";")[0].split()
    subprocess.run(command, check=True, capture_output=True, timeout=120)
    assert read_mesh(tmp_path / "old-v2.msh").cells["tetra"].shape == (1, 4)


def test_gmsh_v2_and_v4_are_not_taken_for_v1(tmp_path):
    for fmt in ("gmsh22", "gmsh"):
        f = tmp_path / f"{fmt}.msh"
        meshio.write(f, meshio.read(HERE / "bad_inputs" / "meshes" / "tri_ok.vtu"), fmt)
        assert read_mesh(f).cells


def test_score_names_a_short_stiffness_array(made, tmp_path, capsys):
    """A network whose stiffness array is short: the field, the counts and the fix."""
    meshio.write(tmp_path / "ascii.vtu", meshio.read(made / "net.vtu"), binary=False)
    text = (tmp_path / "ascii.vtu").read_text()
    start = text.index('Name="stiffness"')
    a, b = text.index(">", start) + 1, text.index("</DataArray>", start)
    values = text[a:b].split()
    short = tmp_path / "short.vtu"
    short.write_text(text[:a] + "\n" + " ".join(values[:-3]) + "\n" + text[b:])
    one_line(
        ["score", short, made / "tiny.toml"],
        capsys,
        str(short),
        "stiffness: ",
        f"{len(values) - 3} values for {len(values)} 'line' cells",
        "springbench build",
    )


def test_calibrate_names_format(made, tmp_path, capsys):
    """An unknown --format: the flag, the formats there are."""
    argv = ["calibrate", made / "cube.vtu", "--E", "1e5", "--nu", "0.3"]
    argv += ["--format", "nosuch", "--out", tmp_path / "m.vtu"]
    one_line(argv, capsys, "--format", "'nosuch'", "vtu", "gmsh", "bc2000")


def test_build_names_stiffness(made, tmp_path, capsys):
    """An unknown --stiffness: the flag, not the case key it becomes."""
    out = tmp_path / "b.vtu"
    line = one_line(
        ["build", made / "tiny.toml", "--stiffness", "bogus", "--out", out],
        capsys,
        "--stiffness",
        "'bogus'",
        "deussen",
    )
    assert "model.stiffness" not in line and not out.exists()


def test_build_names_out_when_the_write_is_refused(made, tmp_path, capsys, monkeypatch):
    """The folder turns read-only after the early check (or is one the check cannot see,
    e.g. /sys as root): the refusal names --out."""
    import harness.outputs

    monkeypatch.setattr(harness.outputs, "check_out_file", lambda path, field="--out": path)
    ro = tmp_path / "ro"
    ro.mkdir()
    with read_only(ro, simulate=True):
        one_line(
            ["build", made / "tiny.toml", "--out", ro / "b.vtu"],
            capsys,
            str(ro / "b.vtu"),
            "--out",
            "read-only",
        )
    assert not (ro / "b.vtu").exists()
