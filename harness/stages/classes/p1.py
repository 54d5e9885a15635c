"""The linear finite element (P1) on the model's cells, masses and nodes: the bound a
network on those nodes can reach with the case's material (the rule "p1";
harness/models/p1.py). The base of the classes that fit its material: "p1" (one per
element, harness/stages/classes/p1_element.py) and "p1-global" (one for the body)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from harness.models.p1 import with_p1
from harness.models.sms import build_network
from harness.stages.classes.base import ModelClass


@dataclass(frozen=True)
class P1Class(ModelClass):
    building: str = "building the P1 model"
    spring_constants: bool = False  # its springs are only the connectivity

    def build(self, case, spec: dict, seed: int = 0):
        """P1 with the case's material; ``info`` holds its one (E, nu) (NaN: a material
        with fibres or regions), what an export of the plain P1 writes."""
        net = with_p1(build_network(case, spec, seed=seed), case.material)
        m = case.material
        uniform = m.fibre is None and not m.regions
        pair = (m.E, m.nu) if uniform else (math.nan, math.nan)
        return net.with_k(net.k, E_effective=float(pair[0]), nu_effective=float(pair[1]))
