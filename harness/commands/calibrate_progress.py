"""calibrate's progress line (harness/progress.py Clock): the phase the stage's status
messages name (building, FEM reference, validation fit k, final fit start i of n), the
latest detail, and from the first fit on the ETA its --budget bounds: the validation fits
take at most VALIDATION_BUDGET x the budget together, the final fit's starts the budget."""

from __future__ import annotations


def tracker(clock, budget: float, validated: bool):
    """The stage's ``status(msg)`` callback driving ``clock``."""
    from harness.stages.sms_select import VALIDATION_BUDGET

    state = {"phase": "", "fits": 0}

    def enter(phase: str, bound: float | None):
        if state["phase"] != phase:
            state["phase"] = phase
            clock.bound(bound)

    def status(msg: str):
        if msg.startswith("building"):
            enter("building", None)
            clock.set("building the network", msg)
        elif msg.startswith(("reference solve", "FEM")):
            enter("fem", None)
            clock.set("FEM reference", msg)
        elif msg.startswith("validation:"):
            enter("validation", (VALIDATION_BUDGET + 1) * budget)
            state["fits"] += 1
            clock.set(f"validation fit {state['fits']}", msg.removeprefix("validation: "))
        elif msg.startswith("fitting "):
            enter("final", budget)
            clock.set("final fit", msg.removeprefix("fitting "))
        elif msg.startswith("optimising"):
            enter("fit", (VALIDATION_BUDGET + 1) * budget if validated else budget)
            clock.set("fit", msg)
        else:
            clock.set(None, msg)

    return status
