"""``engines run newton-tets | mujoco-flex PACK --model MODEL.json``: a calibrated material
for the engines' own tetrahedra (calibrate --model p1 or p1-global; harness/engines/
tet_material.py), against a linear P1 solve assembled here with numpy from the same
per-tetrahedron (E, nu).

A box beam clamped at x = 0 under gravity sag and a tip traction, each scaled so the P1
answer's largest strain is PEAK (the engines' nonlinear materials are their linearisation
to about that: the bound is 3 PEAK, plus four float32 spacings for Newton, as in
tests/engines/test_adapters_p1.py). newton-tets runs two regions (x < L/2 and beyond)
of different E and nu; mujoco-flex one pair; the pack's own material is a third. The JSON
lists its tetrahedra shuffled, each oriented (V0 > 0) and its nodes cycled, as a
calibrate export of a negatively oriented mesh does: the adapters match them by node sets.
A broken adapter (the model ignored, k_mu and k_lambda swapped, the per-tet arrays taken
in the JSON's row order, the pair's nu dropped) fails the check; every refusal is one line
naming the file, the field and the fix; the model run is in U.npz and in score's output.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from harness import cli
from harness.errors import SpringbenchError
from harness.export.pack import Pack, PackLoad, write_pack
from tests.independent import p1_bodies as P1
from tests.run.test_robustness import names_a_fix

E_PACK, NU_PACK, RHO = 1e5, 0.3, 1000.0  # the pack's own material
REGIONS = ((5e4, 0.45), (2e5, 0.25))  # newton-tets: x < L/2, x >= L/2
PAIR = (6e4, 0.42)  # mujoco-flex
MAX_STEPS = 12_000  # good runs settle in a few thousand steps; a broken one stops here


def _oriented(points, tets):
    """Two nodes swapped where the signed volume is negative (a mesh every reader takes)."""
    t = tets.copy()
    neg = np.linalg.det(points[t[:, 1:]] - points[t[:, :1]]) < 0
    t[neg, 0], t[neg, 1] = tets[neg, 1], tets[neg, 0]
    return t


@functools.cache
def mesh():
    m = P1.beam_mesh()
    points = m.p.T.copy()
    return points, _oriented(points, m.t.T.copy())


def materials(kind: str):
    """(E, nu) per tetrahedron of the mesh: 'regions', 'pair' or 'pack'."""
    points, tets = mesh()
    x = points[tets].mean(axis=1)[:, 0]
    if kind == "regions":
        far = x >= 0.5 * points[:, 0].max()
        return (
            np.where(far, REGIONS[1][0], REGIONS[0][0]),
            np.where(far, REGIONS[1][1], REGIONS[0][1]),
        )
    E, nu = {"pair": PAIR, "pack": (E_PACK, NU_PACK)}[kind]
    return np.full(len(tets), E), np.full(len(tets), nu)


def p1_stiffness(points, tets, E, nu):
    """K (csr, node-major dofs) of linear P1 elasticity with one (E, nu) per tetrahedron:
    sum_e V_e B_e^T D_e B_e (Voigt, engineering shear)."""
    m = len(tets)
    M = np.concatenate([np.ones((m, 4, 1)), points[tets]], axis=2)  # rows [1, x, y, z]
    grad = np.linalg.inv(M)[:, 1:, :].transpose(0, 2, 1)  # (m, 4, 3): grad of each hat
    vol = np.abs(np.linalg.det(M)) / 6.0
    B = np.zeros((m, 6, 12))
    for a in range(4):
        gx, gy, gz = grad[:, a, 0], grad[:, a, 1], grad[:, a, 2]
        c = 3 * a
        B[:, 0, c], B[:, 1, c + 1], B[:, 2, c + 2] = gx, gy, gz
        B[:, 3, c], B[:, 3, c + 1] = gy, gx
        B[:, 4, c + 1], B[:, 4, c + 2] = gz, gy
        B[:, 5, c], B[:, 5, c + 2] = gz, gx
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    mu = E / (2 * (1 + nu))
    D = np.zeros((m, 6, 6))
    D[:, :3, :3] = lam[:, None, None]
    D[:, [0, 1, 2], [0, 1, 2]] += 2 * mu[:, None]
    D[:, [3, 4, 5], [3, 4, 5]] = mu[:, None]
    Ke = vol[:, None, None] * np.einsum("mji,mjk,mkl->mil", B, D, B)
    dof = (3 * tets[:, :, None] + np.arange(3)).reshape(m, 12)
    rows = np.broadcast_to(dof[:, :, None], Ke.shape)
    cols = np.broadcast_to(dof[:, None, :], Ke.shape)
    n = 3 * len(points)
    return sp.coo_matrix((Ke.ravel(), (rows.ravel(), cols.ravel())), (n, n)).tocsr()


@functools.cache
def pack_of(kind: str) -> Pack:
    """The beam as a pack of the pack's own material whose loads' answers are the P1
    solve of ``kind``'s material (each load scaled to PEAK)."""
    points, tets = mesh()
    E, nu = materials(kind)
    K = p1_stiffness(points, tets, E, nu)
    ref = P1.body("beam", P1.beam_mesh(), E_PACK, NU_PACK, RHO)  # the loads' shapes
    clamped = ref.clamped
    free = np.ones(points.shape, bool)
    free[clamped] = False
    dofs = np.flatnonzero(free.ravel())
    held, nan = np.ones((len(clamped), 3), bool), np.full(len(points), np.nan)
    loads = []
    for name in ("sag", "tip"):
        f = ref.forces[name].ravel()
        u = np.zeros(f.size)
        u[dofs] = spla.spsolve(K[dofs][:, dofs].tocsc(), f[dofs])
        s = P1.PEAK / P1.peak_strain(points, tets, u.reshape(-1, 3))
        loads.append(
            PackLoad(
                name, "heldout", clamped, held, s * f.reshape(-1, 3), s * u.reshape(-1, 3), nan
            )
        )
    return Pack(points, {"tetra": tets}, E_PACK, NU_PACK, RHO, tuple(loads), None, {})


