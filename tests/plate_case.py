"""The small 2-D plate case several tests write: a 2 x 1 rectangle, E = 1000, nu = 0.3,
the basic2d loads; each test adds its own top-level keys, [loads] keys and tables."""

from __future__ import annotations

import textwrap

HEAD = """name = "{name}"
dim = 2
{top}[body]
shape = "rectangle"
size = [2.0, 1.0]
[material]
E = 1000.0
nu = 0.3
[loads]
set = "basic2d"
"""


def plate_case(name: str, tables: str = "", *, top: str = "", loads: str = "") -> str:
    """TOML text of the plate case ``name``: ``top`` (top-level keys such as description
    and tags), ``loads`` (more [loads] keys, e.g. heldout), then ``tables`` (the
    [reference], [model], ... tables); each block may be indented (it is dedented)."""

    def block(text: str) -> str:
        text = textwrap.dedent(text).strip("\n")
        return text + "\n" if text else ""

    return HEAD.format(name=name, top=block(top)) + block(loads) + block(tables)
