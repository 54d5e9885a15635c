"""`springbench pack --loads`: a mesh's pack holds by default the loads that judge an engine
(held out, FEM error estimate <= 1 % or none), `--loads all` every load."""

from __future__ import annotations

import json

import numpy as np
import pytest

from harness import cli
from harness.errors import SpringbenchError
from harness.export import pack_make
from harness.export.pack import Pack, PackLoad, read_pack
from tests import meshes

pytest.importorskip("gmsh")
HELDOUT = {"sag", "tip", "tip2", "torsion", "bridge"}
COARSE = "torsion"  # the load whose estimate is made 5 %, the others 0.2 %


def _estimates(ref, points, names):
    """An error estimate of 5 % of |u| max for COARSE and 0.2 % for the others."""
    u = pack_make.reference_displacements(ref, points, names)
    umax = np.linalg.norm(u, axis=-1).max(axis=1)
    frac = np.array([0.05 if n == COARSE else 0.002 for n in names])
    return np.repeat((frac * umax)[:, None], len(points), axis=1)


def _pack(mesh, out, *flags, estimated=False):
    argv = ["pack", str(mesh), "--E", "1e5", "--nu", "0.3", "--max-refine", "0", *flags]
    with pytest.MonkeyPatch.context() as mp:
        if estimated:
            mp.setattr(pack_make, "reference_error", _estimates)
        assert cli.main(argv + ["--out", str(out)]) == 0
    return json.loads((out / "problem.json").read_text()), read_pack(out)


@pytest.fixture(scope="module")
def mesh(tmp_path_factory):
    return meshes.cylinder(tmp_path_factory.mktemp("cyl"), size=0.08)


def test_a_mesh_pack_holds_only_held_out_loads_by_default(mesh, tmp_path, capsys):
    """Unestimated (--max-refine 0) held-out loads are kept, each with a line saying so."""
    man, pack = _pack(mesh, tmp_path / "p")
    assert {ld.name for ld in pack.loads} == HELDOUT
    assert {ld["role"] for ld in man["loads"]} == {"heldout"}
    assert man["load_set"] == "judged" and pack.meta["load_set"] == "judged"
    err = capsys.readouterr().err
    assert all(f"kept {n}: its FEM error is not estimated" in err for n in HELDOUT), err


def test_a_held_out_load_above_one_percent_is_left_out_and_named(mesh, tmp_path, capsys):
    man, pack = _pack(mesh, tmp_path / "p", estimated=True)
    assert {ld.name for ld in pack.loads} == HELDOUT - {COARSE}
    lines = [ln for ln in capsys.readouterr().err.splitlines() if "left out" in ln]
    assert len(lines) == 1 and COARSE in lines[0] and "5 %" in lines[0], lines
    assert man["load_set"] == "judged"


def test_loads_all_keeps_the_fitted_and_the_coarse_loads(mesh, tmp_path, capsys):
    man, pack = _pack(mesh, tmp_path / "p", "--loads", "all", estimated=True)
    roles = {ld.name: ld.role for ld in pack.loads}
    assert HELDOUT <= set(roles) and {n for n, r in roles.items() if r == "heldout"} == HELDOUT
    assert "fitted" in roles.values() and any(n.startswith("train-") for n in roles)
    assert man["load_set"] == "all" and "left out" not in capsys.readouterr().err


def _load(name, role, error):
    u = np.array([[1.0, 0.0], [0.0, 2.0]])
    return PackLoad(name, role, np.array([0]), np.ones((1, 2), bool), 0 * u, u, np.full(2, error))


def test_judged_keeps_the_estimate_at_the_bound_and_needs_one_load():
    loads = (
        _load("a", "heldout", 0.02),
        _load("b", "heldout", 0.021),
        _load("c", "fitted", 0.0),
    )
    pack = Pack(np.zeros((2, 2)), {"triangle": np.zeros((0, 3), int)}, 1.0, 0.3, 1.0, loads)
    kept, notes = pack_make.judged(pack)
    assert [ld.name for ld in kept.loads] == ["a"] and len(notes) == 1 and "b" in notes[0]
    with pytest.raises(SpringbenchError) as exc:
        pack_make.judged(Pack(pack.points, pack.cells, 1.0, 0.3, 1.0, loads[1:]))
    assert exc.value.field == "--loads" and "--loads all" in exc.value.fix
