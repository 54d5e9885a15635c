"""Every key of the case-file schema, fed a value of each wrong type (a list, a table, a
string, a boolean, a number): ``springbench validate`` gives exit 2 and one line naming the
file and that key, never a traceback. The keys are walked from the schema itself
(harness/case/reader.py TOP, harness/case/sections.py), so a key added later is fuzzed too."""

from __future__ import annotations

import copy

import pytest

from harness import cli
from harness.case import reader, sections
from tests.run.test_robustness import names_a_fix

# TOML source of each wrong value. The list holds a boolean and a string, so it is wrong for
# every list-valued key too (strings, numbers, tables, seeds, grid sizes).
WRONG = {
    "list": '[true, "x"]',
    "table": "{ a = 1 }",
    "string": '"x"',
    "bool": "true",
    "float": "1.5",
}
# the wrong values that are the key's own type (a string is also a one-item list of strings)
RIGHT = {
    "float": {"float"},
    "str": {"string"},
    "strs": {"string"},
    "bool": {"bool"},
    "table": {"table"},
    "tables": {"table"},
}
# "any" keys: the type their owner expects (the schema's check says it)
ANY_RIGHT = {
    "optimizer.options": {"table"},
    "optimizer.compare_options": {"table"},
    "optimizer.frequency.options": {"table"},
    "expect.values": {"table"},
    "body.parts": {"table"},
}

SMS_2D = {
    "": {"name": '"s"', "dim": "2"},
    "body": {"shape": '"rectangle"', "size": "[2.0, 1.0]"},
    "material": {"E": "1000.0", "nu": "0.3"},
    "loads": {"set": '"basic2d"'},
    "reference": {"cell": '"tri"', "divisions": "2"},
    "model": {
        "kind": '"sms"',
        "placement": '"grid"',
        "grid": "[3, 3]",
        "structure": '"edges+diagonal"',
    },
    "optimizer": {"method": '"none"'},
}
BC2000_3D = {
    "": {"name": '"b"', "dim": "3"},
    "body": {"shape": '"box"', "size": "[1.0, 1.0, 1.0]"},
    "material": {"E": "1000.0", "nu": "0.3"},
    "loads": {"set": '"basic3d"'},
    "reference": {"cell": '"hex"', "divisions": "1"},
    "model": {"kind": '"bc2000"'},
}
# the valid parent a nested key is fuzzed in (added to the base case)
PARENTS = {
    "material.fibre": "{ E_fibre = 2.0, E_cross = 1.0, direction = [1.0, 0.0] }",
    "material.regions": "[{ box = [[0.0, 0.0], [1.0, 1.0]], E = 5.0 }]",
    "loads.case": '[{ name = "t", constraint = [{ part = "x0" }], '
    'traction = [{ part = "x1", vector = [1.0, 0.0] }] }]',
    "optimizer.select": "{}",
    "optimizer.frequency": "{}",
}


def keys(spec, prefix=""):
    """(dotted key, Field) of every key of a spec, nested tables and arrays of tables included."""
    for name, f in spec.items():
        yield prefix + name, f
        if f.kind in ("table", "tables") and f.spec:
            yield from keys(f.spec, prefix + name + ".")


def schema_keys():
    """(base, dotted key, Field): the core sections, the stage-owned ones, each model kind."""
    out = []
    for key, f in keys(reader.TOP):
        out.append((SMS_2D, key, f))
    for sec, spec in sections.SECTIONS.items():
        if spec == "model":
            for kind, base in (("sms", SMS_2D), ("bc2000", BC2000_3D)):
                out += [(base, f"model.{k}", f) for k, f in keys(sections.MODEL_KINDS[kind])]
            out.append((SMS_2D, "model.kind", reader.Field("str")))
            continue
        out.append((SMS_2D, sec, reader.Field("table")))
        out += [(SMS_2D, f"{sec}.{k}", f) for k, f in keys(spec)]
    out += [(SMS_2D, m, reader.Field("table")) for m in reader.MODES]
    return out


def wrong_types(key: str, f) -> list[str]:
    right = ANY_RIGHT.get(key, set()) if f.kind == "any" else RIGHT.get(f.kind, set())
    return [t for t in WRONG if t not in right]


PARAMS = [(base, key, t) for base, key, f in schema_keys() for t in wrong_types(key, f)]


