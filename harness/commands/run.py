"""springbench run [PATH ...]: run case files or suites and write results/."""

from __future__ import annotations

from pathlib import Path

HELP = "run case files or folders of them (default: every case under cases/) and write tables to results/"


def add_arguments(p):
    p.add_argument("paths", nargs="*", metavar="PATH", help="case files or folders (default: cases/)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--quick", dest="mode", action="store_const", const="quick",
                      help="the case's quick budget (default)")
    mode.add_argument("--full", dest="mode", action="store_const", const="full",
                      help="the case's full budget: reproduces the papers")
    p.set_defaults(mode="quick")
    p.add_argument("--results", type=Path, default=None, help="output folder (default: results/)")


def main(args) -> int:
    from harness.runner import DEFAULT_RESULTS, run_paths
    tables = run_paths(args.paths, args.mode, args.results or DEFAULT_RESULTS)
    for suite, df in tables.items():
        print(f"\n== {suite} ({len(df)} rows) -> {(args.results or DEFAULT_RESULTS) / suite / 'summary.csv'}")
        print(df.to_string(index=False, max_colwidth=40))
    return 0
