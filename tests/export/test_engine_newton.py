"""Engine round trip: the JSON of a calibrated tet mesh and of a triangle mesh
loaded into NVIDIA Newton (``ModelBuilder.add_particle`` / ``add_spring``, float32, CPU; constants
by the best rule, which
is deterministic where a wall-time fit budget is not),
run with ``SolverSemiImplicit`` at the exported ``dt_stable_float32`` and ``spring_damping``
to static equilibrium under the held-out loads, against springbench's own statics of the
same network and the FEM."""

import json

import numpy as np
import pytest

from harness import cli
from harness.case.default_loads import end_loads
from harness.case.reader import load_case
from harness.commands import calibrate_case
from harness.commands.calibrate_settings import Settings
from harness.export.vtu import read_vtu
from harness.io.meshfile import read_mesh
from harness.mechanics import statics
from tests import meshes

pytest.importorskip("gmsh")
newton = pytest.importorskip("newton")
wp = pytest.importorskip("warp")

E, NU, RHO, S = 1e7, 0.3, 1000.0, 1e3  # S: the tip traction, 1e-4 E (small rotations)


def calibrated(tmp_path, mesh, *argv):
    out = tmp_path / "m.vtu"
    assert (
        cli.main(
            [
                "calibrate",
                str(mesh),
                "--E",
                str(E),
                "--nu",
                str(NU),
                "--density",
                str(RHO),
                "--magnitude",
                str(S),
                "--method",
                "rule",
                "--max-refine",
                "0",  # deterministic: no wall-time budget
                "--out",
                str(out),
                *argv,
            ]
        )
        == 0
    )
    m = read_mesh(mesh)
    args = Settings(
        mesh=mesh,
        out=out,
        E=E,
        nu=NU,
        density=RHO,
        magnitude=S,
        rule="lloyd",
        method="rule",
        loads="homogeneous",
        max_refine=0,
    )
    (tmp_path / "c.toml").write_text(
        calibrate_case.case_text(args, m.dim, m.cells, ends=end_loads(m.points, m.cells))
    )
    net, _ = read_vtu(out)
    return json.loads(out.with_suffix(".json").read_text()), load_case(tmp_path / "c.toml"), net


def newton_equilibrium(data, fixed, force, max_steps=150_000):
    """Particles and springs exactly as the JSON says (clamped particles get mass 0), its
    volume terms as Newton tetrahedra with k_mu = 0, k_lambda = kv (Newton's Neo-Hookean
    energy is then kv/2 V0 (J - 1)^2, the exported term's kv/2 (V - V0)^2 / V0), the load
    as external particle forces, a little extra velocity damping to settle."""
    b = newton.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    q = np.asarray(data["particle_q"], float)
    for i, (x, m) in enumerate(zip(q, data["particle_mass"])):
        b.add_particle(
            wp.vec3(*x), wp.vec3(0.0, 0.0, 0.0), 0.0 if fixed[i] else float(m), radius=0.0
        )
    for (i, j), ke, kd in zip(
        data["spring_indices"], data["spring_stiffness"], data["spring_damping"]
    ):
        b.add_spring(int(i), int(j), float(ke), float(kd), 0.0)
    for (i, j, k, l), kv in zip(data.get("volume_indices", []), data.get("volume_stiffness", [])):
        b.add_tetrahedron(int(i), int(j), int(k), int(l), k_mu=0.0, k_lambda=float(kv), k_damp=0.0)
    model = b.finalize(device="cpu")
    solver = newton.solvers.SolverSemiImplicit(model)
    s0, s1, control = model.state(), model.state(), model.control()
    f3 = np.zeros((len(q), 3), np.float32)
    f3[:, : force.shape[1]] = force
    fext = wp.array(f3, dtype=wp.vec3, device="cpu")
    dt = float(data["dt_stable_float32"])
    prev = None
    for step in range(max_steps):
        s0.clear_forces()
        wp.copy(s0.particle_f, fext)
        solver.step(s0, s1, control, None, dt)
        s0, s1 = s1, s0
        if step % 20 == 0:
            s0.particle_qd.assign(0.97 * s0.particle_qd.numpy())
        if step % 2000 == 1999:
            u = s0.particle_q.numpy().astype(float) - q
            # float32 positions: their rounding
            ulp = float(np.spacing(np.float32(np.abs(q).max())))
            if prev is not None and np.abs(u - prev).max() < max(1e-4 * np.abs(u).max(), 4 * ulp):
                return u[:, : force.shape[1]], step
            prev = u
    raise AssertionError("Newton did not settle")


