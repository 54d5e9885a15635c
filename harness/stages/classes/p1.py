"""The linear finite element (P1) on the model's cells, masses and nodes: the bound a
network on those nodes can reach without constants to fit (harness/models/p1.py)."""

from __future__ import annotations

from dataclasses import dataclass

from harness.models.p1 import with_p1
from harness.models.sms import build_network
from harness.stages.classes.base import ModelClass


@dataclass(frozen=True)
class P1Class(ModelClass):
    building: str = "building the P1 model"
    spring_constants: bool = False  # its springs are only the connectivity

    def build(self, case, spec: dict, seed: int = 0):
        return with_p1(build_network(case, spec, seed=seed), case.material)


P1 = P1Class("p1")
