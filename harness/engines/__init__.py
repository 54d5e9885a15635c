"""Engine adapters: drive a physics engine to static equilibrium on every load of a
benchmark pack (harness/export/pack.py) and return its displacements for
``springbench score --displacements``.

Each adapter is one module registered in ``harness.registry.ENGINES`` (imported when
run; its ``about`` is the package it needs and what it runs); the function takes (pack,
options) and returns {load: settle.Answer}. Engines are
optional extras: a missing one is one line naming the extra that installs it. Bullet's
FEM soft body (``pybullet-fem``) and Drake's (``drake-fem``) take no nodal forces: they
run the gravity loads alone (the others are ``unsupported``, with no displacement in the
answer), Bullet with its own uniform node masses.
"""

from __future__ import annotations

import importlib.util

from harness.errors import SpringbenchError
from harness.registry import ENGINES, PIP_NAMES

EXTRA = 'pip install -e ".[engines]"'


def names() -> tuple[str, ...]:
    return tuple(ENGINES)


def adapter(name: str):
    """The run function of engine ``name`` (its package imported): one-line errors for an
    unknown engine or a missing package."""
    if name not in ENGINES:
        raise SpringbenchError(
            f"unknown engine '{name}'", field="ENGINE", fix=f"one of {', '.join(ENGINES)}"
        )
    package = ENGINES.about[name][0]
    if importlib.util.find_spec(package) is None:  # found, not imported: an engine sets itself up
        raise SpringbenchError(
            f"engine '{name}' needs the package '{package}', which is not installed",
            field="ENGINE",
            fix=f"{EXTRA} (or pip install {PIP_NAMES.get(package, package)})",
        ) from None
    return ENGINES.load(name)
