"""Engine adapters: drive a physics engine to static equilibrium on every load of a
benchmark pack (harness/export/pack.py) and return its displacements for
``springbench score --displacements``.

Each adapter is one module registered in ``ENGINES`` ("module:function", imported when
run); the function takes (pack, options) and returns {load: settle.Answer}. Engines are
optional extras: a missing one is one line naming the extra that installs it. Bullet
(pybullet) installs but is not among them: its deformable bodies take no nodal forces
(gravity only), set their own node masses, and went still 55 % away from the FEM's sag
on a 875-tet cylinder.
"""

from __future__ import annotations

import importlib
import importlib.util

from harness.case.sections import ENGINE_NAMES
from harness.errors import SpringbenchError

ENGINES = {
    "newton-springs": ("harness.engines.newton_engine:run_springs", "newton", "a springbench export (--model "
                       "MODEL.json) as NVIDIA Newton particles, springs and (springs+volume) tetrahedra"),
    "newton-tets": ("harness.engines.newton_engine:run_tets", "newton", "NVIDIA Newton's own tetrahedral FEM "
                    "(stable Neo-Hookean, k_mu / k_lambda from E and nu)"),
    "mujoco-flex": ("harness.engines.mujoco_flex:run", "mujoco", "MuJoCo's 3-D flex with its own elasticity "
                    "(young, poisson)"),
}
EXTRA = 'pip install -e ".[engines]"'
if tuple(ENGINES) != ENGINE_NAMES:      # the case files' vocabulary (harness/case/sections.py)
    raise ImportError(f"harness.engines.ENGINES {tuple(ENGINES)} != harness.case.sections.ENGINE_NAMES")


def names() -> tuple[str, ...]:
    return tuple(ENGINES)


def adapter(name: str):
    """The run function of engine ``name`` (its package imported): one-line errors for an
    unknown engine or a missing package."""
    if name not in ENGINES:
        raise SpringbenchError(f"unknown engine '{name}'", field="ENGINE", fix=f"one of {', '.join(ENGINES)}")
    target, package, _ = ENGINES[name]
    if importlib.util.find_spec(package) is None:       # found, not imported: an engine sets itself up
        raise SpringbenchError(f"engine '{name}' needs the package '{package}', which is not installed",
                               field="ENGINE", fix=f"{EXTRA} (or pip install {package})") from None
    module, func = target.split(":")
    return getattr(importlib.import_module(module), func)
