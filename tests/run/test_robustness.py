"""Bad inputs never give tracebacks: the catalogue in tests/bad_inputs/ (case fields,
meshes, parameters), CLI flags, a hypothesis property test of the case parser, case files
that look like code, and output paths that try to leave the results folder.

Each catalogue file starts with ``# expect: <text>`` lines (all must appear in the one
error line) and optionally ``# only: run`` (an error only ``springbench run`` can see,
e.g. a case name that is a path) or ``# only: full`` (an error in the [full] override)."""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from harness import cli
from harness.case.reader import Case, load_case
from harness.errors import CaseError

HERE = Path(__file__).resolve().parents[1]  # tests/
CATALOGUE = sorted((HERE / "bad_inputs").glob("*.toml"))
ERROR = re.compile(r"^springbench( \w+)?: (error: )?")


def header(path: Path, key: str) -> list[str]:
    text = path.read_bytes().decode("utf-8", "replace")
    return [ln.split(":", 1)[1].strip() for ln in text.splitlines() if ln.startswith(f"# {key}:")]


def names_a_fix(line: str) -> bool:
    """A fix in parentheses, or a message that says what is expected."""
    return line.rstrip().endswith(")") or any(w in line for w in ("expected", "one of", "must"))


def cli_run(argv, capsys) -> tuple[int, list[str], str]:
    try:
        code = cli.main([str(a) for a in argv])
    except SystemExit as exc:  # argparse errors
        code = exc.code
    out = capsys.readouterr()
    return code, [ln for ln in out.err.splitlines() if ln.strip()], out.out


def test_catalogue_is_large_and_annotated():
    """>= 150 distinct bad inputs, each tested for exit 2 and one line: the case
    files here, the CLI flag cases below, and the tables of tests/test_bad_*.py (calibrate
    flags and meshes, case-file edits per section, score/reference/build/report inputs,
    unwritable outputs and full disks)."""
    from tests.case.test_bad_cases import BAD_CASES
    from tests.case.test_schema_types import PARAMS
    from tests.commands.test_bad_calibrate import CALIBRATE_CASES
    from tests.commands.test_bad_commands import COMMAND_CASES
    from tests.commands.test_bad_outputs import OUTPUT_CASES
    from tests.commands.test_bad_score import SCORE_FLAG_CASES

    names = (
        [f"case file {p.name}" for p in CATALOGUE]
        + [f"cli {' '.join(a)}" for a, _ in CLI_CASES]
        + CALIBRATE_CASES
        + BAD_CASES
        + COMMAND_CASES
        + OUTPUT_CASES
        + SCORE_FLAG_CASES
        + [f"case key {key} = a {kind} ({base['']['name']})" for base, key, kind in PARAMS]
    )
    assert len(set(names)) == len(names) >= 300, len(names)
    assert all(header(p, "expect") for p in CATALOGUE)


@pytest.mark.parametrize("path", CATALOGUE, ids=lambda p: p.stem)
def test_catalogue_validate(path, capsys):
    only = header(path, "only")
    code, err, _ = cli_run(["validate", path], capsys)
    if only == ["run"]:
        assert code == 0, err
        return
    assert code == 2
    assert len(err) == 1, err
    line = err[0]
    assert line.startswith("springbench: error: ") and "Traceback" not in line
    assert path.name in line
    for e in header(path, "expect"):
        assert e in line, (e, line)
    assert names_a_fix(line), line


@pytest.fixture(scope="module")
def catalogue_run(tmp_path_factory):
    """The whole catalogue as one suite through `springbench run` (quick, then the
    [full]-only file with --full): every file fails on its own, the suite carries on."""
    import contextlib
    import io
    import shutil

    from harness import registry

    work = tmp_path_factory.mktemp("catalogue")
    cat = work / "bad_inputs"  # a copy: the fake stage writes calls.log beside the case files
    shutil.copytree(HERE / "bad_inputs", cat)
    res = work / "results"
    out = {}
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(registry, "STAGES", registry.STAGES.with_entries({"fake": "tests.fakestage"}))
        for mode, paths in (
            ("--quick", [cat]),
            ("--full", [cat / p.name for p in CATALOGUE if header(p, "only") == ["full"]]),
        ):
            err = io.StringIO()
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                code = cli.main(
                    [
                        "run",
                        *map(str, paths),
                        "--results",
                        str(res),
                        "--jobs",
                        "1",
                        "--no-figures",
                        mode,
                    ]
                )
            out[mode] = (code, [ln for ln in err.getvalue().splitlines() if ln.strip()])
    return res, out


