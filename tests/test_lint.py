"""The code's own hygiene: ``ruff check`` (the rules in pyproject.toml) and ``ruff format
--check`` are clean, and no module, test, help text or docstring tells the history of the
code or names an issue (that belongs in CHANGELOG.md)."""

import re
import subprocess
import sys

from harness.paths import ROOT

CODE = ("harness", "reference", "tests", "cases", "examples", "docs")
# the patterns spell their words with a character class, so this file does not match itself
HISTORY = [
    r"\biss[u]es? ?#?\d+",
    r"\bprev[i]ously\b",
    r"\bform[e]rly\b",
    r"\bthe o[l]d (?!file|one)",
    r"\bused t[o] be\b",
    r"\bthe for[m]er\b",
    r"\bwas ch[a]nged\b",
    r"\bhad be[e]n\b",
    r"\bthe new def[a]ult\b",
    r"\bbefore this (?:sess[i]on|ch[a]nge)\b",
    r"\bany ?mo[r]e\b",
    r"\bearlier r[u]ns\b",
    r"\bthe first v[e]rsion\b",
]
# others' trackers
EXTERNAL = re.compile(r"\b(numba|scikit-fem|meshio|newton|warp|mujoco|pyamg|scipy) issue", re.I)


def history_lines(text: str) -> list[str]:
    """The lines of ``text`` that tell the code's past rather than what it is."""
    pattern = re.compile("|".join(HISTORY), re.I)
    return [
        ln.strip() for ln in text.splitlines() if pattern.search(ln) and not EXTERNAL.search(ln)
    ]


def test_ruff_check_is_clean():
    proc = subprocess.run(
        [sys.executable, "-m", "ruff", "check", "--no-cache", "--output-format", "concise", "."],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-1000:]


def test_the_project_is_in_ruff_format_style():
    """Line length 100 (E501 holds everywhere, no file exempt) and one layout."""
    proc = subprocess.run(
        [sys.executable, "-m", "ruff", "format", "--check", "--no-cache", "."],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-1000:]


def test_no_history_or_issue_numbers_in_the_code():
    found = []
    for folder in CODE:
        for path in sorted((ROOT / folder).rglob("*.py")):
            found += [f"{path.relative_to(ROOT)}: {ln}" for ln in history_lines(path.read_text())]
    assert not found, "\n".join(found)


def test_the_history_scan_finds_history_and_spares_other_trackers():
    issue, before, old = "iss" + "ue 12", "prev" + "iously", "the o" + "ld"
    lines = [
        f"# {issue}: the hexa rows had f1 0",
        f"x = 1  # {before} 2",
        "# a crash in numba iss" + "ue 8578",
        f"# {old} estimate was 0.12",
        f"# {old} file stays",
    ]
    assert history_lines("\n".join(lines)) == [lines[0], lines[1], lines[3]]


# handlers of these that neither raise nor stand here change behaviour silently
SWALLOWED = ("ImportError", "ModuleNotFoundError", "TypeError")
# (file, what the handler does instead): optional tools a benchmark reports as missing in
# its table, and the report's conversion of a cell to a number
ALLOWED = {
    ("harness/bench/heldout.py", "a row saying gmsh is missing"),
    ("harness/bench/calibrate.py", "a row saying gmsh is missing"),
    ("harness/report/findings.py", "a cell that is not a number is NaN"),
    ("harness/report/numbers.py", "a cell that is not a number is printed as it is"),
    ("harness/report/claims.py", "a foreign or partial summary gets no sentence"),
    ("harness/report/figures/volume.py", "results moved from their cases: no such figure"),
    ("harness/export/pack.py", "a one-line error naming the pack (its _bad raises)"),
}


def silent_handlers(text: str) -> list[int]:
    """Lines of the ``except`` clauses catching an import or type error whose body raises
    nothing: a missing module or a wrong call would take another path unseen."""
    import ast

    out = []
    for node in ast.walk(ast.parse(text)):
        if not isinstance(node, ast.ExceptHandler) or node.type is None:
            continue
        types = node.type.elts if isinstance(node.type, ast.Tuple) else [node.type]
        names = {t.id for t in types if isinstance(t, ast.Name)}
        raises = any(isinstance(n, ast.Raise) for b in node.body for n in ast.walk(b))
        if names & set(SWALLOWED) and not raises:
            out.append(node.lineno)
    return out


def test_no_import_or_type_error_is_swallowed():
    allowed = {f for f, _ in ALLOWED}
    found = {}
    for folder in ("harness", "reference"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            lines = silent_handlers(path.read_text(encoding="utf-8"))
            if lines and rel not in allowed:
                found[rel] = lines
    assert not found, f"except clauses that swallow {SWALLOWED}: {found}"
    # the scan finds the pattern it is for, and spares a handler that raises
    swallow = "try:\n    import x\nexcept ImportError:\n    x = None\n"
    retry = "try:\n    f(a, b=1)\nexcept TypeError:\n    f(a)\n"
    loud = "try:\n    import x\nexcept ImportError as e:\n    raise SystemExit(str(e))\n"
    assert silent_handlers(swallow) == [3] and silent_handlers(retry) == [3]
    assert silent_handlers(loud) == []


# a function does one thing, in at most this many lines (from ``def`` to its last line), in
# every hand-written module (generated ones say so on their first line)
MAX_FUNCTION_LINES = 80
SMALL_FUNCTION_ROOMS = ("harness", "reference")
# (file, function): why it is longer; an entry that fits the limit is an error (remove it)
LONG_ALLOWED = {
    ("harness/optimize/incremental_kernels.py", "_propose"): (
        "a numba kernel compiled with fastmath: split, its vectorised sums would round "
        "differently (27 of its lines are the argument list)"
    ),
}


def long_functions(text: str, limit: int = MAX_FUNCTION_LINES) -> list[tuple[str, int]]:
    """(name, lines) of the functions and methods in ``text`` longer than ``limit`` lines."""
    import ast

    return [
        (node.name, n)
        for node in ast.walk(ast.parse(text))
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
        and (n := node.end_lineno - node.lineno + 1) > limit
    ]


def test_functions_are_small():
    found, seen = {}, set()
    for room in SMALL_FUNCTION_ROOMS:
        for path in sorted((ROOT / room).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            text = path.read_text(encoding="utf-8")
            if text.lstrip('"').startswith("GENERATED"):
                continue
            for name, n in long_functions(text):
                seen.add((rel, name))
                if (rel, name) not in LONG_ALLOWED:
                    found[f"{rel}:{name}"] = n
    assert not found, f"functions over {MAX_FUNCTION_LINES} lines (split them): {found}"
    stale = sorted(set(LONG_ALLOWED) - seen)
    assert not stale, f"LONG_ALLOWED entries that are short now or gone (remove them): {stale}"
    # the scan counts from def to the last line, nested functions and methods too
    body = "".join(f"    x{i} = {i}\n" for i in range(MAX_FUNCTION_LINES))
    src = f"def long():\n{body}\n\nclass C:\n    def m(self):\n        return 1\n"
    assert long_functions(src) == [("long", MAX_FUNCTION_LINES + 1)]
    assert long_functions(src, MAX_FUNCTION_LINES + 1) == []
