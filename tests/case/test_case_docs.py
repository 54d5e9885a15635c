"""cases/README.md documents every key the case schema accepts in [model], for every kind."""

import re
from pathlib import Path

from harness.case.sections import MODEL_KINDS

README = Path(__file__).resolve().parents[2] / "cases" / "README.md"


def _documented(section: str) -> set[str]:
    """The keys named in the first column of the section's tables."""
    cells = re.findall(r"^\| ([^|]+) \|", section, flags=re.M)
    return {k for c in cells for k in re.findall(r"`([^`]+)`", c)}


def test_every_model_key_is_documented():
    text = README.read_text(encoding="utf-8")
    start = text.index("### `[model]`")
    section = text[start:text.index("\n### ", start + 1)]
    assert "`kind`" in section
    tables = re.split(r"^`kind = \"(\w+)\"`", section, flags=re.M)[1:]
    per_kind = {kind: _documented(body) for kind, body in zip(tables[::2], tables[1::2])}
    assert set(per_kind) == set(MODEL_KINDS)
    for kind, spec in MODEL_KINDS.items():
        missing = sorted(set(spec) - per_kind[kind])
        assert not missing, f"[model] kind = {kind}: undocumented keys {missing}"
