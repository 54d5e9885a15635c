"""Case files: the schema accepts good files and names file + field for every mistake."""

import re
import textwrap

import numpy as np
import pytest

from harness.case.reader import load_case
from harness.cli import main as cli
from harness.errors import CaseError

GOOD_2D = """
name = "plate"
dim = 2
[body]
shape = "rectangle"
origin = [1.0, -2.0]
size = [2.0, 1.0]
[material]
E = 210e9
nu = 0.3
density = 7800
plane = "strain"
[loads]
set = "basic2d"
magnitude = 1e6
"""

GOOD_3D = """
name = "box"
dim = 3
[body]
shape = "box"
size = [1, 2, 3]
parts = { top = { box = [[0, 0, 2.9], [1, 2, 3]] } }
[material]
E = 1.0
nu = 0.25
[material.fibre]
E_fibre = 10.0
E_cross = 1.0
nu_fibre = 0.3
nu_cross = 0.4
azimuth_deg = 30
elevation_deg = 45
[loads]
set = "basic3d"
[[loads.case]]
name = "sag"
gravity = [0, 0, -9.81]
[[loads.case.constraint]]
part = "z0"
[[loads.case.traction]]
part = "top"
vector = [0, 1, 0]
[score]
weights = [1, 3, 15]
[quick.reference]
element = "P1"
"""


