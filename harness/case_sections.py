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
        "seeds": Field("any", [0], check=lambda v: _seeds_problem(v),
                       doc="an integer >= 0 or a list of distinct ones, e.g. seeds = [0, 1, 2]"),
        "stages": Field("strs", ()),
    },
}


def _seeds_problem(v):
    """[run] seeds (the runner's entry): an integer >= 0 or a non-empty list of distinct ones."""
    def ok(s):
        return isinstance(s, int) and not isinstance(s, bool) and s >= 0
    seeds = [v] if ok(v) else v
    if not isinstance(seeds, list) or not seeds or not all(ok(s) for s in seeds):
        return f"expected an integer >= 0 or a non-empty list of them, got {v!r}"
    if len(set(seeds)) != len(seeds):
        return "repeated seed"
    return None
