"""springbench score with a bad value of each of its flags and arguments: exit 2 and one
line naming the flag (or the file), with the fix; the network and the case are never
overwritten."""

from __future__ import annotations

from pathlib import Path

import pytest

from harness import cli
from tests.run.test_robustness import names_a_fix

pytestmark = pytest.mark.usefixtures("cache")  # the reference cache of the ``made`` inputs

# (extra argv after NET CASE, text the line must hold); NET, CASE and DIR expand to the inputs and
# a folder
SCORE_FLAGS = [
    ("--weights nan 1 1", "--weights"),
    ("--weights inf 1 1", "--weights"),
    ("--weights -1 1 1", "--weights"),
    ("--weights 0 0 0", "--weights"),
    ("--weights 1e308 1e308 1e308", "--weights"),
    ("--weights 1e-320 0 0", "--weights"),
    ("--weights 1 1", "--weights"),
    ("--weights a b c", "--weights"),
    ("--out DIR", "--out"),
    ("--out NET", "--out"),
    ("--out CASE", "--out"),
    ("--full --frobnicate", "--frobnicate"),
]
SCORE_ARGS = [
    ("DIR CASE", "a folder, not a network file"),
    ("NET DIR", "a folder, not a case file"),
    ("NET DIR/missing.toml", "file not found"),
    ("NET", "CASE"),
]


def _argv(text: str, made: Path, folder: Path) -> list[str]:
    sub = {"NET": str(made / "net.vtu"), "CASE": str(made / "tiny.toml"), "DIR": str(folder)}
    return ["score", *[sub.get(a, a.replace("DIR", str(folder))) for a in text.split()]]


def _one_line(argv, must, capsys):
    try:
        code = cli.main(argv)
    except SystemExit as exc:  # argparse
        code = exc.code
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("springbench")]
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert must in lines[0] and names_a_fix(lines[0]), lines[0]


@pytest.mark.parametrize("extra, must", SCORE_FLAGS, ids=[c for c, _ in SCORE_FLAGS])
def test_bad_score_flag_is_one_line(extra, must, made, tmp_path, capsys):
    before = {p: p.read_bytes() for p in (made / "net.vtu", made / "tiny.toml")}
    _one_line(_argv(f"NET CASE {extra}", made, tmp_path), must, capsys)
    assert {p: p.read_bytes() for p in before} == before  # the inputs are untouched
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("args, must", SCORE_ARGS, ids=[c for c, _ in SCORE_ARGS])
def test_bad_score_argument_is_one_line(args, must, made, tmp_path, capsys):
    _one_line(_argv(args, made, tmp_path), must, capsys)


def test_the_good_score_passes(made, tmp_path, capsys):
    """The control: the same network and case score, and --out writes the table."""
    assert cli.main(_argv("NET CASE --weights 1 3 15 --out DIR/g.csv", made, tmp_path)) == 0, (
        capsys.readouterr().err
    )
    assert (tmp_path / "g.csv").read_text().startswith("load")


SCORE_FLAG_CASES = [f"score {c}" for c, _ in SCORE_FLAGS + SCORE_ARGS]
