"""Which load's constraints the natural frequencies use (harness.case.loads.modal_load):
a clamp, held out first, never corner or anchor points."""

from __future__ import annotations

from harness.case.loads import modal_load
from harness.case.reader import load_case

BOX = """name = "m"
dim = 3
[body]
shape = "box"
size = [2.0, 1.0, 1.0]
[material]
E = 1000.0
nu = 0.3
"""


def case(tmp_path, loads: str):
    p = tmp_path / "c.toml"
    p.write_text(BOX + loads)
    return load_case(p)


def test_a_clamp_held_out_comes_first(tmp_path):
    c = case(tmp_path, '[loads]\nset = "basic3d"\n')
    assert c.loads[0].name == "stretch-x"  # held at corners: not it
    first = modal_load(c)
    assert first.name != "stretch-x" and any(
        k.part in ("x0", "y0", "z0") for k in first.constraints
    )
    c = case(
        tmp_path,
        """[[loads.case]]
name = "pull"
constraint = [{ part = "x0y0z0", components = ["all"] },
              { part = "x0y1z0", components = ["x", "z"] },
              { part = "x0y0z1", components = ["x"] }]
traction = [{ part = "x1", vector = [1.0, 0.0, 0.0] }]
[[loads.case]]
name = "edge"
constraint = [{ part = "x0y0", components = ["all"] }, { part = "x0y1", components = ["all"] }]
gravity = [0.0, 0.0, -1.0]
[[loads.case]]
name = "sag"
constraint = [{ part = "x0", components = ["all"] }]
gravity = [0.0, 0.0, -1.0]
[[loads.case]]
name = "tip"
constraint = [{ part = "x0", components = ["all"] }]
traction = [{ part = "x1", vector = [0.0, 0.0, -1.0] }]
[loads]
heldout = ["tip"]
""",
    )
    assert modal_load(c).name == "tip"  # held out and clamped
    c = case(
        tmp_path,
        """[[loads.case]]
name = "pull"
constraint = [{ part = "x0y0z0", components = ["all"] },
              { part = "x0y1z0", components = ["x", "z"] },
              { part = "x0y0z1", components = ["x"] }]
traction = [{ part = "x1", vector = [1.0, 0.0, 0.0] }]
[[loads.case]]
name = "slide"
constraint = [{ part = "x0", components = ["x"] }, { part = "x0y0z0", components = ["all"] },
              { part = "x0y1z0", components = ["all"] }]
traction = [{ part = "x1", vector = [1.0, 0.0, 0.0] }]
""",
    )
    assert modal_load(c).name == "pull"  # no clamp at all: the first load


def test_homogeneous_states_fall_back_to_the_first_load(tmp_path):
    c = case(tmp_path, '[loads]\nset = "homogeneous3d"\n')
    assert modal_load(c).name == c.loads[0].name
