"""A tiny declarative schema for TOML tables: types, ranges, choices, unknown keys.

A spec is a dict ``key -> Field``. ``check(data, spec, file, path)`` returns a new
dict with defaults filled in, or raises :class:`CaseError` naming the file, the
dotted field and what is expected. Nothing here evaluates user text.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from typing import Any, Callable

from harness.errors import CaseError, raise_all

REQUIRED = object()
# the magnitudes a number may have (0 aside): the solvers multiply and square them (stiffness
# E L, G sums |u|^2 with u ~ s L / E), and double precision overflows near 1e308
SMALLEST, LARGEST = 1e-30, 1e30


@dataclass(frozen=True)
class Field:
    """One key of a table.

    kind: "float", "int", "str", "bool", "floats" (list of numbers), "matrix" (list
    of lists of numbers), "strs", "table" (nested spec), "tables" (array of tables
    with one spec), "any" (free-form, validated later by its owner).
    """

    kind: str
    default: Any = REQUIRED
    doc: str = ""
    choices: tuple = ()
    min: float | None = None
    max: float | None = None
    min_exclusive: bool = False
    max_exclusive: bool = False
    length: int | tuple[int, ...] | None = None
    spec: dict | None = None
    check: Callable[[Any], str | None] | None = None


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def describe(v) -> str:
    return {
        bool: "a boolean",
        int: "an integer",
        float: "a number",
        str: "a string",
        list: "a list",
        dict: "a table",
    }.get(type(v), type(v).__name__)


def check(data: Any, spec: dict[str, Field], file: str, path: str = "") -> dict:
    """Validate ``data`` (a TOML table) against ``spec``; return it with defaults."""

    def fail(key, msg, fix=None):
        raise CaseError(msg, file=file, field=(path + key) if key else path.rstrip("."), fix=fix)

    if not isinstance(data, dict):
        fail("", f"expected a table, got {describe(data)}")
    errors = []  # every mistake of the table, not just the first
    for key in sorted(set(data) - set(spec)):
        errors.append(
            CaseError("unknown key", file=file, field=path + key, fix=did_you_mean(key, spec))
        )
    out = {}
    for key, f in spec.items():
        try:
            if key not in data:
                if f.default is REQUIRED:
                    fail(
                        key,
                        f"missing required {f.kind} field",
                        f.doc
                        or (
                            f"add a [{path}{key}] table"
                            if f.kind == "table"
                            else f"add {key} = ..."
                        ),
                    )
                # an absent table with a {} default still gets its own defaults
                out[key] = (
                    check({}, f.spec, file, path + key + ".")
                    if f.kind == "table" and f.default == {}
                    else f.default
                )
                continue
            out[key] = _value(data[key], f, file, path + key)
        except CaseError as exc:
            errors.append(exc)
    raise_all(errors)
    return out


def did_you_mean(key: str, allowed) -> str:
    """'did you mean ...? allowed here: ...' for an unknown key."""
    allowed = sorted(allowed)
    close = difflib.get_close_matches(key, allowed, n=1, cutoff=0.6)
    k = str(key).lower()  # or one is the other's start: 'tolerance' for 'tol'
    close = close or [
        a
        for a in allowed
        if min(len(k), len(a)) >= 3 and (k.startswith(a.lower()) or a.lower().startswith(k))
    ]
    hint = f"did you mean '{close[0]}'? " if close else ""
    return f"{hint}allowed here: {', '.join(allowed)}"


def _value(v, f: Field, file: str, where: str):
    def fail(msg, fix=None):
        raise CaseError(msg, file=file, field=where, fix=fix or (f.doc or None))

    k = f.kind
    if k == "any":  # free-form, but a Field.check still applies
        msg = f.check(v) if f.check is not None else None
        if msg:
            fail(msg)
        return v
    if k == "float":
        if not _is_number(v):
            fail(f"expected a number, got {describe(v)}")
        v = float(v)
        if not math.isfinite(v):
            fail("expected a finite number")
        _magnitude(v, fail)
        _range(v, f, fail)
    elif k == "int":
        if not isinstance(v, int) or isinstance(v, bool):
            fail(f"expected an integer, got {describe(v)}")
        if f.choices and v not in f.choices:
            fail(f"{v} is not one of {', '.join(map(str, f.choices))}")
        _range(v, f, fail)
    elif k == "bool":
        if not isinstance(v, bool):
            fail(f"expected true or false, got {describe(v)}")
    elif k == "str":
        if not isinstance(v, str):
            fail(f"expected a string, got {describe(v)}")
        if f.choices and v not in f.choices:
            fail(f"'{v}' is not one of {', '.join(map(str, f.choices))}")
    elif k == "strs":
        if isinstance(v, str):
            v = [v]
        if not isinstance(v, list) or not all(isinstance(s, str) for s in v):
            fail("expected a list of strings")
        bad = [s for s in v if f.choices and s not in f.choices]
        if bad:
            fail(f"'{bad[0]}' is not one of {', '.join(map(str, f.choices))}")
        v = tuple(v)
    elif k == "floats":
        if not isinstance(v, list) or not all(_is_number(x) for x in v):
            fail(f"expected a list of numbers, got {describe(v)}")
        v = tuple(float(x) for x in v)
        if not all(math.isfinite(x) for x in v):
            fail("expected finite numbers")
        _length(v, f, fail)
        for x in v:
            _magnitude(x, fail)
            _range(x, f, fail)
    elif k == "matrix":
        if not isinstance(v, list) or not all(
            isinstance(r, list) and all(_is_number(x) for x in r) for r in v
        ):
            fail("expected a list of lists of numbers")
        v = tuple(tuple(float(x) for x in r) for r in v)
        if not all(math.isfinite(x) for r in v for x in r):
            fail("expected finite numbers (no nan or inf)")
        for r in v:
            for x in r:
                _magnitude(x, fail)
        _length(v, f, fail)
    elif k == "table":
        v = check(v, f.spec, file, where + ".")
    elif k == "tables":
        if isinstance(v, dict):
            v = [v]
        if not isinstance(v, list):
            fail("expected an array of tables ([[...]])")
        v = tuple(check(t, f.spec, file, f"{where}[{i}].") for i, t in enumerate(v))
    else:  # pragma: no cover - programming error
        raise ValueError(k)
    if f.check is not None:
        msg = f.check(v)
        if msg:
            fail(msg)
    return v


def _magnitude(x: float, fail):
    if x != 0 and not SMALLEST <= abs(x) <= LARGEST:
        fail(
            f"{x:g} is too {'large' if abs(x) > LARGEST else 'small'} to compute with",
            f"numbers between {SMALLEST:g} and {LARGEST:g} in size (or 0): change the units",
        )


def _range(x, f: Field, fail):
    if f.min is not None and (x < f.min or (f.min_exclusive and x == f.min)):
        fail(f"{x} is out of range", f"must be {'>' if f.min_exclusive else '>='} {f.min}")
    if f.max is not None and (x > f.max or (f.max_exclusive and x == f.max)):
        fail(f"{x} is out of range", f"must be {'<' if f.max_exclusive else '<='} {f.max}")


def _length(v, f: Field, fail):
    if f.length is None:
        return
    ok = (f.length,) if isinstance(f.length, int) else f.length
    if len(v) not in ok:
        fail(f"expected {' or '.join(map(str, ok))} entries, got {len(v)}")
