"""A case table as TOML text (what ``calibrate --save-case`` writes): tables become
``[a.b]`` headers, lists of tables ``[[a.b]]``, everything else ``key = value``. Only the
types a case holds: str, bool, int, float (finite), lists of them, tables."""

from __future__ import annotations

import json
import math


def dumps(table: dict) -> str:
    """The TOML text of ``table``; ``tomllib.loads`` gives it back."""
    return "".join(_table(table, ()))


def _table(table: dict, path: tuple) -> list[str]:
    plain = [(k, v) for k, v in table.items() if not _is_table(v) and not _is_tables(v)]
    out = [f"{_key(k)} = {_value(v)}\n" for k, v in plain]
    for k, v in table.items():
        if _is_table(v):
            out.append(f"[{'.'.join(map(_key, path + (k,)))}]\n")
            out += _table(v, path + (k,))
        elif _is_tables(v):
            for item in v:
                out.append(f"[[{'.'.join(map(_key, path + (k,)))}]]\n")
                out += _table(item, path + (k,))
    return out


def _is_table(v) -> bool:
    return isinstance(v, dict)


def _is_tables(v) -> bool:
    return isinstance(v, (list, tuple)) and len(v) > 0 and all(isinstance(x, dict) for x in v)


def _key(k: str) -> str:
    bare = k.replace("-", "").replace("_", "").isalnum() and k.isascii()
    return k if bare else json.dumps(k)


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"{v!r} has no TOML spelling here")
        return repr(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    raise TypeError(f"{type(v).__name__} is not a case value")
