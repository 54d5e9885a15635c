"""calibrate's progress line (harness/progress.py Clock): the phase the stage's status
messages name (building, FEM reference, validation, final fit, fit), the latest detail,
and the phase's ETA from its work. The fits stop by counts fixed before the run, so the
work ahead is known and the messages say where it stands: "validation: ... (fit k of n)",
"fitting ... (start i of n)" as unit k (or i) begins, "lbfgs it k of n", "gauss-newton it
k of n", "sa T#k of n" once unit k is done. The time left is the phase's elapsed time per
unit done times the units left; --budget plays no part (it only aborts a fit). The wall
time of each phase is kept for calibrate's closing line (:func:`split`): it is reported,
never used for a choice."""

from __future__ import annotations

import re
import time

OF = re.compile(r"\b(\d+) of (\d+)\b")


def left(msg: str, begun: bool, elapsed: float) -> float | None:
    """Seconds the phase has left by the "k of n" in ``msg`` (None: no count, or no unit
    done yet): unit k begins (``begun``: k - 1 are done) or is done, after ``elapsed``."""
    m = OF.search(msg)
    if m is None:
        return None
    k, n = int(m[1]), int(m[2])
    done = k - 1 if begun else k
    if done < 1 or done > n:
        return None
    return elapsed * (n - done) / done


# the phases of the split, in the order they run, as calibrate's closing line names them
PHASES = {
    "building": "building",
    "fem": "FEM reference",
    "rules": "rules",
    "validation": "validation",
    "final": "final fit",
    "fit": "fit",
}


def tracker(clock, *_, spent: dict | None = None):
    """The stage's ``status(msg)`` callback driving ``clock`` (``clock.set(phase, detail)``,
    ``clock.bound(seconds or None)``). Further arguments (the budget, whether the fit is
    validated) are not needed: the work says how much is left. ``spent`` (phase -> wall
    seconds) gets each phase's time as the next one begins."""
    state = {"phase": "", "t0": time.monotonic(), "fits": 0}
    spent = {} if spent is None else spent

    def stop():
        """The current phase's time into ``spent``; no phase runs after it."""
        now = time.monotonic()
        if state["phase"]:
            spent[state["phase"]] = spent.get(state["phase"], 0.0) + now - state["t0"]
        state.update(phase="", t0=now)

    def enter(phase: str):
        if state["phase"] != phase:
            stop()
            state["phase"] = phase
            clock.bound(None)

    def estimate(msg: str, begun: bool):
        seconds = left(msg, begun, time.monotonic() - state["t0"])
        if seconds is not None:
            clock.bound(seconds)

    def status(msg: str):
        if msg.startswith("building"):
            enter("building")
            clock.set("building the network", msg)
        elif msg.startswith(("reference solve", "FEM")):
            enter("fem")
            clock.set("FEM reference", msg)
        elif msg.startswith("validation:"):
            enter("validation")
            state["fits"] += 1
            m = OF.search(msg)
            clock.set(
                f"validation fit {m[0] if m else state['fits']}", msg.removeprefix("validation: ")
            )
            estimate(msg, begun=True)
        elif msg.startswith("fitting "):
            enter("final")
            clock.set("final fit", msg.removeprefix("fitting "))
            estimate(msg, begun=True)
        elif msg.startswith("statics of"):
            enter("rules")
            clock.set("rules", msg)
        elif msg.startswith("optimising") or ": fitting " in msg:
            enter("fit")
            clock.set("fit", msg)
        else:
            clock.set(None, msg)
            if state["phase"] == "fit":
                estimate(msg, begun=False)

    status.stop = stop  # at the stage's end: the last phase's time into ``spent``
    return status


def split(spent: dict, total: float) -> str:
    """calibrate's closing line: the wall time of each phase that ran and of the rest
    (reading the mesh, scoring, writing), in seconds."""
    parts = [f"{PHASES[k]} {spent[k]:.0f} s" for k in PHASES if spent.get(k, 0.0) > 0]
    rest = max(total - sum(spent.values()), 0.0)
    return f"wall time: {', '.join(parts + [f'the rest {rest:.0f} s'])} ({total:.0f} s)"
