"""Mirror-symmetric solves of boxes (reference/graded/symmetry.py): which loads are cut where,
and a solve on the cut box, unfolded, equals the solve of the whole box."""

import textwrap

import numpy as np
import pytest

from harness.case.reader import load_case
from reference.graded.levels import Levels
from reference.graded.meshes import graded_axes, tensor_mesh
from reference.graded.symmetry import mirror_of
from reference.mirror import Mirror
from reference.problem import solve_mesh

USER_LOADS = """
[[loads.case]]
name = "sag"
gravity = [0.0, 0.0, -9.81]
[[loads.case.constraint]]
part = "z0"
components = "all"

[[loads.case]]
name = "pinch"
[[loads.case.constraint]]
part = "x0"
components = "all"
[[loads.case.constraint]]
part = "x1"
components = "all"
[[loads.case.traction]]
part = "y0"
vector = [0.0, 2.0, 0.0]
[[loads.case.traction]]
part = "y1"
vector = [0.0, -2.0, 0.0]

[[loads.case]]
name = "patch"
[[loads.case.constraint]]
part = "x0"
components = "all"
[[loads.case.traction]]
part = "pad"
vector = [0.0, 0.0, 1.5]

[[loads.case]]
name = "lopsided"
[[loads.case.constraint]]
part = "x0"
components = "all"
[[loads.case.traction]]
part = "x1"
vector = [0.3, 1.0, 0.0]
"""


def write_case(
    tmp_path, material="E = 1000.0\nnu = 0.3", loads='set = "basic3d"', extra="", name="c"
):
    p = tmp_path / f"{name}.toml"
    p.write_text(
        textwrap.dedent(f"""
        name = "{name}"
        dim = 3
        [body]
        shape = "box"
        origin = [0.3, -1.2, 4.0]
        size = [2.0, 1.0, 1.5]
        {extra}
        [material]
        density = 2.0
        {material}
        """)
        + "[loads]\n"
        + loads
    )
    return load_case(p)


def test_which_loads_are_cut_and_how(tmp_path):
    case = write_case(tmp_path)
    m = {l.name: mirror_of(case, l) for l in case.loads}
    for a in "xyz":
        assert not m[f"stretch-{a}"]  # the corner constraints of a stretch are not mirror-invariant
    # shear-ab: b0 clamped, traction along a on b1: odd under the a-mirror, even under the third
    assert m["shear-xy"] == Mirror((0, 2), (-1, 1))
    assert m["shear-zy"] == Mirror((0, 2), (1, -1))
    assert m["shear-yz"] == Mirror((0, 1), (1, -1))
    user = write_case(
        tmp_path,
        loads=USER_LOADS,
        extra="parts = { pad = { box = [[0.8, -1.2, 5.5], [1.8, -0.2, 5.5]] } }",
        name="u",
    )
    m = {l.name: mirror_of(user, l) for l in user.loads}
    assert m["sag"] == Mirror((0, 1), (1, 1))
    assert m["pinch"] == Mirror((0, 1, 2), (1, 1, 1))
    assert m["patch"] == Mirror((1,), (1,))  # x0 clamped: only the y-mirror (the pad is centred)
    assert m["lopsided"] == Mirror((2,), (1,))  # (0.3, 1, 0) on x1: neither even nor odd in y


def test_no_cut_for_an_asymmetric_material(tmp_path):
    oblique = write_case(
        tmp_path,
        material=textwrap.dedent("""
        E = 1000.0
        nu = 0.3
        [material.fibre]
        E_fibre = 5000.0
        E_cross = 1000.0
        nu_fibre = 0.3
        nu_cross = 0.3
        G_fibre = 400.0
        direction = [1.0, 1.0, 0.0]"""),
        name="o",
    )
    m = {l.name: mirror_of(oblique, l) for l in oblique.loads}
    # a fibre along (1, 1, 0) is not mirrored by x or y, but is by z
    assert m["shear-xy"] == Mirror((2,), (1,)) and m["shear-yz"] == Mirror()
    along = write_case(
        tmp_path,
        material=textwrap.dedent("""
        E = 1000.0
        nu = 0.3
        [material.fibre]
        E_fibre = 5000.0
        E_cross = 1000.0
        nu_fibre = 0.3
        nu_cross = 0.3
        G_fibre = 400.0
        direction = [0.0, 0.0, 1.0]"""),
        name="a",
    )
    assert mirror_of(along, along.loads[3]) == Mirror((0, 2), (-1, 1))
    region = write_case(
        tmp_path,
        material=textwrap.dedent("""
        E = 1000.0
        nu = 0.3
        [[material.regions]]
        box = [[0.3, -1.2, 4.0], [2.3, -0.7, 5.5]]
        E = 3000.0"""),
        name="r",
    )
    assert not any(mirror_of(region, l) for l in region.loads)


def _whole_and_cut(case, n=2):
    lo, hi = case.body.bbox()
    axes = graded_axes(lo, hi - lo, n)
    lev = Levels(3)
    lev.add_mesh(n, tensor_mesh(axes))
    mirrors = {l.name: mirror_of(case, l) for l in case.loads}
    cut = lev.solve(case, 0, axes, mirrors)
    whole = solve_mesh(case, lev.meshes[0])
    return mirrors, cut, whole


@pytest.mark.parametrize("which", ["basic3d", "user"])
def test_cut_solve_equals_the_whole_box(tmp_path, which):
    case = (
        write_case(tmp_path)
        if which == "basic3d"
        else write_case(
            tmp_path,
            loads=USER_LOADS,
            extra="parts = { pad = { box = [[0.8, -1.2, 5.5], [1.8, -0.2, 5.5]] } }",
        )
    )
    mirrors, cut, whole = _whole_and_cut(case)
    assert sum(bool(m) for m in mirrors.values()) >= 3
    for name, u in whole.items():
        scale = np.abs(u).max()
        assert scale > 0
        np.testing.assert_allclose(cut[name], u, rtol=0, atol=1e-9 * scale, err_msg=name)


def test_odd_graded_axes_cannot_be_cut():
    from reference.graded.symmetry import lower_half

    with pytest.raises(ValueError):
        lower_half([np.array([0.0, 0.3, 1.0, 2.0])], Mirror((0,), (1,)))
