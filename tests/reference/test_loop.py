"""The adaptive reference's target loop (reference/adaptive/adapt.py, ``max_refine`` at or
above UNTIL_TOL: calibrate's default): it stops at the first level where every held-out
load's estimate is below tol, or before the level that would pass the dof cap, the same way
every time; a bounded ``max_refine`` keeps its count of levels; the estimate where it stops
against an independent finer solve (tests/independent/simplex.py) on a small rounded body.
The body: scikit-fem's ball of 64 tetrahedra stretched to a 0.6 x 0.24 x 0.2 m ellipsoid
(no mesher: the same mesh everywhere), clamped at its x0 cap, loaded at its x1 cap."""

from __future__ import annotations

import textwrap

import meshio
import numpy as np
import pytest
import skfem

import reference
from harness.case.reader import load_case
from reference.adaptive import adapt
from tests.independent import simplex

E, NU = 1000.0, 0.3
AXES = (0.3, 0.12, 0.1)
CUT = 0.1  # the clamp and tip boxes reach this far into each end


def _ellipsoid(folder) -> tuple:
    """(VTU path, scikit-fem mesh) of the stretched ball, every cell positively oriented."""
    m = skfem.MeshTet.init_ball(1)
    p = m.p * np.array(AXES)[:, None]
    t = m.t.copy()
    J = np.stack([p[:, t[i]] - p[:, t[0]] for i in (1, 2, 3)], axis=1).transpose(2, 0, 1)
    flip = np.linalg.det(J) < 0
    t[0, flip], t[1, flip] = m.t[1, flip], m.t[0, flip]
    path = folder / "ellipsoid.vtu"
    meshio.write(path, meshio.Mesh(p.T, [("tetra", t.T)]))
    return path, skfem.MeshTet(p, t)


def _case(folder, tol: float, max_refine: int = adapt.UNTIL_TOL):
    """Held out: a tip traction, clamped at x0; fitted: the homogeneous states (closed
    forms) and a sag on the same clamp (a clamped training state, no target of the loop:
    its estimate is above the tip's on every level)."""
    path, _ = _ellipsoid(folder)
    lo, hi = -AXES[0] + CUT, AXES[0] - CUT
    text = f"""
        name = "loop"
        dim = 3
        [body]
        shape = "mesh"
        file = "{path}"
        [body.parts]
        clamp = {{ box = [[-1.0, -1.0, -1.0], [{lo}, 1.0, 1.0]] }}
        tip = {{ box = [[{hi}, -1.0, -1.0], [1.0, 1.0, 1.0]] }}
        [material]
        E = {E}
        nu = {NU}
        density = 1.0
        [loads]
        set = "homogeneous3d"
        heldout = ["tip"]
        [[loads.case]]
        name = "tip"
        constraint = [{{ part = "clamp", components = "all" }}]
        traction = [{{ part = "tip", vector = [0.0, 0.0, -1.0] }}]
        [[loads.case]]
        name = "sag"
        gravity = [0.0, 0.0, -1.0]
        constraint = [{{ part = "clamp", components = "all" }}]
        [reference]
        max_refine = {max_refine}
        tol = {tol}
        """
    f = folder / "loop.toml"
    f.write_text(textwrap.dedent(text))
    return load_case(f)


def test_the_loop_stops_at_the_first_level_below_tol(tmp_path):
    """The held-out estimate below tol at the last level, not at the one before; the
    training state, still above tol, does not keep the loop going."""
    ref = reference.solve(_case(tmp_path, 0.11), cache=False)
    assert ref.stop.reason == "tol" and ref.targets == ("tip",)
    assert ref.history[-1]["tip"] < 0.11 <= ref.history[-2]["tip"]
    assert ref.history[-1]["sag"] >= 0.11  # not a target
    assert ref.stop.n_dofs == ref.history[-1]["n_dofs"] == ref.n_dofs


def test_the_loop_stops_at_the_cap_the_same_way_twice(tmp_path, monkeypatch):
    monkeypatch.setitem(adapt.TARGET_DOFS, 3, 5_000)
    case = _case(tmp_path, 1e-9)
    one, two = (reference.solve(case, cache=False) for _ in range(2))
    assert one.stop.reason == "cap" and one.stop.cap == 5_000
    assert one.n_dofs <= 5_000 < max(one.stop.next_dofs, adapt.GROWTH_MIN * one.n_dofs)
    assert one.stop == two.stop
    rows = [[list(h.values()) for h in r.history] for r in (one, two)]
    np.testing.assert_array_equal(*rows)
    pts = one.mesh.p.T
    for load in ("tip", "sag"):
        np.testing.assert_array_equal(one.displacement(pts, load), two.displacement(pts, load))
        np.testing.assert_array_equal(one.error_estimate(pts, load), two.error_estimate(pts, load))


