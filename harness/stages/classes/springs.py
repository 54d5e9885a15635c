"""Springs on the model's edges, optionally with a volume term (harness/models/volume.py)
or Kot & Nagahashi's kn term (harness/models/kn.py): the classes whose constants the
optimisers of harness/optimize fit (K = B diag(k) B^T, the terms' columns beside B)."""

from __future__ import annotations

from dataclasses import dataclass

from harness import registry
from harness.export.vtu import write_vtu
from harness.mechanics.homogenize import case_report
from harness.models.kn import case_kn
from harness.models.kn import save as save_kn
from harness.models.sms import build_network
from harness.models.volume import case_volume, save
from harness.stages.classes.base import ModelClass, model_label


@dataclass(frozen=True)
class Springs(ModelClass):
    """``volume`` and ``kn``: the [model] keys of the extra term (``none``: springs alone)."""

    volume: str = "none"
    kn: str = "none"
    building: str = "building the spring/mass system"
    selects: bool = True

    def spec(self, spec: dict) -> dict:
        return {**spec, "volume": self.volume, "kn": self.kn}

    def build(self, case, spec: dict, seed: int = 0):
        net = build_network(case, spec, seed=seed)
        if self.volume != "none":
            net = case_volume(net, case, spec)
        if self.kn != "none":  # a ModelError if the volume term is there too
            net = case_kn(net, case, spec)
        return net

    def label(self, spec: dict, case) -> str:
        label = model_label(spec, case)
        if self.volume != "none":
            label += f"+volume-{self.volume}"
        if self.kn != "none":
            label += f"+kn-{self.kn}"
        return label

    def rules(self, spec: dict) -> list[str]:
        return list(spec["stiffness"])

    def fit_runs(self, runs: list[dict]) -> list[dict]:
        return runs

    def fit(self, setting, run: dict, start, first: dict):
        from harness.stages.sms_fit import optimise

        return optimise(setting, run, start, first)

    def columns(self, case, spec: dict, net) -> dict:
        out = {}
        if self.volume != "none":
            out.update(volume=self.volume, n_volumes=net.volume.n_elements)
        if self.kn != "none":
            out.update(kn=self.kn, n_kn=net.volume.n_elements)
        return out

    def lattice(self, case, spec: dict) -> dict | None:
        return case_report(case, spec)

    def save(self, ctx, net, res, tag: str) -> None:
        """The network with its displacements as VTU, the extra term's constants as .npz."""
        write_vtu(ctx.file(f"model-{tag}.vtu"), net, dict(zip(res.names, res.u)))
        if getattr(net, "volume", None) is None:
            return
        if self.kn != "none":
            save_kn(ctx.file(f"kn-{tag}.npz"), net)
        else:
            save(ctx.file(f"volume-{tag}.npz"), net)


# the instances harness/registry.py MODEL_CLASSES names (its ``about`` says what each is)
SPRINGS = Springs("springs")
VOLUME_SHARED = Springs("springs+volume-shared", volume="shared")
VOLUME_ELEMENT = Springs("springs+volume-element", volume="element")
NODE_VOLUME_SHARED = Springs("springs+node-volume-shared", volume="node-shared")
NODE_VOLUME_NODE = Springs("springs+node-volume-node", volume="node")
KN_SHARED = Springs("springs+kn", kn="shared")  # Kot & Nagahashi 2015
KN_NODE = Springs("springs+kn-node", kn="node")


def of_spec(spec: dict) -> Springs:
    """The class of a case without ``[model] classes``: the registered springs class of its
    own volume and kn keys (both set: a class of both, which its build refuses)."""
    keys = (spec.get("volume", "none"), spec.get("kn", "none"))
    for name in registry.SPRINGS_CLASSES:
        cls = registry.MODEL_CLASSES.load(name)
        if (cls.volume, cls.kn) == keys:
            return cls
    return Springs(f"springs+volume-{keys[0]}+kn-{keys[1]}", volume=keys[0], kn=keys[1])
