"""An engine's answer and the pack it was made for: `engines run` writes the pack's digest
and rewrites its answer as each load finishes (Ctrl-C keeps the finished ones, and says how
many); `score --displacements` refuses an answer made for another pack, notes one without a
digest, and scores the loads an answer has unless --require-all. A tiny hand-made pack and
a fake engine keep these fast."""

import numpy as np
import pytest

import harness.engines
from harness import cli
from harness.engines.settle import Answer
from harness.export.pack import DIGEST_KEY, Pack, PackLoad, pack_digest, read_pack, write_pack

POINTS = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], float)
TETS = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
NAMES = ("sxx", "syy", "tip")


def tiny_pack(folder, held=(0,)):
    """Five nodes, two tets, three loads held at ``held``: written and read back."""
    held = np.asarray(held, int)
    loads = []
    for k, name in enumerate(NAMES):
        u = np.zeros((5, 3))
        u[:, k] = 1e-3 * POINTS[:, k] + 1e-4
        u[held] = 0.0
        force = np.zeros((5, 3))
        force[4, k] = 1.0
        loads.append(
            PackLoad(name, "heldout", held, np.ones((len(held), 3), bool), force, u, np.zeros(5))
        )
    pack = Pack(POINTS, {"tetra": TETS}, 1e5, 0.3, 1000.0, tuple(loads))
    write_pack(pack, folder)
    return read_pack(folder)


def fake_engine(stop_after=None):
    """An adapter answering the FEM's own displacements; Ctrl-C after ``stop_after`` loads."""
    done = []

    def run(pack, options):
        out = {}
        for ld in pack.loads:
            if stop_after is not None and len(done) == stop_after:
                raise KeyboardInterrupt
            done.append(ld.name)
            out[ld.name] = Answer(ld.u_fem.copy(), "settled", steps=10)
        return out

    return run


@pytest.fixture
def engine(monkeypatch):
    def use(stop_after=None):
        monkeypatch.setattr(harness.engines, "adapter", lambda name: fake_engine(stop_after))

    return use


def run_cli(argv):
    try:
        return cli.main([str(a) for a in argv])
    except SystemExit as exc:
        return exc.code


def test_the_digest_tells_packs_apart(tmp_path):
    a = tiny_pack(tmp_path / "a")
    again = tiny_pack(tmp_path / "again")
    other = tiny_pack(tmp_path / "other", held=(0, 1))
    assert pack_digest(a) == pack_digest(again) != pack_digest(other)
    assert len(pack_digest(a)) == 16


