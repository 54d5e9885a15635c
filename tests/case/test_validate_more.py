"""Mistakes that passed silently before: a 2-entry grid in a 3-D case, an
absurd divisions, score weights that are NaN or all zero. Each is one line naming the
file or flag and the fix, exit 2."""

import textwrap
from pathlib import Path

import pytest

from harness import cli

ROOT = Path(__file__).resolve().parents[2]


def case3d(tmp_path, model="grid = [5, 3]", reference=""):
    p = tmp_path / "c.toml"
    p.write_text(
        textwrap.dedent(f"""
        name = "c"
        dim = 3
        [body]
        shape = "box"
        size = [1.0, 1.0, 1.0]
        [material]
        E = 1.0
        nu = 0.3
        [loads]
        set = "basic3d"
        [reference]
        {reference}
        [model]
        kind = "sms"
        placement = "grid"
        {model}
        """)
    )
    return p


@pytest.mark.parametrize(
    "model,reference,field",
    [
        ("grid = [5, 3]", "", "model.grid"),
        ("grid = [5, 3, 1]", "", "model.grid"),
        ("grid = [3, 3, 3]", "divisions = 9223372036854775807", "reference.divisions"),
    ],
)
def test_validate_names_the_field(tmp_path, capsys, model, reference, field):
    code = cli.main(["validate", str(case3d(tmp_path, model, reference))])
    err = (capsys.readouterr().err + "").strip().splitlines()
    out = [line for line in err if "c.toml" in line]
    assert code == 2 and len(out) == 1 and field in out[0]


@pytest.mark.parametrize("weights", [["nan", "1", "1"], ["0", "0", "0"], ["-1", "1", "1"]])
def test_score_weights_must_be_usable(tmp_path, capsys, weights):
    case = ROOT / "cases" / "verification" / "plate_stress_tri.toml"
    code = cli.main(["score", str(tmp_path / "missing.vtu"), str(case), "--weights", *weights])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--weights" in err[0]