def write(tmp_path, text, name="case.toml"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


def test_good_2d(tmp_path):
    case = load_case(write(tmp_path, GOOD_2D))
    assert case.dim == 2 and case.material.plane == "strain"
    assert [l.name for l in case.loads] == ["stretch-x", "stretch-y", "shear-x", "shear-y"]
    lo, hi = case.body.bbox()
    assert np.allclose(lo, [1, -2]) and np.allclose(hi, [3, -1])
    assert case.loads[0].tractions[0].vector == (1e6, 0.0)


def test_good_3d_modes_and_user_loads(tmp_path):
    p = write(tmp_path, GOOD_3D)
    quick, full = load_case(p, "quick"), load_case(p, "full")
    assert quick.reference.element == "P1" and full.reference.element == "P2"
    assert len(quick.loads) == 10 and quick.loads[-1].gravity == (0.0, 0.0, -9.81)
    assert quick.loads[-1].constraints[0].components == (0, 1, 2)
    assert quick.section("score")["weights"] == (1.0, 3.0, 15.0)
    assert quick.material.fibre.G_fibre > 0


def _replace(text, old, new):
    assert old in text, old
    return text.replace(old, new, 1)


# (case text, field named in the message)
BAD = [
    (_replace(GOOD_2D, 'name = "plate"\n', ""), "name"),
    (_replace(GOOD_2D, "dim = 2", "dim = 4"), "dim"),
    (_replace(GOOD_2D, "dim = 2", 'dim = "two"'), "dim"),
    (_replace(GOOD_2D, "E = 210e9", "E = -1.0"), "material.E"),
    (_replace(GOOD_2D, "E = 210e9", 'E = "steel"'), "material.E"),
    (_replace(GOOD_2D, "nu = 0.3", "nu = 0.5"), "material.nu"),
    (_replace(GOOD_2D, "nu = 0.3", "nu = -1.2"), "material.nu"),
    (_replace(GOOD_2D, "nu = 0.3", ""), "material.nu"),
    (_replace(GOOD_2D, 'plane = "strain"', 'plane = "shell"'), "material.plane"),
    (_replace(GOOD_2D, "density = 7800", "density = 0"), "material.density"),
    (_replace(GOOD_2D, "density = 7800", "densty = 7800"), "material.densty"),
    (_replace(GOOD_2D, 'shape = "rectangle"', 'shape = "box"'), "body.shape"),
    (_replace(GOOD_2D, "size = [2.0, 1.0]", "size = [2.0, -1.0]"), "body.size"),
    (_replace(GOOD_2D, "size = [2.0, 1.0]", "size = [2.0, 1.0, 3.0]"), "body.size"),
    (_replace(GOOD_2D, "size = [2.0, 1.0]\n", ""), "body.size"),
    (_replace(GOOD_2D, 'set = "basic2d"', 'set = "basic3d"'), "loads.set"),
    (_replace(GOOD_2D, 'set = "basic2d"', 'set = "stretchy"'), "loads.set"),
    (_replace(GOOD_2D, "magnitude = 1e6", "magnitude = [1]"), "loads.magnitude"),
    (GOOD_2D + '[[loads.case]]\nname = "g"\ngravity = [0, -9.8]\n', "loads.case[0].constraint"),
    (
        GOOD_2D + '[[loads.case]]\nname = "p"\n[[loads.case.constraint]]\npart = "left"\n',
        "loads.case[0].constraint[0].part",
    ),
    (
        GOOD_2D + '[[loads.case]]\nname = "p"\n[[loads.case.constraint]]\npart = "z0"\n',
        "loads.case[0].constraint[0].part",
    ),
    (
        GOOD_2D + '[[loads.case]]\nname = "p"\n[[loads.case.constraint]]\npart = "x0"\n'
        'components = ["z"]\n',
        "loads.case[0].constraint[0].components",
    ),
    (
        GOOD_2D + '[[loads.case]]\nname = "stretch-x"\n[[loads.case.constraint]]\npart = "x0"\n',
        "loads.case[0].name",
    ),
    (
        GOOD_2D + '[[loads.case]]\nname = "t"\n[[loads.case.constraint]]\npart = "x0"\n'
        '[[loads.case.traction]]\npart = "x1"\nvector = [1, 0, 0]\n',
        "loads.case[0].traction[0].vector",
    ),
    (GOOD_2D + '[reference]\ncell = "tet"\n', "reference.cell"),
    (GOOD_2D + '[reference]\nelement = "P3"\n', "reference.element"),
    (GOOD_2D + "[reference]\ntol = 0\n", "reference.tol"),
    (GOOD_2D + "[solver]\nx = 1\n", "solver"),
    (GOOD_2D + "[score]\nweights = [1, 3]\n", "score.weights"),
    (GOOD_2D + '[model]\nkind = "magic"\n', "model.kind"),
    ("quick = 3\n" + GOOD_2D, "quick"),
    (_replace(GOOD_2D, 'shape = "rectangle"', 'shape = "mesh"\nfile = "nope.msh"'), "body.file"),
    (GOOD_2D.replace("[loads]", "[loads\n"), None),  # TOML syntax error
    (_replace(GOOD_3D, "E_cross = 1.0", "E_cross = 0.0"), "material.fibre.E_cross"),
    (_replace(GOOD_3D, "nu_cross = 0.4", "nu_cross = 0.99"), "material.fibre"),
    (
        _replace(GOOD_3D, "azimuth_deg = 30", "direction = [1, 0, 0]\nazimuth_deg = 30"),
        "material.fibre",
    ),
    (
        _replace(GOOD_3D, "box = [[0, 0, 2.9], [1, 2, 3]]", "box = [[0, 0, 3.1], [1, 2, 3]]"),
        "body.parts.top.box",
    ),
]


@pytest.mark.parametrize("text,field", BAD, ids=[f"bad{i:02d}" for i in range(len(BAD))])
def test_bad_case_is_one_line_naming_file_and_field(tmp_path, capsys, text, field):
    p = write(tmp_path, text, "bad.toml")
    with pytest.raises(CaseError) as err:
        load_case(p)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(str(p))
    if field is not None:
        assert re.search(rf": {re.escape(field)}(:|\.| )", msg), msg
    assert cli(["validate", str(p)]) == 2
    out = capsys.readouterr()
    assert "Traceback" not in out.err and len(out.err.strip().splitlines()) == 1


def test_bad_mesh_file_is_named(tmp_path):
    (tmp_path / "broken.msh").write_text("this is not a mesh\n")
    p = write(tmp_path, _replace(GOOD_3D, 'shape = "box"', 'shape = "mesh"\nfile = "broken.msh"'))
    with pytest.raises(CaseError, match=r"body\.file: cannot read mesh"):
        load_case(p)


def test_validate_accepts_shipped_cases(capsys):
    from pathlib import Path

    cases = Path(__file__).resolve().parents[2] / "cases"
    assert cli(["validate", str(cases)]) in (0,)