@pytest.mark.slow
@pytest.mark.parametrize("which", ["cylinder", "holed_plate"])
def test_newton_reproduces_springbench_statics_and_the_fem(tmp_path, which):
    import reference

    mesh = meshes.cylinder(tmp_path) if which == "cylinder" else meshes.holed_plate(tmp_path)
    data, case, net = calibrated(tmp_path, mesh)
    assert data["dt_stable_float32"] > 0 and min(data["particle_mass"]) > 0
    res = statics.solve(net, case)
    fem = reference.solve(case, cache=False)
    for name in ("sag", "tip"):
        load = next(l for l in case.loads if l.name == name)
        fixed = statics.fixed_mask(net.points, case, load).any(axis=1)
        u_sb = res.u[res.names.index(name)]
        u_nt, steps = newton_equilibrium(data, fixed, statics.force_vector(net, case, load))
        scale = np.abs(u_sb).max()
        assert np.abs(u_nt - u_sb).max() <= 0.01 * scale, (name, steps)  # the engine runs our model
        u_fem = fem.displacement(net.points, name)
        e_nt, e_sb = (np.sqrt(np.mean(np.sum((u - u_fem) ** 2, axis=1))) for u in (u_nt, u_sb))
        # and is as good against the FEM
        assert abs(e_nt - e_sb) <= 0.01 * np.abs(u_fem).max(), name


@pytest.mark.slow
def test_newton_runs_springs_plus_volume_as_tetrahedra(tmp_path):
    """springs + one volume term per tetrahedron (calibrate --model springs+volume-element):
    in Newton the springs plus tetrahedra with k_mu = 0, k_lambda = kv reach springbench's own
    linear statics of the same model (the volume term changes the answer, so a Newton
    model that ignored it would fail)."""
    from harness.models.volume import with_volume

    mesh = meshes.cylinder(tmp_path)
    data, case, net = calibrated(tmp_path, mesh, "--model", "springs+volume-element")
    assert (
        len(data["volume_indices"]) == len(read_mesh(mesh).cells["tetra"])
        and min(data["volume_stiffness"]) > 0
    )
    vnet = with_volume(
        net, "element", np.asarray(data["volume_stiffness"]), np.asarray(data["volume_indices"])
    )
    res, plain = statics.solve(vnet, case), statics.solve(net, case)
    load_ = next(l for l in case.loads if l.name == "tip")
    fixed = statics.fixed_mask(net.points, case, load_).any(axis=1)
    u_sb = res.displacement("tip")
    # the term matters
    assert np.abs(plain.displacement("tip") - u_sb).max() > 0.05 * np.abs(u_sb).max()
    u_nt, steps = newton_equilibrium(data, fixed, statics.force_vector(net, case, load_))
    assert np.sqrt(np.sum((u_nt - u_sb) ** 2) / np.sum(u_sb**2)) <= 1e-3, steps


@pytest.mark.slow
def test_the_documented_newton_recipe_reaches_springbench_statics(tmp_path):
    """docs/calibrate.md's Newton snippet, run as printed on a calibrated cylinder's JSON:
    its clamped_nodes, loaded_nodes and forces are the ones springbench's statics holds
    and applies, and dt_safe with settle_damping settles the sag within the snippet's
    5,000 steps to 1e-3 (L2) of springbench's own statics."""
    import re
    from pathlib import Path

    mesh = meshes.cylinder(tmp_path)
    data, case, net = calibrated(tmp_path, mesh)
    res = statics.solve(net, case)
    for load in case.loads:
        f = np.zeros((net.n_nodes, 3))
        f[data["loaded_nodes"][load.name]] = data["forces"][load.name]
        assert np.allclose(f, statics.force_vector(net, case, load), rtol=1e-8, atol=0), load.name
        fixed = statics.fixed_mask(net.points, case, load)
        rows = data["clamped_nodes"][load.name]
        assert rows["nodes"] == np.flatnonzero(fixed.any(axis=1)).tolist(), load.name
        assert rows["components"] == [np.flatnonzero(r).tolist() for r in fixed[rows["nodes"]]], (
            load.name
        )
    doc = (Path(__file__).parents[2] / "docs" / "calibrate.md").read_text()
    snippet = re.search(r"In NVIDIA Newton.*?```python\n(.*?)```", doc, re.S).group(1)
    space = {"d": data, "L": "sag"}
    exec(snippet, space)
    u_sb = res.displacement("sag")
    assert np.sqrt(np.sum((space["u"] - u_sb) ** 2) / np.sum(u_sb**2)) <= 1e-3