def test_engines_run_writes_the_digest_and_score_checks_it(tmp_path, engine, capsys):
    """The answer carries the pack's digest; scored on another pack it is refused in one line."""
    pack = tiny_pack(tmp_path / "p")
    other = tiny_pack(tmp_path / "q", held=(0, 1))
    engine()
    u = tmp_path / "u.npz"
    assert run_cli(["engines", "run", "mujoco", tmp_path / "p", "--out", u]) == 0
    with np.load(u) as z:
        assert str(z[DIGEST_KEY]) == pack_digest(pack) and set(z.files) == {*NAMES, DIGEST_KEY}
    capsys.readouterr()
    assert run_cli(["score", "--displacements", u, tmp_path / "p"]) == 0
    assert capsys.readouterr().err == ""
    assert run_cli(["score", "--displacements", u, tmp_path / "q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert pack_digest(pack) in err[0] and pack_digest(other) in err[0]
    assert str(u) in err[0] and "engines run" in err[0] and err[0].endswith(")")


def test_an_answer_without_a_digest_is_scored_and_says_so(tmp_path, capsys):
    pack = tiny_pack(tmp_path / "p")
    np.savez(tmp_path / "u.npz", **{ld.name: ld.u_fem for ld in pack.loads})
    capsys.readouterr()
    assert run_cli(["score", "--displacements", tmp_path / "u.npz", tmp_path / "p"]) == 0
    out = capsys.readouterr()
    err = out.err.strip().splitlines()
    assert len(err) == 1 and "no pack digest" in err[0], err
    assert all(name in out.out for name in NAMES)


def test_score_takes_the_loads_an_answer_has(tmp_path, capsys):
    """The loads an answer has are scored and the others named, without --loads."""
    pack = tiny_pack(tmp_path / "p")
    fields = {ld.name: ld.u_fem for ld in pack.loads if ld.name != "syy"}
    np.savez(tmp_path / "u.npz", **fields, **{DIGEST_KEY: pack_digest(pack)})
    argv = ["score", "--displacements", tmp_path / "u.npz", tmp_path / "p"]
    capsys.readouterr()
    assert run_cli([*argv, "--out", tmp_path / "g.csv"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "syy" in err[0] and "1 of 3" in err[0], err
    import pandas as pd

    assert list(pd.read_csv(tmp_path / "g.csv").load) == ["sxx", "tip", "total"]
    assert run_cli([*argv, "--require-all"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'syy'" in err[0] and "--require-all" in err[0], err
    assert run_cli([*argv, "--loads", "sxx,syy"]) == 2  # a load asked for by name is needed
    assert "'syy'" in capsys.readouterr().err


@pytest.mark.parametrize("stop_after", [2, 0])
def test_ctrl_c_keeps_the_finished_loads(stop_after, tmp_path, engine, capsys):
    """Ctrl-C keeps the loads written so far and says how many, or that none were."""
    pack = tiny_pack(tmp_path / "p")
    engine(stop_after)
    u = tmp_path / "u.npz"
    capsys.readouterr()
    assert run_cli(["engines", "run", "mujoco", tmp_path / "p", "--out", u]) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "interrupted" in err[0], err
    if stop_after == 0:
        assert not u.exists() and "none of the 3 loads" in err[0], err
        return
    assert "2 of 3 loads kept" in err[0] and str(u) in err[0], err
    with np.load(u) as z:
        assert set(z.files) == {"sxx", "syy", DIGEST_KEY}
        assert np.array_equal(z["sxx"], pack.load("sxx").u_fem)
    capsys.readouterr()
    assert run_cli(["score", "--displacements", u, tmp_path / "p"]) == 0
    assert "tip" in capsys.readouterr().err  # the missing load named, the others scored


def test_engines_run_loads_keeps_the_full_packs_digest(tmp_path, engine):
    pack = tiny_pack(tmp_path / "p")
    engine()
    u = tmp_path / "u.npz"
    assert run_cli(["engines", "run", "mujoco", tmp_path / "p", "--loads", "tip", "--out", u]) == 0
    with np.load(u) as z:
        assert set(z.files) == {"tip", DIGEST_KEY} and str(z[DIGEST_KEY]) == pack_digest(pack)


def test_an_unsupported_load_leaves_no_field_and_score_takes_the_others(
    tmp_path, monkeypatch, capsys
):
    """An engine that cannot run a load (pybullet-fem: no nodal forces) answers it
    `unsupported` with NaN: `engines run` writes no field for it (exit 0), and `score`
    scores the others and names it as missing; a field of NaN would stop `score`."""
    from harness.engines.settle import unsupported

    def run(pack, options):
        return {
            ld.name: unsupported(pack, "no nodal forces")
            if ld.name == "tip"
            else Answer(ld.u_fem.copy(), "settled", steps=10)
            for ld in pack.loads
        }

    monkeypatch.setattr(harness.engines, "adapter", lambda name: run)
    tiny_pack(tmp_path / "p")
    u = tmp_path / "u.npz"
    assert run_cli(["engines", "run", "pybullet-fem", tmp_path / "p", "--out", u]) == 0
    with np.load(u) as z:
        assert set(z.files) == {"sxx", "syy", DIGEST_KEY}
    capsys.readouterr()
    assert run_cli(["score", "--displacements", u, tmp_path / "p"]) == 0
    captured = capsys.readouterr()
    assert "not scored: tip" in captured.err and "sxx" in captured.out


def test_newton_springs_refuses_a_kn_export_in_one_line(tmp_path):
    """A springs+kn export's kn terms have no Newton counterpart: refused in one line, not
    run silently as its springs alone."""
    import json

    from harness.engines.newton_engine import run_springs
    from harness.errors import SpringbenchError

    pack = tiny_pack(tmp_path / "p")
    model = {
        "particle_q": POINTS.tolist(),
        "particle_mass": [1.0] * 5,
        "spring_indices": [[0, 1], [1, 2]],
        "spring_stiffness": [1.0, 1.0],
        "dt_safe": 1e-3,
        "kn_nodes": [0, 1],
        "kn_stiffness": [1.0, 1.0],
    }
    path = tmp_path / "m.json"
    path.write_text(json.dumps(model))
    with pytest.raises(SpringbenchError) as exc:
        run_springs(pack, {"model": path})
    assert exc.value.field == "kn_nodes" and "springs+kn" in exc.value.message
