"""Schemas of the case-file sections that later stages own. One entry per section;
the stage that reads a section owns its spec here. Free-form keys ("any") are
validated by their owner when the stage runs."""

from harness.schema import Field

SECTIONS: dict[str, dict[str, Field]] = {
    # [model]: how the spring/mass system or element model is built (harness/models)
    "model": {
        "kind": Field("str", "sms", doc="sms | anisotropic | ..."),
        "options": Field("any", {}),
    },
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