@pytest.mark.parametrize("path", CATALOGUE, ids=lambda p: p.stem)
def test_catalogue_run(path, catalogue_run):
    """The same files through `springbench run`: one error line each, exit 2."""
    res, out = catalogue_run
    code, err = out["--full" if header(path, "only") == ["full"] else "--quick"]
    assert code == 2
    assert not any("Traceback" in ln for ln in err)
    mine = [ln for ln in err if f"/{path.name}:" in ln or f" {path.name}:" in ln]
    assert len(mine) == 1, (path.name, err)
    assert ERROR.match(mine[0])
    for e in header(path, "expect"):
        assert e in mine[0], (e, mine[0])


def test_catalogue_run_writes_only_inside_results(catalogue_run):
    import pandas as pd

    res, out = catalogue_run
    root = res.parent
    assert all(
        p.resolve().is_relative_to(res.resolve()) or p.is_relative_to(root / "bad_inputs")
        for p in root.rglob("*")
        if p.is_file()
    )
    assert not (HERE / "bad_inputs" / "calls.log").exists()
    df = pd.read_csv(res / "bad_inputs" / "summary.csv")
    assert (df.status == "error").all() and len(df) == len(CATALOGUE)
    assert len(out["--quick"][1]) == len(CATALOGUE) - 1  # one line per failure, nothing else


CLI_CASES = [
    (["run", "--jobs", "0"], "--jobs/-j: 0 must be at least 1 (e.g. --jobs 2)"),
    (["run", "--jobs", "two"], "'two' is not a whole number"),
    (["run", "--executor", "spark"], "invalid choice: 'spark'"),
    (["run", "--quick", "--full"], "not allowed with argument"),
    (["run", "--frobnicate"], "unrecognized arguments: --frobnicate"),
    (["run", "no/such/case.toml"], "no/such/case.toml: no such file or folder (check the path)"),
    (
        ["run", "--scheduler", "tcp://127.0.0.1:1", "CASES"],
        "--scheduler: --scheduler needs --executor dask",
    ),
    (["run", "CASES", "--results", "AFILE"], "--results: exists and is not a folder"),
    (["report", "no/such/results"], "no/such/results: no such folder"),
    (["validate"], "the following arguments are required: FILE"),
    (["validate", "no/such.toml"], "no/such.toml: no such file or folder"),
    (["bench", "nosuch"], "invalid choice: 'nosuch'"),
    (["nosuchcommand"], "invalid choice: 'nosuchcommand'"),
]


@pytest.mark.parametrize("argv, expect", CLI_CASES, ids=[" ".join(a) for a, _ in CLI_CASES])
def test_cli_flags(argv, expect, tmp_path, capsys, fake):
    (tmp_path / "AFILE").write_text("x")
    argv = [
        str(tmp_path / "AFILE")
        if a == "AFILE"
        else str(HERE / "bad_inputs" / "E_zero.toml")
        if a == "CASES"
        else a
        for a in argv
    ]
    code, err, _ = cli_run(argv, capsys)
    assert code == 2
    assert len(err) == 1 and ERROR.match(err[0]) and "Traceback" not in err[0], err
    assert expect in err[0]


def test_through_a_real_process(tmp_path):
    """The installed entry point: exit status 2, one line, no traceback."""
    for argv in (
        ["validate", str(HERE / "bad_inputs" / "mesh_inverted_tet.toml")],
        ["run", "--jobs", "-3"],
        ["report", str(tmp_path)],
    ):
        p = subprocess.run(
            [sys.executable, "-m", "harness", *argv],
            capture_output=True,
            text=True,
            timeout=120,
            cwd=tmp_path,
            env={
                **os.environ,
                "PYTHONPATH": os.pathsep.join([str(HERE.parent), os.environ.get("PYTHONPATH", "")]),
            },
        )
        lines = p.stderr.strip().splitlines()
        assert p.returncode == 2 and len(lines) == 1 and "Traceback" not in p.stderr, p.stderr


# -- case files cannot run code ---------------------------------------------------------------


def test_case_files_cannot_run_code(tmp_path):
    marker = tmp_path / "pwned"
    payload = f"__import__('os').system('touch {marker}')"
    (tmp_path / "c.toml").write_text(f'''name = "{payload}"
dim = 2
description = "{{{{ {payload} }}}} $(touch {marker}) `touch {marker}`"
tags = ["!!python/object/apply:os.system ['touch {marker}']"]
[body]
shape = "rectangle"
size = [1.0, 1.0]
[material]
E = 1.0
nu = 0.25
''')
    case = load_case(tmp_path / "c.toml")
    assert case.name == payload and not marker.exists()
    # the loaders parse with tomllib only; nothing is evaluated or unpickled
    root = HERE.parent / "harness"
    for f in ("case/reader.py", "case/schema.py", "case/sections.py"):
        src = (root / f).read_text()
        assert not re.search(
            r"\b(eval|exec|compile|__import__)\s*\(|pickle|yaml|import_module", src
        ), f


