"""Bad input to score, reference, build, report, run and validate beyond case files:
a network file with an out-of-range spring index, NaN points or no stiffness, a points CSV
that is empty or not numbers, a truncated result file, a folder without case files, a
time step that blows up. Each is exit 2 and one line naming the user's file (or flag), the
field and the fix."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest

from harness import cli
from tests.commands.inputs import cube_tets
from tests.fakestage import write_case
from tests.run.test_robustness import names_a_fix

HERE = Path(__file__).resolve().parents[1]  # tests/

pytestmark = pytest.mark.usefixtures("cache")  # the reference cache of the ``made`` inputs


def one_line(argv, capsys, *must) -> str:
    try:
        code = cli.main([str(a) for a in argv])
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("springbench")]
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert all(m in lines[0] for m in must) and names_a_fix(lines[0]), (must, lines[0])
    return lines[0]


# -- score: the network file ---------------------------------------------------------------


def _networks(net: meshio.Mesh) -> dict:
    """name -> (meshio.Mesh or raw bytes, text the line must hold)."""
    pts, lines = net.points, net.cells[0].data
    pd_, k = dict(net.point_data), net.cell_data["stiffness"][0]

    def mesh(points=pts, springs=lines, stiffness=k, cell_data=True):
        return meshio.Mesh(
            points,
            [("line", springs)],
            point_data=pd_,
            cell_data={"stiffness": [stiffness]} if cell_data else {},
        )

    bad_index, self_loop, nan_pt, nan_k, neg_k, zero_k, flat3d = (
        lines.copy(),
        lines.copy(),
        pts.copy(),
        k.copy(),
        k.copy(),
        k.copy(),
        pts.copy(),
    )
    bad_index[0, 1] = 10**6
    self_loop[0, 1] = self_loop[0, 0]
    nan_pt[0, 0] = np.nan
    nan_k[0], neg_k[0], zero_k[0] = np.nan, -1.0, 0.0
    flat3d[:, 2] = np.arange(len(pts)) * 0.1
    loose = ~(lines == 4).any(1)  # node 4 (the middle) keeps no spring
    return {
        "spring_index_out_of_range": (mesh(springs=bad_index), "out of range"),
        "spring_to_itself": (mesh(springs=self_loop), "itself"),
        "nan_point": (mesh(points=nan_pt), "non-finite"),
        "nan_stiffness": (mesh(stiffness=nan_k), "stiffness"),
        "negative_stiffness": (mesh(stiffness=neg_k), "stiffness"),
        "zero_stiffness": (mesh(stiffness=zero_k), "stiffness"),
        "no_stiffness": (mesh(cell_data=False), "no cell data 'stiffness'"),
        "no_springs": (
            meshio.Mesh(pts, [("vertex", np.arange(len(pts))[:, None])]),
            "no 'line' cells",
        ),
        "three_d_network": (
            meshio.Mesh(flat3d, [("line", lines)], cell_data={"stiffness": [k]}),
            "3-D",
        ),
        "floating_node": (mesh(springs=lines[loose], stiffness=k[loose]), "floating"),
        "empty_file": (b"", "empty"),
        "truncated": (None, "not a mesh file"),
        "not_a_mesh": (b"x,y\n1,2\n", "not a mesh file"),
    }


SCORE_CASES = sorted(
    (
        ["spring_index_out_of_range", "spring_to_itself", "nan_point"]
        + ["nan_stiffness", "negative_stiffness", "zero_stiffness"]
        + ["no_stiffness", "no_springs", "three_d_network", "floating_node"]
        + ["empty_file", "truncated", "not_a_mesh"]
    )
) + ["missing", "a_folder"]


@pytest.fixture(scope="module")
def networks(made):
    d = made / "networks"
    d.mkdir(exist_ok=True)
    good = meshio.read(made / "net.vtu")
    out = {}
    for name, (m, must) in _networks(good).items():
        f = d / f"{name}.vtu"
        if isinstance(m, meshio.Mesh):
            meshio.write(f, m)
        else:
            f.write_bytes((made / "net.vtu").read_bytes()[:300] if m is None else m)
        out[name] = (f, must)
    (d / "a_folder.vtu").mkdir(exist_ok=True)
    out["a_folder"] = (d / "a_folder.vtu", "cannot read")
    out["missing"] = (d / "missing.vtu", "file not found")
    return out


@pytest.mark.parametrize("name", SCORE_CASES)
def test_score_names_the_network_file(name, networks, made, capsys):
    f, must = networks[name]
    one_line(["score", f, made / "tiny.toml"], capsys, str(f), must)


def test_score_control_the_good_network_scores(made, capsys):
    assert cli.main(["score", str(made / "net.vtu"), str(made / "tiny.toml")]) == 0, (
        capsys.readouterr().err
    )


# -- reference --points ----------------------------------------------------------------------

POINTS = {
    "empty": ("", "empty"),
    "header_only": ("x,y\n", "no points"),
    "missing_y": ("x,z\n1,2\n", "missing column"),
    "not_numbers": ("x,y\na,b\n", "non-numeric"),
    "nan": ("x,y\nnan,0.5\n", "infinite"),
    "inf": ("x,y\n0.5,inf\n", "infinite"),
    "outside_the_body": ("x,y\n5,5\n", "outside the body"),
    "binary": (bytes(range(256)) * 2, "not a CSV"),
    "missing": (None, "file not found"),
    "a_folder": ("DIR", "is a folder"),
}


@pytest.mark.parametrize("name", sorted(POINTS))
def test_reference_points_file(name, made, tmp_path, capsys):
    data, must = POINTS[name]
    f = tmp_path / f"{name}.csv"
    if data == "DIR":
        f.mkdir()
    elif isinstance(data, bytes):
        f.write_bytes(data)
    elif data is not None:
        f.write_text(data)
    one_line(
        ["reference", made / "tiny.toml", "--points", f, "--out", tmp_path / "u.csv"],
        capsys,
        str(f),
        "--points",
        must,
    )
    assert not (tmp_path / "u.csv").exists()


# -- build, report, run, validate -----------------------------------------------------------


def test_build_flags(made, tmp_path, capsys):
    out = tmp_path / "b.vtu"
    one_line(["build", made / "tiny.toml", "--seed", "-5", "--out", out], capsys, "--seed")
    one_line(
        ["build", made / "tiny.toml", "--stiffness", "springy", "--out", out],
        capsys,
        "springy",
        "one of",
    )
    one_line(["build", made / "tiny.toml", "--seed", "x", "--out", out], capsys, "--seed")
    no_model = tmp_path / "no_model.toml"
    no_model.write_text((made / "tiny.toml").read_text().split("[model]")[0])
    one_line(["build", no_model, "--out", out], capsys, str(no_model), "model.kind")
    assert not out.exists()


BUILD_CASES = [
    "build --seed -5",
    "build --stiffness springy",
    "build --seed x",
    "build without [model]",
]


def _stored_run(tmp_path) -> Path:
    suite = tmp_path / "cases" / "demo"
    write_case(suite, "a", "rows=1")
    assert (
        cli.main(
            ["run", str(suite), "--results", str(tmp_path / "res"), "--jobs", "1", "--no-figures"]
        )
        == 0
    )
    return tmp_path / "res" / "demo"


@pytest.mark.parametrize("damage", ["truncated", "rows not a list", "empty"])
def test_report_names_a_damaged_result_file(damage, tmp_path, capsys, fake):
    suite = _stored_run(tmp_path)
    f = next(suite.glob("*/result-seed*.json"))
    text = f.read_text()
    f.write_text(
        {
            "truncated": text[: len(text) // 2],
            "rows not a list": json.dumps({"rows": 3}),
            "empty": "",
        }[damage]
    )
    capsys.readouterr()
    one_line(["report", suite, "--no-figures"], capsys, str(f), "re-run")


REPORT_CASES = ["report truncated", "report rows not a list", "report empty result"]


def test_folder_without_case_files(tmp_path, capsys, fake):
    (tmp_path / "empty").mkdir()
    for cmd in (["validate"], ["run", "--results", tmp_path / "res"]):
        one_line([*cmd, tmp_path / "empty"], capsys, str(tmp_path / "empty"), "no case files")


RUN_CASES = ["validate an empty folder", "run an empty folder"]


def test_blow_up_names_dynamics_dt(tmp_path, capsys):
    """A time step 1700x the stable one: the line names the case, dynamics.dt and the fix."""
    pts, tets = cube_tets(1)
    lines = [f"{len(pts)} {len(tets)}"] + [f"{x} {y} {z}\t{int(y == 1)}" for x, y, z in pts]
    (tmp_path / "cube.mesh").write_text(
        "\n".join(lines + [" ".join(map(str, t)) for t in tets]) + "\n"
    )
    case = tmp_path / "cases" / "blow.toml"
    case.parent.mkdir()
    case.write_text(
        'name = "blow"\ndim = 3\n[body]\nshape = "mesh"\nfile = "../cube.mesh"\nformat = "bc2000"\n'
        '[material]\nE = 1.0\nnu = 0.3\n[model]\nkind = "bc2000"\nmodels = ["MS"]\n'
        '[dynamics]\nexperiment = "run"\ndt = 100.0\nsteps = 5\n[run]\nstages = ["bc2000"]\n'
    )
    line = one_line(
        ["run", case, "--results", tmp_path / "res", "--jobs", "1", "--no-figures"],
        capsys,
        "blow.toml",
        "dynamics.dt",
        "blew up",
        "reduce dt",
    )
    assert "stable-step estimate" in line


SIMULATION_CASES = ["dynamics.dt blows up"]


def test_through_a_real_process(made, networks, tmp_path):
    """The same as a user sees it: a fresh interpreter, exit 2, one line, no traceback."""
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(HERE.parent), os.environ.get("PYTHONPATH", "")]),
        "SPRINGBENCH_CACHE": str(made / "cache"),
    }
    (tmp_path / "ro.csv").mkdir()
    for argv in (
        ["score", made / "networks" / "spring_index_out_of_range.vtu", made / "tiny.toml"],
        ["build", made / "tiny.toml", "--out", tmp_path / "ro.csv"],
        [
            "calibrate",
            made / "cube.vtu",
            "--E",
            "1e308",
            "--nu",
            "0.3",
            "--out",
            tmp_path / "m.vtu",
        ],
    ):
        p = subprocess.run(
            [sys.executable, "-m", "harness", *map(str, argv)],
            capture_output=True,
            text=True,
            timeout=300,
            cwd=tmp_path,
            env=env,
        )
        lines = p.stderr.strip().splitlines()
        assert p.returncode == 2 and len(lines) == 1 and "Traceback" not in p.stderr, p.stderr


COMMAND_CASES = (
    [f"score {c}" for c in SCORE_CASES]
    + [f"reference --points {c}" for c in POINTS]
    + BUILD_CASES
    + REPORT_CASES
    + RUN_CASES
    + SIMULATION_CASES
)
