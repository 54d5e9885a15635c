"""Markdown tables for the report (GitHub-flavoured)."""

from __future__ import annotations

import math


def cell(v) -> str:
    """One table cell: blank for None / NaN, floats to 4 significant digits, pipes escaped."""
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return ""
    if isinstance(v, float):
        return f"{v:.4g}"
    if hasattr(v, "item"):
        return cell(v.item())
    return str(v).replace("|", "\\|").replace("\n", " ")


def markdown_table(df) -> str:
    """A GitHub-flavoured Markdown table (numbers to 4 significant digits). Written here
    rather than via pandas.to_markdown so springbench needs no `tabulate` dependency."""
    cols = [str(c) for c in df.columns]
    numeric = [df[c].dtype.kind in "iuf" for c in df.columns]
    lines = [
        "| " + " | ".join(c.replace("|", "\\|") for c in cols) + " |",
        "| " + " | ".join("---:" if n else "---" for n in numeric) + " |",
    ]
    for row in df.itertuples(index=False):
        lines.append("| " + " | ".join(cell(v) for v in row) + " |")
    return "\n".join(lines) + "\n"
