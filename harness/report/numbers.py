"""Numbers as the report prints them."""

from __future__ import annotations

import math


def fmt(v, digits: int = 3) -> str:
    """A number to ``digits`` significant digits ("0.0230", "5.09", "270"); "" if missing."""
    if v is None or isinstance(v, str):
        return v or ""
    try:
        v = float(v)
    except (TypeError, ValueError):
        return str(v)
    if not math.isfinite(v):
        return ""
    if abs(v) >= 10**digits:
        return f"{v:,.0f}"
    if v == int(v):  # counts: 72, not 72.0
        return str(int(v))
    s = f"{v:#.{digits}g}"
    return s.rstrip(".") if "e" not in s else f"{v:.{digits - 1}e}"
