"""Every engine adapter's simulator is a settle.Sim: the same methods with the same
parameters (one ``load(ld)`` signature), so settle drives any of them alike."""

from __future__ import annotations

import inspect

import pytest

from harness.engines import settle

SIMS = [
    ("harness.engines.newton_engine", "NewtonSim"),
    ("harness.engines.mujoco_flex", "MujocoSim"),
    ("harness.engines.pybullet_fem", "PybulletSim"),
    ("harness.engines.drake_fem", "DrakeSim"),
    ("harness.engines.mujoco_springs", "MujocoSpringsSim"),
]
METHODS = ("load", "set_damping", "advance", "measure")


def _params(f) -> list[str]:
    return list(inspect.signature(f).parameters)


@pytest.mark.parametrize("module, name", SIMS)
def test_each_simulator_has_the_protocols_methods_and_parameters(module, name):
    import importlib

    cls = getattr(importlib.import_module(module), name)
    for method in METHODS:
        assert _params(getattr(cls, method)) == _params(getattr(settle.Sim, method)), method


def test_the_check_sees_a_second_load_signature():
    """The check is not vacuous: a load(held_nodes, held_components, force) fails it."""

    class Old:
        def load(self, held_nodes, held_components, force):
            pass

    assert _params(Old.load) != _params(settle.Sim.load)
