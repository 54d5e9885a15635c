"""Bourguignon & Cani's element model (harness/models/mt.py) on the model's cells: its
three constants theta fitted by the class's own least squares (harness/stages/sms_mt.py);
a 2-D case gets one row saying the paper has no 2-D element."""

from __future__ import annotations

from dataclasses import dataclass

from harness.errors import naming
from harness.models.mt import with_mt
from harness.models.sms import build_network
from harness.stages import sms_mt
from harness.stages.classes.base import ModelClass


@dataclass(frozen=True)
class MTClass(ModelClass):
    building: str = "building the MT model"

    def skip(self, case, label: str) -> dict | None:
        return sms_mt.skip_row(case, label)

    def build(self, case, spec: dict, seed: int = 0):
        net = build_network(case, spec, seed=seed)
        with naming(case):
            return with_mt(net, case.material)

    def fit_runs(self, runs: list[dict]) -> list[dict]:
        return sms_mt.runs(runs)

    def fit(self, setting, run: dict, start, first: dict):
        return sms_mt.optimise(setting, run, start, first)

    def columns(self, case, spec: dict, net) -> dict:
        # B&C's elements (the springs: connectivity)
        return {"n_elements": len(net.volume.body.cells)}

    def constants(self, net) -> dict:
        return sms_mt.constants(net)

    def save(self, ctx, net, res, tag: str) -> None:
        sms_mt.save(ctx.file(f"mt-{tag}.npz"), net)


MT = MTClass("mt")
