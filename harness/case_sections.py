"""Schemas of the case-file sections that later stages own. One entry per section;
the stage that reads a section owns its spec here. Free-form keys ("any") are
validated by their owner when the stage runs."""

from harness.models.sms import MODEL_SPEC as SMS
from harness.schema import Field

# [model] kind = "..." selects the spec of the other keys; each model owner adds its kind.
MODEL_KINDS: dict[str, dict[str, Field]] = {
    "sms": SMS,      # spring/mass systems of Deussen 1995 (harness/models/sms.py)
    "bc2000": {},    # the anisotropic element model of Bourguignon & Cani 2000
}

SECTIONS: dict[str, dict[str, Field] | str] = {
    # [model]: how the spring/mass system or element model is built (harness/models)
    # keys depend on kind: see MODEL_KINDS
    "model": "model",
    # [optimizer]: spring-constant calibration (harness/optimize)
    "optimizer": {
        "method": Field("str", "none"),
        "options": Field("any", {}),
    },
    # [score]: G criteria weights (harness/scoring)
    "score": {
        "weights": Field("floats", (1.0, 1.0, 1.0), length=3, min=0,
                         doc="G_{a:b:c} weights: inner, border, corner"),
    },
    # [expect]: the paper's numbers, reported beside ours
    "expect": {
        "source": Field("str", ""),
        "values": Field("any", {}),
    },
    # [run]: what `springbench run` does with the case and its seeds
    "run": {
        "seeds": Field("any", [0]),
        "stages": Field("strs", ()),
    },
}
