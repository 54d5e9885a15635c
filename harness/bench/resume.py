"""A long benchmark's finished units kept on disk, so a run that stops (a closed session, a
killed machine) resumes where it stopped: each unit's rows go to ``WORK/<unit>.json``
(``springbench bench NAME`` keeps them in OUT/_work/NAME, git-ignored) with
the unit's inputs and the code they ran (the hash of every source file of harness/ and
reference/, as the suite runner records a stage that runs springbench commands, and of the
benchmarks' own modules, harness/bench/). A unit whose inputs and code are unchanged is
read back instead of run again; anything else runs. Deleting WORK starts over."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from harness.outputs import atomic_write
from harness.run.jobs import code_unchanged, loaded_sources
from harness.sources import file_sha, relative

FORMAT = 1


def _plain(value):
    """JSON's value of a numpy scalar (rows hold numpy ints and floats)."""
    return value.item() if hasattr(value, "item") else str(value)


def _say(line: str):
    print(line, file=sys.stderr)


def _code() -> dict:
    code = loaded_sources(everything=True)
    for p in sorted(Path(__file__).parent.glob("*.py")):
        code[relative(p)] = file_sha(p)
    return code


def kept(work: Path | None, unit: str, inputs: dict, compute, finished=None, status=None):
    """``compute()``'s rows of one unit (a dict or a list of dicts), from ``work`` when a run
    with the same inputs and code left them there, else computed and saved there when
    ``finished(rows)`` says they are (a failed unit's rows run again next time; ``work``
    None: always computed, nothing saved)."""
    if work is None:
        return compute()
    inputs = json.loads(json.dumps(inputs, default=_plain))  # as it reads back (lists, not tuples)
    path = Path(work) / f"{unit}.json"
    if path.exists():
        old = json.loads(path.read_text())
        if old.get("format") == FORMAT and old.get("inputs") == inputs:
            if code_unchanged(old.get("code")):
                (status or _say)(f"{unit}: unchanged since it ran, read from {path}")
                return old["rows"]
    code = _code()  # before the unit runs: the code it ran
    rows = compute()
    if finished is not None and not finished(rows):
        return rows
    data = dict(format=FORMAT, unit=unit, inputs=inputs, code=code, rows=rows)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, json.dumps(data, indent=1, default=_plain).encode())
    return rows
