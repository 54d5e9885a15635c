"""The model-class protocol (see the package docstring) and what one class's rows share."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from harness.stages.rows import FitColumns


@dataclass(frozen=True)
class Setting:
    """What every row of one class on one case shares: the case and stage context, the
    class's [model] table and label, the columns every row carries, the reference
    displacements ``u_ref`` (loads x nodes x dim) of the loads ``names`` (``fit``: the
    indices of the fitted ones), the node-class weights, the FEM's natural frequencies
    ``fem_f``, the optimiser entry, and the stage's ``evaluate(net[, res])``,
    ``write(net, res, tag)`` and ``validated(net, res)`` (the validation loads' columns)."""

    case: Any
    ctx: Any
    spec: dict
    label: str
    common: dict
    u_ref: Any
    names: tuple
    fit: list
    weights: Any
    fem_f: Any
    optimize: Callable
    evaluate: Callable
    write: Callable
    validated: Callable = lambda net, res: {}

    def fit_columns(self, first: dict, stiffness: str, optimizer: str, sc, **fit) -> FitColumns:
        """The shared columns of a fit of this class from rule ``stiffness`` (its row
        ``first``: G at the start) by ``optimizer``, scored ``sc`` after it; ``fit``: the
        other fields of :class:`harness.stages.rows.FitColumns`. Its ``row(self.common,
        ...)`` is the fitted row."""
        return FitColumns.of(self.label, stiffness, optimizer, first, sc, **fit)


def model_label(spec, case) -> str:
    """The nodes' label: placement and size (``sms-grid5x3-structure1``, ``sms-mesh``...)."""
    p = spec["placement"]
    if p == "grid":
        structure = spec["structure"] or ("structure1" if case.dim == 2 else "edges+face+body")
        return f"sms-grid{'x'.join(map(str, spec['grid']))}-{structure}"
    if p == "lloyd":
        return f"sms-lloyd{spec['lloyd_iterations']}-n{spec['n_points']}"
    if p == "random":
        return f"sms-random-n{spec['n_points']}"
    return "sms-mesh"


@dataclass(frozen=True)
class ModelClass:
    """A model class's defaults: no skipped cases, no extra columns, no fit, no files.
    ``building`` is its status message; ``spring_constants`` whether its ``k`` are spring
    constants (the ``k_spread`` column); ``selects`` whether ``[optimizer.select]`` can
    choose its capacity."""

    name: str
    building: str = "building the model"
    spring_constants: bool = True
    selects: bool = False

    def spec(self, spec: dict) -> dict:
        return {**spec, "volume": "none", "kn": "none"}

    def skip(self, case, label: str) -> dict | None:
        return None

    def build(self, case, spec: dict, seed: int = 0):
        raise NotImplementedError

    def label(self, spec: dict, case) -> str:
        return f"{self.name}-{model_label(spec, case)}"

    def rules(self, spec: dict) -> list[str]:
        return [self.name]

    def fit_runs(self, runs: list[dict]) -> list[dict]:
        return []

    def fit(self, setting: Setting, run: dict, start, first: dict):
        raise NotImplementedError(f"model class {self.name} has no fit")

    def columns(self, case, spec: dict, net) -> dict:
        return {}

    def lattice(self, case, spec: dict) -> dict | None:
        """The Cauchy-lattice report of its springs (harness.mechanics.homogenize), or None."""
        return None

    def constants(self, net) -> dict:
        return {}

    def save(self, ctx, net, res, tag: str) -> None:
        return None