def export_of(kind: str, **change) -> dict:
    """A material export's keys (harness/export/model_json.py) for ``kind``'s material,
    its rows shuffled and each row's nodes cycled (orientation kept); ``change`` replaces
    keys."""
    points, tets = mesh()
    E, nu = materials(kind)
    order = np.random.default_rng(0).permutation(len(tets))
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    one = kind != "regions"
    data = {
        "particle_q": points.tolist(),
        "tet_indices": tets[order][:, [1, 2, 0, 3]].tolist(),  # an even permutation
        "tet_E": E[order].tolist(),
        "tet_nu": nu[order].tolist(),
        "tet_k_mu": (4 / 3 * mu)[order].tolist(),
        "tet_k_lambda": (lam + 5 / 6 * mu)[order].tolist(),
        "E_effective": float(E[0]) if one else None,
        "nu_effective": float(nu[0]) if one else None,
    }
    data.update(change)
    return data


def write(tmp_path, data: dict, name="model.json"):
    path = tmp_path / name
    path.write_text(json.dumps(data))
    return path


def errors(engine: str, kind: str, tmp_path) -> dict:
    """{load: (status, relative error against the P1 solve, bound)} of ``engine`` running
    ``kind``'s export on the pack."""
    pack = pack_of(kind)
    found = compared(engine, pack, write(tmp_path, export_of(kind)))
    print(engine, kind, found)
    return found


def compared(engine: str, pack: Pack, model) -> dict:
    """{load: (status, relative error against the load's u_fem, bound)} of ``engine``
    running ``model`` on ``pack``: the bound is 3 PEAK, plus four float32 spacings over
    the RMS displacement for Newton (tests/engines/test_adapters_p1.py)."""
    from harness.engines import adapter
    from harness.engines.settle import float32_resolution

    answers = adapter(engine)(pack, {"model": model})
    res = float32_resolution(pack.points) if engine.startswith("newton") else 0.0
    out = {}
    for ld in pack.loads:
        u, a = ld.u_fem, answers[ld.name]
        rms = math.sqrt(float(np.mean(np.sum(u * u, axis=1))))
        err = float(np.linalg.norm(a.u - u) / np.linalg.norm(u))
        out[ld.name] = (a.status, err, 3.0 * P1.PEAK + 4.0 * res / rms)
    return out


def check(found: dict) -> None:
    for name, (status, err, bound) in found.items():
        assert status == "settled" and err <= bound, (name, status, err, bound)


