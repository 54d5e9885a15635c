"""Model classes an sms case can score on the same nodes (``[model] classes``).

Each class is one entry of CLASSES: the [model] keys it overrides and whether its
stiffness is the P1 finite element one (harness/models/p1.py) or Bourguignon & Cani's
element model (harness/models/mt.py) instead of fitted springs.
springs+kn: harness/models/kn.py (Kot & Nagahashi 2015).
A new class is one entry here and its name in ``harness.case.sections.MODEL_CLASSES``.
"""

from __future__ import annotations

from harness.case.sections import MODEL_CLASSES

CLASSES = {
    "springs": {"volume": "none", "kn": "none"},                    # springs on the model's edges
    "springs+volume": {"volume": "shared", "kn": "none"},           # + one volume constant per body
    "springs+volume-element": {"volume": "element", "kn": "none"},  # + one volume constant per element
    "p1": {"volume": "none", "kn": "none", "p1": True},             # linear FEM on the same cells, no constants
    "mt": {"volume": "none", "kn": "none", "mt": True},             # Bourguignon & Cani's elements (harness/models/mt.py)
    "springs+kn": {"volume": "none", "kn": "shared"},               # + Kot & Nagahashi 2015, one kn per body
    "springs+node-volume": {"volume": "node-shared", "kn": "none"},  # + one volume term per node, one kv per body
}

if set(CLASSES) != set(MODEL_CLASSES):
    raise ImportError(f"model classes {sorted(CLASSES)} and MODEL_CLASSES {sorted(MODEL_CLASSES)} differ")


def class_spec(spec: dict, name: str) -> dict:
    """The validated [model] table ``spec`` as model class ``name`` builds it."""
    return {**spec, "p1": False, "mt": False, **CLASSES[name]}


def class_of(spec: dict) -> str:
    """The class name of a [model] table (its ``volume``, ``kn`` and ``p1``)."""
    if spec.get("p1"):
        return "p1"
    if spec.get("mt"):
        return "mt"
    if spec.get("kn", "none") != "none":
        return "springs+kn" if spec["kn"] == "shared" else "springs+kn-node"
    return {"none": "springs", "shared": "springs+volume", "element": "springs+volume-element",
            "node-shared": "springs+node-volume", "node": "springs+node-volume-node"}[spec.get("volume", "none")]


def build(case, spec: dict, seed: int = 0):
    """The network of a class spec: springs (+ volume or kn term), P1 or MT on the same nodes."""
    from harness.models.sms import build_network
    net = build_network(case, {k: v for k, v in spec.items() if k not in ("p1", "mt")}, seed=seed)
    if spec.get("p1"):
        from harness.models.p1 import with_p1
        return with_p1(net, case.material)
    if spec.get("mt"):
        from harness.errors import naming
        from harness.models.mt import with_mt
        with naming(case):
            return with_mt(net, case.material)
    if spec.get("volume", "none") != "none":
        from harness.models.volume import case_volume
        net = case_volume(net, case, spec)
    if spec.get("kn", "none") != "none":       # a ModelError if the volume term is there too
        from harness.models.kn import case_kn
        net = case_kn(net, case, spec)
    return net
