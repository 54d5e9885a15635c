"""springbench validate FILE...: check case files against the schema."""

from __future__ import annotations

import sys

from harness.case.reader import MODES, find_cases, load_case
from harness.errors import SpringbenchError, error_lines
from harness.stages import check_case

HELP = "check case files (or folders of them) against the schema; one line per mistake"


def add_arguments(p):
    p.add_argument("paths", nargs="+", metavar="FILE", help="case files or folders")


def main(args) -> int:
    bad = 0
    files = find_cases(args.paths)
    for f in files:
        try:
            for mode in MODES:
                check_case(load_case(f, mode))
        except SpringbenchError as exc:
            bad += 1
            for line in error_lines(exc):  # one line per mistake
                print(f"springbench: error: {line}", file=sys.stderr)
        else:
            print(f"ok  {f}")
    return 2 if bad else 0
