"""Progress on stderr with an ETA (tqdm), for the long commands: a bar over known steps
(:func:`steps`: the benchmarks' sizes and cases) and a clock for work in phases whose
remaining time is estimated from the work done (:class:`Clock`: calibrate). Both are
silent with ``--quiet`` (:func:`configure`) and whenever stderr is not a terminal (logs
and pipes get no bars). ``springbench run``'s :class:`SuiteProgress` draws a bar over the
cases on a terminal and, without one, prints a line per finished case and every
:data:`EVERY` seconds a line with the time left (:class:`Remaining`), so a log shows the
run is alive. The time left only ever printed: no choice depends on the clock.
"""

from __future__ import annotations

import shutil
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

    tick = 1.0  # seconds between redraws of the line

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
        while not self._stop.wait(self.tick):
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


EVERY = 30.0  # seconds between the progress lines of a run without a terminal


def duration(seconds: float) -> str:
    """'45 s', '3 min 05 s', '1 h 02 min'."""
    s = int(round(max(seconds, 0.0)))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"


class Remaining:
    """The time left of a set of jobs, from counts: each job weighs its recorded seconds
    (a job without a record weighs the mean of those with one, or 1), and the time left is
    the elapsed time times the weight still to finish over the weight finished. Unknown
    (None) until a job with weight finishes."""

    def __init__(self, weights: dict, clock=time.monotonic):
        known = [float(w) for w in weights.values() if w is not None and w > 0]
        fill = sum(known) / len(known) if known else 1.0
        self.weights = {
            k: float(w) if w is not None and w > 0 else fill for k, w in weights.items()
        }
        self.total, self.finished = sum(self.weights.values()), 0.0
        self.clock, self.t0 = clock, clock()

    def finish(self, label) -> None:
        self.finished += self.weights.pop(label, 0.0)

    def elapsed(self) -> float:
        return self.clock() - self.t0

    def seconds(self) -> float | None:
        if self.finished <= 0:
            return None
        return self.elapsed() * max(self.total - self.finished, 0.0) / self.finished


class SuiteProgress:
    """``springbench run``'s progress: a tqdm bar over the cases on a terminal (the postfix:
    the running jobs' latest status); without one (CI logs, pipes) a line per finished
    case on ``out`` and every ``every`` seconds a line with the cases done, the elapsed
    time and the time left (:class:`Remaining`). ``enabled`` None: decide by the terminal;
    False: silent. ``weights``: label -> recorded seconds of the jobs to run."""

    def __init__(
        self, total: int, enabled, weights=None, clock=time.monotonic, every=EVERY, tick=1.0
    ):
        from tqdm import tqdm

        tty = sys.stderr.isatty() if enabled is None else bool(enabled)
        size = shutil.get_terminal_size((0, 0))  # a pty without a size (0 x 0) hides tqdm bars
        self.bar = tqdm(
            total=total,
            desc="suite",
            unit="case",
            file=sys.stderr,
            disable=not tty,
            dynamic_ncols=size.columns > 0,
            ncols=None if size.columns > 0 else 100,
            nrows=None if size.lines > 0 else 24,
        )
        self.lines = enabled is None and not tty
        self.total, self.n, self.every = total, 0, every
        self.status: dict[str, str] = {}
        self.left = Remaining(dict(weights or {}), clock)
        self.last, self._lock, self._stop = self.left.t0, threading.RLock(), threading.Event()
        self._thread, self.tick = None, tick
        if self.lines and tick:  # tick None: no thread, the caller polls (tests)
            self._thread = threading.Thread(target=self._tick, daemon=True)
            self._thread.start()

    def set(self, label: str, msg: str):
        with self._lock:
            self.status[label] = msg
            self._show()

    def done(self, label: str, what: str = ""):
        with self._lock:
            self.status.pop(label, None)
            self.left.finish(label)
            self.n += 1
            self.bar.update(1)
            self._show()
            if self.lines and what:
                print(f"[{self.n}/{self.total}] {label}: {what}", flush=True)

    def line(self) -> str:
        """The progress line: cases done, elapsed, time left, the running jobs."""
        left = self.left.seconds()
        eta = (
            "time left: known once a case finishes"
            if left is None
            else (f"about {duration(left)} left")
        )
        running = "; ".join(f"{k}: {v}" for k, v in list(self.status.items())[-3:])
        return f"[{self.n}/{self.total}] {duration(self.left.elapsed())} elapsed, {eta}" + (
            f" (running: {running[:160]})" if running else ""
        )

    def poll(self) -> bool:
        """Print :meth:`line` if ``every`` seconds have passed since the last one."""
        with self._lock:
            now = self.left.clock()
            if not self.lines or self.n >= self.total or now - self.last < self.every:
                return False
            self.last = now
            print(self.line(), flush=True)
            return True

    def _tick(self):
        while not self._stop.wait(self.tick):
            self.poll()

    def _show(self):
        text = "; ".join(f"{k}: {v}" for k, v in list(self.status.items())[-3:])
        left = self.left.seconds()
        text = (f"about {duration(left)} left; " if left is not None else "") + text
        self.bar.set_postfix_str(text[:120], refresh=True)

    def write(self, line: str):
        self.bar.write(line, file=sys.stderr)

    def close(self):
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2)
        self.bar.close()