# -- property test: the parser returns a Case or raises CaseError, nothing else -----------------

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

KEYS = (
    ["name", "dim", "description", "tags", "body", "shape", "size"]
    + ["origin", "vertices", "file", "format", "parts", "box", "material"]
    + ["E", "nu", "density", "plane", "fibre", "E_fibre", "E_cross"]
    + ["direction", "field", "regions", "loads", "set", "magnitude", "case"]
    + ["constraint", "part", "components", "traction", "vector", "gravity"]
    + ["reference", "element", "cell", "tol", "quick", "full", "score"]
    + ["weights", "run", "seeds", "stages", "expect", "values", "model"]
    + ["kind", "bogus", "x0"]
)
WORDS = (
    ["x0", "x1", "y0", "x0y0", "basic2d", "basic3d", "rectangle", "box"]
    + ["polygon", "mesh", "stress", "strain", "P1", "P2", "tri", "quad"]
    + ["tet", "hex", "all", "z", "vertical", "sms", "stretch-x", "..", ""]
    + ["/", "nan"]
)
SCALARS = (
    st.booleans()
    | st.integers(-5, 5)
    | st.integers()
    | st.floats()
    | st.text(max_size=6)
    | st.sampled_from(WORDS)
)
VALUES = st.recursive(
    SCALARS,
    lambda ch: (
        st.lists(ch, max_size=4)
        | st.dictionaries(st.sampled_from(KEYS) | st.text(max_size=4), ch, max_size=4)
    ),
    max_leaves=12,
)

BASE = {
    "name": "p",
    "dim": 2,
    "body": {"shape": "rectangle", "size": [2.0, 1.0]},
    "material": {"E": 100.0, "nu": 0.3},
    "loads": {
        "set": "basic2d",
        "case": [
            {
                "name": "pull",
                "constraint": [{"part": "x0"}],
                "traction": [{"part": "x1", "vector": [1.0, 0.0]}],
            }
        ],
    },
    "score": {"weights": [1.0, 3.0, 15.0]},
    "run": {"seeds": [0, 1]},
}


def toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return (
            "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
        )
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    return "{" + ", ".join(f"{toml_key(k)} = {toml_value(x)}" for k, x in v.items()) + "}"


def toml_key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else json.dumps(k, ensure_ascii=False)


def to_toml(d: dict) -> str:
    return "".join(f"{toml_key(k)} = {toml_value(v)}\n" for k, v in d.items())


def paths_of(obj, prefix=()):
    yield prefix
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from paths_of(v, prefix + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from paths_of(v, prefix + (i,))


def mutate(doc, data):
    doc = json.loads(json.dumps(doc))
    for _ in range(data.draw(st.integers(1, 4))):
        paths = [p for p in paths_of(doc) if p]
        path = data.draw(st.sampled_from(paths))
        parent = doc
        for k in path[:-1]:
            parent = parent[k]
        op = data.draw(st.sampled_from(["delete", "replace", "add"]))
        if op == "delete":
            del parent[path[-1]]
        elif op == "replace":
            parent[path[-1]] = data.draw(VALUES)
        elif isinstance(parent, dict):
            parent[data.draw(st.sampled_from(KEYS))] = data.draw(VALUES)
        if not doc:
            break
    return doc


TMP = Path(tempfile.mkdtemp(prefix="springbench-hyp-"))
__import__("atexit").register(__import__("shutil").rmtree, TMP, True)


def parse(text: str):
    f = TMP / "case.toml"
    f.write_text(text, encoding="utf-8", errors="surrogatepass")
    for mode in ("quick", "full"):
        try:
            assert isinstance(load_case(f, mode), Case)
        except CaseError as exc:
            assert "\n" not in str(exc)


def test_base_document_is_valid():
    assert load_case_text(to_toml(BASE)).name == "p"


def load_case_text(text):
    f = TMP / "base.toml"
    f.write_text(text)
    return load_case(f)


@settings(max_examples=400, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.data())
def test_parser_mutated_cases_give_case_or_case_error(data):
    parse(to_toml(mutate(BASE, data)))


@settings(max_examples=200, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.dictionaries(st.sampled_from(KEYS), VALUES, max_size=8))
def test_parser_random_documents_give_case_or_case_error(doc):
    parse(to_toml(doc))


@settings(max_examples=100, deadline=None)
@given(st.text(max_size=200))
def test_parser_random_text_gives_case_error(text):
    try:
        parse(text)
    except UnicodeEncodeError:  # lone surrogates cannot be written as a file at all
        pass
