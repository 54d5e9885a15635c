"""The code's own hygiene: ``ruff check`` (the rules in pyproject.toml) is clean, and no
module, test, help text or docstring tells the history of the code or names an issue
(that belongs in CHANGELOG.md)."""

import re
import subprocess
import sys

from harness.paths import ROOT

CODE = ("harness", "reference", "tests", "cases", "examples", "docs")
HISTORY = [r"\bissues? ?#?\d+", r"\bpreviously\b", r"\bformerly\b", r"\bthe old (?!file|one)", r"\bused to be\b",
           r"\bthe former\b", r"\bwas changed\b", r"\bhad been\b", r"\bthe new default\b",
           r"\bbefore this (?:session|change)\b", r"\bany ?more\b", r"\bearlier runs\b"]
EXTERNAL = re.compile(r"\b(numba|scikit-fem|meshio|newton|warp|mujoco|pyamg|scipy) issue", re.I)   # others' trackers


def history_lines(text: str) -> list[str]:
    """The lines of ``text`` that tell how the code used to be."""
    pattern = re.compile("|".join(HISTORY), re.I)
    return [ln.strip() for ln in text.splitlines() if pattern.search(ln) and not EXTERNAL.search(ln)]


def test_ruff_check_is_clean():
    proc = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "--output-format", "concise", "."],
                          cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-1000:]


def test_no_history_or_issue_numbers_in_the_code():
    found = []
    for folder in CODE:
        for path in sorted((ROOT / folder).rglob("*.py")):
            if path.name in ("test_lint.py", "test_docs.py"):     # they hold the patterns
                continue
            found += [f"{path.relative_to(ROOT)}: {ln}" for ln in history_lines(path.read_text())]
    assert not found, "\n".join(found)


def test_the_history_scan_finds_history_and_spares_other_trackers():
    text = ("# issue 12: the hexa rows had f1 0\nx = 1  # previously 2\n"
            "# a crash in numba issue 8578\n# the old estimate was 0.12\n# the old file stays\n")
    assert history_lines(text) == ["# issue 12: the hexa rows had f1 0", "x = 1  # previously 2",
                                    "# the old estimate was 0.12"]