@pytest.fixture
def capped(monkeypatch):
    """Every adapter's settle stops at MAX_STEPS (a broken run ends in seconds)."""
    from harness.engines import mujoco_flex, newton_engine, settle

    capped = functools.partial(settle.settle, max_steps=MAX_STEPS)
    monkeypatch.setattr(newton_engine, "settle", capped)
    monkeypatch.setattr(mujoco_flex, "settle", capped)


ENGINE_KIND = {"newton-tets": "regions", "mujoco-flex": "pair"}


@pytest.mark.parametrize("engine", sorted(ENGINE_KIND))
def test_each_engine_runs_the_calibrated_material(engine, tmp_path, capped):
    pytest.importorskip(engine.split("-")[0])
    check(errors(engine, ENGINE_KIND[engine], tmp_path))


def _break(monkeypatch, variant: str):
    """Patch an adapter into the broken ``variant``; the engine it breaks."""
    from harness.engines import mujoco_flex, newton_engine, tet_material

    if variant == "newton: model ignored":
        materials_ = newton_engine._materials
        monkeypatch.setattr(
            newton_engine, "_materials", lambda pack, tets, m, d: materials_(pack, tets, None, d)
        )
    elif variant == "newton: k_mu, k_lambda swapped":
        material = newton_engine.material
        monkeypatch.setattr(
            newton_engine,
            "material",
            lambda *a: (lambda m: dataclasses.replace(m, k_mu=m.k_lambda, k_lambda=m.k_mu))(
                material(*a)
            ),
        )
    elif variant == "newton: per-tet arrays in the JSON's row order":
        monkeypatch.setattr(tet_material, "match", lambda t, pack_tets: np.arange(len(t)))
    elif variant == "mujoco: model ignored":
        monkeypatch.setattr(mujoco_flex, "_material", lambda pack, *a: (pack.E, pack.nu))
    elif variant == "mujoco: nu_effective dropped (the pack's nu)":
        material_ = mujoco_flex._material
        monkeypatch.setattr(
            mujoco_flex, "_material", lambda pack, *a: (material_(pack, *a)[0], pack.nu)
        )
    return "newton-tets" if variant.startswith("newton") else "mujoco-flex"


@pytest.mark.parametrize(
    "variant",
    [
        "newton: model ignored",
        "newton: k_mu, k_lambda swapped",
        "newton: per-tet arrays in the JSON's row order",
        "mujoco: model ignored",
        "mujoco: nu_effective dropped (the pack's nu)",
    ],
)
def test_a_broken_adapter_fails_the_check(monkeypatch, tmp_path, capped, variant):
    engine = _break(monkeypatch, variant)
    pytest.importorskip(engine.split("-")[0])
    mujoco = pytest.importorskip("mujoco")
    previous, seen = mujoco.get_mju_user_warning(), []
    mujoco.set_mju_user_warning(seen.append)  # else MuJoCo logs unstable steps in the cwd
    try:
        found = errors(engine, ENGINE_KIND[engine], tmp_path)
    finally:
        mujoco.set_mju_user_warning(previous)
    with pytest.raises(AssertionError):
        check(found)


def test_the_json_tetrahedra_match_the_pack_by_node_sets():
    """Rows shuffled, nodes cycled: each pack tetrahedron finds its JSON row; another set
    (a row dropped, a node changed, a row repeated) is no match."""
    from harness.engines.tet_material import match

    _, tets = mesh()
    order = np.random.default_rng(1).permutation(len(tets))
    shuffled = tets[order][:, [2, 0, 1, 3]]
    rows = match(shuffled, tets)
    assert np.array_equal(np.sort(shuffled[rows], axis=1), np.sort(tets, axis=1))
    other = tets.copy()
    other[0, 0] = other[1, 3] if other[1, 3] not in other[0] else other[2, 3]
    twice = tets.copy()
    twice[1] = tets[0]
    assert match(tets[1:], tets) is None and match(other, tets) is None
    assert match(twice, tets) is None


# -- the command line: the record of the model run, and every refusal in one line ------------


@pytest.fixture
def on_disk(tmp_path):
    """(the 'pair' pack written as a benchmark pack, its folder)."""
    folder = tmp_path / "pack"
    write_pack(pack_of("pair"), folder)
    return folder


