"""docs/case-files.md against the case schema (harness/case/reader.py, harness/case/sections.py):
every key the schema accepts is in the table of its section, every key documented is one the
schema accepts, and every value of a key with a fixed list of choices is named in its row."""

import re
from pathlib import Path

import pytest

from harness.case import reader, sections
from harness.case.schema import Field

PAGE = Path(__file__).resolve().parents[2] / "docs" / "case-files.md"


def schema_tables() -> dict[tuple[str, str | None], dict[str, Field]]:
    """(table path, model kind) -> its spec, for every table a case file may hold."""
    out = {}

    def walk(path, spec, kind=None):
        out[(path, kind)] = spec
        for key, f in spec.items():
            if f.kind in ("table", "tables") and f.spec is not None:
                walk(f"{path}.{key}" if path else key, f.spec, kind)

    walk("", reader.TOP)
    for key, spec in sections.SECTIONS.items():
        if spec == "model":
            for kind, kspec in sections.MODEL_KINDS.items():
                walk("model", kspec, kind)
        else:
            walk(key, spec)
    return out


def documented_tables(text: str) -> dict[tuple[str, str | None], dict[str, str]]:
    """(table path, model kind) -> {key: its table row} from the page: a heading names its
    table (`[path]`, `[[path]]`, 'Top level', with `kind = "..."` for a model kind), and the
    keys are the backticked names in the first column of the tables under it."""
    out = {}
    parts = re.split(r"^(#{2,4} .+)$", text, flags=re.M)
    for heading, body in zip(parts[1::2], parts[2::2]):
        m = re.search(r"`\[\[?([\w.]+)\]\]?`", heading)
        if m:
            path = m.group(1)
        elif heading.strip("# ").lower() == "top level":
            path = ""
        else:
            continue
        kind = re.search(r'kind = "(\w+)"', heading)
        rows = {}
        for row in re.findall(r"^\| (.+) \|$", body, flags=re.M):
            first = row.split(" | ")[0]
            if first in ("key", "---") or set(first) <= set("- "):
                continue
            for key in re.findall(r"`([^`]+)`", first):
                rows[key] = row
        if rows:
            out[(path, kind.group(1) if kind else None)] = rows
    return out


def test_every_schema_key_is_documented_and_every_documented_key_exists():
    schema = schema_tables()
    docs = documented_tables(PAGE.read_text(encoding="utf-8"))
    missing_tables = sorted(str(t) for t in schema if t not in docs)
    assert missing_tables == [], f"tables with no key table in docs/case-files.md: {missing_tables}"
    assert sorted(str(t) for t in docs if t not in schema) == [], (
        "documented tables the schema does not have"
    )
    for table, spec in schema.items():
        where = f"[{table[0] or 'top level'}]" + (f' kind = "{table[1]}"' if table[1] else "")
        assert sorted(set(spec) - set(docs[table])) == [], f"{where}: undocumented keys"
        assert sorted(set(docs[table]) - set(spec)) == [], (
            f"{where}: documented keys the schema does not accept"
        )


def test_every_choice_is_named_in_its_row():
    docs = documented_tables(PAGE.read_text(encoding="utf-8"))
    for table, spec in schema_tables().items():
        for key, f in spec.items():
            if not f.choices or f.kind == "int":
                continue
            row = docs[table][key]
            absent = [c for c in f.choices if f"`{c}`" not in row and f'"{c}"' not in row]
            assert absent == [], f"[{table[0]}] {key}: choices not in docs/case-files.md: {absent}"


def test_the_check_sees_a_missing_and_an_extra_key():
    """The parser on a page with one key too few and one too many fails both ways."""
    page = (
        "## `[score]`\n\n| key | default | meaning |\n| --- | --- | --- |\n"
        "| `weight` | 1 | typo |\n\n## `[run]`\n\n| key | meaning |\n| --- | --- |\n"
        "| `seeds`, `stages` | x |\n"
    )
    docs = documented_tables(page)
    assert docs[("score", None)].keys() == {"weight"}
    assert docs[("run", None)].keys() == {"seeds", "stages"}
    schema = schema_tables()
    assert set(schema[("score", None)]) - set(docs[("score", None)]) == {"weights"}
    assert set(schema[("run", None)]) == set(docs[("run", None)])


@pytest.mark.parametrize("kind", sorted(sections.MODEL_KINDS))
def test_model_kinds_have_their_own_tables(kind):
    docs = documented_tables(PAGE.read_text(encoding="utf-8"))
    assert ("model", kind) in docs
