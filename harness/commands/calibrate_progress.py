"""calibrate's progress line (harness/progress.py Clock): the phase the stage's status
messages name (building, FEM reference, validation, final fit, fit), the latest detail,
and the phase's ETA from its work. The fits stop by counts fixed before the run, so the
work ahead is known and the messages say where it stands: "validation: ... (fit k of n)",
"fitting ... (start i of n)" as unit k (or i) begins, "lbfgs it k of n", "gauss-newton it
k of n", "sa T#k of n" once unit k is done. The time left is the phase's elapsed time per
unit done times the units left; --budget plays no part (it only aborts a fit)."""

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


def tracker(clock, *_):
    """The stage's ``status(msg)`` callback driving ``clock`` (``clock.set(phase, detail)``,
    ``clock.bound(seconds or None)``). Further arguments (the budget, whether the fit is
    validated) are not needed: the work says how much is left."""
    state = {"phase": "", "t0": time.monotonic(), "fits": 0}

    def enter(phase: str):
        if state["phase"] != phase:
            state.update(phase=phase, t0=time.monotonic())
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
        elif msg.startswith("optimising"):
            enter("fit")
            clock.set("fit", msg)
        else:
            clock.set(None, msg)
            if state["phase"] == "fit":
                estimate(msg, begun=False)

    return status