def test_a_bounded_max_refine_keeps_its_levels(tmp_path):
    """max_refine 1: three bisection steps within MAX_DOFS, all clamped loads marking with
    LEAST, whatever tol; the levels' dofs and estimates are those of the method's fixed
    count (a change here changes every published case that sets max_refine)."""
    ref = reference.solve(_case(tmp_path, 1e-9, max_refine=1), cache=False)
    assert ref.stop.reason == "steps" and ref.stop.cap == adapt.MAX_DOFS[3]
    assert [h["n_dofs"] for h in ref.history] == [387, 477, 663, 912]
    assert ref.error_estimate["tip"] == pytest.approx(0.26659693, rel=1e-6)


@pytest.mark.filterwarnings("ignore:invalid value encountered in log:RuntimeWarning")
def test_a_mesh_the_cap_leaves_no_room_is_estimated_from_coarser_meshes(tmp_path, monkeypatch):
    """The path only: the 25-vertex body's coarse grids (123 and 111 dofs) are too crude for
    an order (tests/reference/test_coarse.py checks that estimate)."""
    monkeypatch.setitem(adapt.TARGET_DOFS, 3, 1_000)  # 387 dofs x TARGET_ROOM (4) > 1000
    ref = reference.solve(_case(tmp_path, 1e-9), cache=False)
    assert ref.stop.reason == "coarse" and ref.n_dofs == 387 and len(ref.history) == 1


def test_the_stop_comes_back_from_the_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("SPRINGBENCH_CACHE", str(tmp_path / "cache"))
    monkeypatch.setitem(adapt.TARGET_DOFS, 3, 2_000)
    case = _case(tmp_path, 1e-9)
    ref, again = reference.solve(case), reference.solve(case)
    assert again.from_cache and again.stop == ref.stop and ref.stop.reason == "cap"


@pytest.mark.slow
def test_the_estimate_where_the_loop_stops_against_an_independent_finer_solve(
    tmp_path, monkeypatch
):
    """The loop stopped at a cap of 2k dofs; the truth: the loop's mesh at a cap of 20k
    dofs (its own estimate below half the stopped level's true error) solved by
    tests/independent/simplex.py (its own assembly, constraints, loads and solver; it
    matches the product on that mesh to rounding). At the user's vertices the estimate
    is at least half the true error wherever that error is above a tenth of its largest
    (the largest: at least that too) and at most 5x the largest true error."""
    case = _case(tmp_path, 1e-9)
    runs = {}
    for cap in (2_000, 20_000):
        monkeypatch.setitem(adapt.TARGET_DOFS, 3, cap)
        runs[cap] = reference.solve(case, cache=False)
    coarse, fine = runs[2_000], runs[20_000]
    _, user = _ellipsoid(tmp_path)
    lo, hi = -AXES[0] + CUT, AXES[0] - CUT
    clamp = simplex.part(user, (-1.0, -1.0, -1.0), (lo, 1.0, 1.0))
    tip = simplex.part(user, (hi, -1.0, -1.0), (1.0, 1.0, 1.0))
    loads = {"tip": ((tip, (0.0, 0.0, -1.0)), None), "sag": (None, (0.0, 0.0, -1.0))}
    basis, U = simplex.solve(fine.mesh, E, NU, clamp, loads)
    pts = user.p.T
    for load, u in U.items():
        truth = simplex.at_vertices(basis, u, len(pts))
        umax = np.linalg.norm(truth, axis=1).max()
        assert np.abs(fine.displacement(pts, load) - truth).max() < 1e-9 * umax
        err = np.linalg.norm(coarse.displacement(pts, load) - truth, axis=1)
        assert fine.error_estimate[load] * umax < 0.5 * err.max()  # the truth: much finer
        e = coarse.error_estimate(pts, load)
        big = err > 0.1 * err.max()
        assert np.all(e[big] >= 0.5 * err[big]), np.min(e[big] / err[big])
        assert 0.5 * err.max() <= e.max() <= 5.0 * err.max(), (e.max(), err.max())