def render(base: dict, key: str, value: str) -> str:
    """The base case with ``key`` (dotted, inside its parents) set to the TOML ``value``."""
    d = copy.deepcopy(base)
    parts = key.split(".")
    top = "" if parts[0] in ("name", "dim", "description", "tags", "quick", "full") else parts[0]
    if len(parts) == 1 and top == "":
        d[""][key] = value
    elif len(parts) == 1:
        d.pop(top, None)
        d[""][top] = value  # the section itself, as a key of the top table
    elif len(parts) == 2:
        d.setdefault(top, {})[parts[1]] = value
    else:  # a key of a nested table: inside its valid parent
        d.setdefault(top, {})[parts[1]] = _inline_set(
            PARENTS[".".join(parts[:2])], parts[2:], value
        )
    lines = [f"{k} = {v}" for k, v in d.pop("").items()]
    for sec, kv in d.items():
        lines += [f"[{sec}]"] + [f"{k} = {v}" for k, v in kv.items()]
    return "\n".join(lines) + "\n"


def _inline_set(parent: str, path: list[str], value: str) -> str:
    """The inline table (or array of tables) ``parent`` with path set to the TOML value;
    each array of tables along the path is entered at its first item."""
    import tomllib

    data = tomllib.loads(f"v = {parent}")["v"]
    item = data
    for name in path[:-1]:
        item = item[0] if isinstance(item, list) else item
        item = item[name]
    item = item[0] if isinstance(item, list) else item
    item[path[-1]] = _Raw(value)
    return _dump(data)


class _Raw(str):
    """TOML source kept as it is."""


def _dump(v) -> str:
    if isinstance(v, _Raw):
        return str(v)
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_dump(x)}" for k, x in v.items()) + " }"
    if isinstance(v, list):
        return "[" + ", ".join(_dump(x) for x in v) + "]"
    if isinstance(v, str):
        return '"' + v + '"'
    if isinstance(v, bool):
        return "true" if v else "false"
    return repr(v)


def validate_lines(path, capsys):
    code = cli.main(["validate", str(path)])
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    return code, [ln for ln in err.splitlines() if ln.startswith("springbench")]


@pytest.mark.parametrize(
    "base, parent",
    [(SMS_2D, None), (BC2000_3D, None)] + [(SMS_2D, p) for p in PARENTS],
    ids=["sms", "bc2000", *PARENTS],
)
def test_the_bases_are_valid(base, parent, tmp_path, capsys):
    """The controls: each wrong value below is the only mistake of its file."""
    f = tmp_path / "base.toml"
    if parent is None:
        text = render(base, "description", '"control"')
    else:
        sec, key = parent.split(".")
        d = copy.deepcopy(base)
        d.setdefault(sec, {})[key] = PARENTS[parent]
        text = render(d, "description", '"control"')
    f.write_text(text)
    assert validate_lines(f, capsys) == (0, []), text


@pytest.mark.parametrize(
    "base, key, kind",
    PARAMS,
    ids=[f"{'bc2000-' if b is BC2000_3D else ''}{k}-{t}" for b, k, t in PARAMS],
)
def test_wrong_type_is_one_line(base, key, kind, tmp_path, capsys):
    f = tmp_path / "c.toml"
    text = render(base, key, WRONG[kind])
    f.write_text(text)
    code, lines = validate_lines(f, capsys)
    assert code == 2 and len(lines) == 1, (text, lines)
    line = lines[0]
    field = key.replace("loads.case.", "loads.case[0].").replace(
        "material.regions.", "material.regions[0]."
    )
    field = field.replace("constraint.", "constraint[0].").replace("traction.", "traction[0].")
    assert line.startswith(f"springbench: error: {f}: ") and field in line and names_a_fix(line), (
        text,
        line,
    )


def test_every_section_and_kind_is_walked():
    """The walk reaches the nested keys and both model kinds (a test that walked nothing would
    pass)."""
    walked = {k for _, k, _ in PARAMS}
    for key in (
        "material.fibre.E_fibre",
        "loads.case.constraint.components",
        "loads.case.traction.twist",
        "material.regions.box",
        "model.grid",
        "model.ks",
        "optimizer.select.maxiter",
        "optimizer.frequency.options",
        "dynamics.snapshots",
        "expect.values",
        "run.seeds",
        "body.parts",
        "quick",
        "model.kind",
    ):
        assert key in walked, key
    assert len(PARAMS) > 400