def test_the_model_run_is_in_the_answer_and_in_score(on_disk, tmp_path, capsys, capped):
    pytest.importorskip("mujoco")
    import hashlib

    from harness.engines.tet_material import MODEL_KEY

    model = write(tmp_path, export_of("pair"))
    digest = hashlib.sha256(model.read_bytes()).hexdigest()[:16]
    u, log, scored = tmp_path / "u.npz", tmp_path / "log.csv", tmp_path / "s.csv"
    argv = ["engines", "run", "mujoco-flex", on_disk, "--model", model, "--loads", "tip"]
    assert cli.main([str(a) for a in [*argv, "--out", u, "--log", log]]) == 0
    ran = capsys.readouterr().out
    assert f"model {model} (sha256 {digest}" in ran and "E_effective 60000 Pa" in ran, ran
    with np.load(u) as z:
        record = json.loads(str(z[MODEL_KEY]))
        assert set(z.files) == {"tip", "__pack_digest__", MODEL_KEY}
    assert (record["sha256"], record["E_effective"], record["nu_effective"]) == (digest, *PAIR)
    assert cli.main(["score", "--displacements", str(u), str(on_disk), "--out", str(scored)]) == 0
    out = capsys.readouterr().out
    assert f"the engine ran model {model} (sha256 {digest}" in out and "lumped" in out, out
    import pandas as pd

    df, runs = pd.read_csv(scored), pd.read_csv(log)
    assert list(df.columns[-2:]) == ["model", "model_sha256"] and df["status"].iloc[0] == "ok"
    assert df["G_norm"].iloc[0] <= 3.0 * P1.PEAK  # the pack's u_fem: the P1 solve of PAIR
    assert list(runs.columns[:2]) == ["load", "status"] and set(runs.model_sha256) == {digest}


def one_line(argv, capsys, *must) -> str:
    code = cli.main([str(a) for a in argv])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("springbench")]
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert all(m in lines[0] for m in must) and names_a_fix(lines[0]), (must, lines[0])
    return lines[0]


SPRINGS = {
    "particle_q": [[0.0, 0.0, 0.0]],
    "particle_mass": [1.0],
    "spring_indices": [],
    "spring_stiffness": [],
}


def _bad_exports() -> dict:
    """name -> (engine, JSON keys or raw text, the words the line must hold)."""
    regions, pair = export_of("regions"), export_of("pair")
    flipped = [list(t) for t in pair["tet_indices"]]
    flipped[3][0], flipped[3][1] = flipped[3][1], flipped[3][0]
    k_off = list(pair["tet_k_mu"])
    k_off[5] *= 1.01
    E_null = list(pair["tet_E"])
    E_null[2] = None
    differ = dict(pair, tet_E=regions["tet_E"], tet_nu=regions["tet_nu"])
    differ.update(tet_k_mu=regions["tet_k_mu"], tet_k_lambda=regions["tet_k_lambda"])
    return {
        "springs to newton-tets": ("newton-tets", SPRINGS, ("tet_indices", "springs export")),
        "springs to mujoco-flex": ("mujoco-flex", SPRINGS, ("tet_indices", "springs export")),
        "tets to newton-springs": ("newton-springs", pair, ("tet_indices", "newton-tets")),
        "tets to mujoco-springs": ("mujoco-springs", pair, ("tet_indices", "newton-tets")),
        "per-tet to mujoco-flex": ("mujoco-flex", regions, ("E_effective", "newton-tets")),
        "elements differ from the pair": ("mujoco-flex", differ, ("tet_E", "p1-global")),
        "a tetrahedron dropped": (
            "newton-tets",
            dict(pair, tet_indices=pair["tet_indices"][1:]),
            ("tet_indices", "not the pack's", "calibrate the pack's own mesh"),
        ),
        "another node count": (
            "mujoco-flex",
            dict(pair, particle_q=pair["particle_q"][:-1]),
            ("particle_q", "calibrate the pack's own mesh"),
        ),
        "a node out of range": (
            "newton-tets",
            dict(pair, tet_indices=[[0, 1, 2, 999]] + pair["tet_indices"][1:]),
            ("tet_indices", "999"),
        ),
        "a negative volume": (
            "newton-tets",
            dict(pair, tet_indices=flipped),
            ("tet_indices", "volume <= 0", "orients"),
        ),
        "k_mu not 4/3 mu": ("newton-tets", dict(pair, tet_k_mu=k_off), ("tet_k_mu", "row 5")),
        "a null E": ("newton-tets", dict(pair, tet_E=E_null), ("tet_E", "null")),
        "not JSON": ("newton-tets", "{not json", ("--model", "unreadable")),
    }


