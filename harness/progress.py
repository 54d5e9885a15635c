"""Progress on stderr with an ETA (tqdm), for the long commands: a bar over known steps
(:func:`steps`: the benchmarks' sizes and cases) and a clock for work in phases whose
remaining time is estimated from the work done (:class:`Clock`: calibrate). Both are
silent with ``--quiet`` (:func:`configure`) and whenever stderr is not a terminal (logs
and pipes get no bars);
``springbench run`` has its own suite bar (harness/run/runner.py) under the same rule.
"""

from __future__ import annotations

import sys
import threading
import time

_QUIET = [False]


def configure(quiet: bool) -> None:
    """Silence every bar of this process (``--quiet``)."""
    _QUIET[0] = bool(quiet)


def shown() -> bool:
    """Whether bars are drawn: not quiet and stderr is a terminal."""
    return not _QUIET[0] and sys.stderr.isatty()


def steps(items, desc: str, unit: str = "step"):
    """``items`` with a tqdm bar (count, elapsed, ETA) when :func:`shown`."""
    from tqdm import tqdm

    items = list(items)
    return tqdm(
        items,
        desc=desc,
        unit=unit,
        file=sys.stderr,
        disable=not shown(),
        leave=False,
        dynamic_ncols=True,
    )


class Clock:
    """A live line for work in phases: the phase, the latest detail, the elapsed time and,
    once :meth:`bound` says about how long the rest will take, a bar and that ETA. Ticks
    once a second on its own (a long FEM solve says nothing for minutes)."""

    def __init__(self, desc: str):
        self.desc, self.phase, self.detail = desc, "", ""
        self.t0, self.end = time.monotonic(), None
        self.bar, self._lock = None, threading.Lock()
        if shown():
            from tqdm import tqdm

            self.bar = tqdm(
                total=None,
                file=sys.stderr,
                leave=False,
                dynamic_ncols=True,
                bar_format="{desc} [{elapsed}]{postfix}",
            )
            self._stop = threading.Event()
            self._thread = threading.Thread(target=self._tick, daemon=True)
            self._thread.start()
        self._draw()

    def set(self, phase: str | None = None, detail: str = "") -> None:
        if phase is not None:
            self.phase = phase
        self.detail = detail
        self._draw()

    def bound(self, seconds: float | None) -> None:
        """The rest takes about ``seconds`` from now (None: unknown)."""
        self.end = None if seconds is None else time.monotonic() + max(float(seconds), 0.0)
        self._draw()

    def _tick(self):
        while not self._stop.wait(1.0):
            self._draw()

    def _draw(self):
        with self._lock:
            if self.bar is not None:
                self._redraw()

    def _redraw(self):
        now = time.monotonic()
        self.bar.set_description_str(f"{self.desc}: {self.phase}", refresh=False)
        self.bar.set_postfix_str(self.detail[:80], refresh=False)
        if self.end is None:
            self.bar.total = None
            self.bar.bar_format = "{desc} [{elapsed}]{postfix}"
        else:
            from tqdm import tqdm

            total = max(self.end, now) - self.t0
            self.bar.total = total
            self.bar.n = min(now - self.t0, total)
            # the phase's own estimate, not tqdm's rate
            left = tqdm.format_interval(max(self.end - now, 0.0))
            self.bar.bar_format = (
                "{desc} {percentage:3.0f}%|{bar}| {elapsed}, about " + left + " left{postfix}"
            )
        self.bar.refresh()

    def close(self) -> None:
        if self.bar is not None:
            self._stop.set()
            self._thread.join(timeout=2)
            with self._lock:
                self.bar.close()
                self.bar = None