@pytest.mark.parametrize("name", sorted(_bad_exports()))
def test_a_wrong_export_is_one_line(name, on_disk, tmp_path, capsys):
    engine, data, must = _bad_exports()[name]
    pytest.importorskip(engine.split("-")[0])  # the adapter checks the package first
    path = tmp_path / "bad.json"
    path.write_text(data if isinstance(data, str) else json.dumps(data))
    argv = ["engines", "run", engine, on_disk, "--model", path, "--out", tmp_path / "u.npz"]
    line = one_line(argv, capsys, str(path), *must)
    assert not (tmp_path / "u.npz").exists(), line


@pytest.mark.parametrize("engine", ["pybullet-fem", "drake-fem"])
def test_an_engine_of_its_own_material_refuses_a_model(engine, on_disk, tmp_path, capsys):
    """At the command line (before the engine is imported) and in the adapter itself."""
    from harness.engines.settle import no_model

    path = write(tmp_path, export_of("pair"))
    argv = ["engines", "run", engine, on_disk, "--model", path, "--out", tmp_path / "u.npz"]
    one_line(argv, capsys, "--model", engine, "newton-tets", "mujoco-flex")
    with pytest.raises(SpringbenchError, match="takes no model"):
        no_model({"model": path}, engine)
    if engine == "pybullet-fem":
        pytest.importorskip("pybullet")
        from harness.engines import pybullet_fem

        with pytest.raises(SpringbenchError, match="takes no model"):
            pybullet_fem.run(pack_of("pair"), {"model": path})


def test_a_real_p1_global_export_runs_on_the_pack_of_its_mesh(tmp_path, monkeypatch, capped):
    """``calibrate --model p1-global`` on a mesh whose tetrahedra are all negatively
    oriented (calibrate orients them, the pack keeps them: the arrays differ, the node sets
    agree) runs in mujoco-flex and newton-tets at the P1 answer of its (E_effective,
    nu_effective)."""
    pytest.importorskip("mujoco")
    pytest.importorskip("newton")
    import meshio

    monkeypatch.setenv("SPRINGBENCH_CACHE", str(tmp_path / "cache"))
    points, tets = mesh()
    flipped = tets[:, [1, 0, 2, 3]]
    meshio.write(tmp_path / "beam.vtu", meshio.Mesh(points, [("tetra", flipped)]))
    out = tmp_path / "m.vtu"
    argv = ["calibrate", tmp_path / "beam.vtu", "--E", E_PACK, "--nu", NU_PACK]
    argv += ["--density", RHO, "--model", "p1-global", "--max-refine", "0", "--quiet"]
    assert cli.main([str(a) for a in [*argv, "--out", out]]) == 0
    data = json.loads(out.with_suffix(".json").read_text())
    assert not np.array_equal(data["tet_indices"], flipped)  # calibrate oriented them
    E, nu = data["E_effective"], data["nu_effective"]
    K = p1_stiffness(points, tets, np.full(len(tets), E), np.full(len(tets), nu))
    base = pack_of("pack")
    free = np.ones(points.shape, bool)
    free[base.loads[0].held_nodes] = False
    dofs = np.flatnonzero(free.ravel())
    loads = []
    for ld in base.loads:
        u = np.zeros(points.size)
        u[dofs] = spla.spsolve(K[dofs][:, dofs].tocsc(), ld.force.ravel()[dofs])
        loads.append(dataclasses.replace(ld, u_fem=u.reshape(-1, 3)))
    pack = dataclasses.replace(base, cells={"tetra": flipped}, loads=tuple(loads))
    for engine in ("mujoco-flex", "newton-tets"):
        found = compared(engine, pack, out.with_suffix(".json"))
        print(engine, E, nu, found)
        check(found)
