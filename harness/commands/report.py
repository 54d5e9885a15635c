"""springbench report [results/<suite> ...]: rebuild tables and figures from stored results."""

from __future__ import annotations

from pathlib import Path

HELP = "rebuild summary tables, figures and results/index.html from stored results (no recomputation)"


def add_arguments(p):
    p.add_argument("paths", nargs="*", metavar="SUITE_DIR",
                   help="results/<suite> folders (default: every suite under --results)")
    p.add_argument("--results", type=Path, default=None, help="results root (default: results/)")
    p.add_argument("--no-figures", dest="figures", action="store_false", help="tables only")
    p.add_argument("--redraw", action="store_true",
                   help="redraw every figure (default: only folders whose data or figure code changed)")


def main(args) -> int:
    from harness.report.build import rebuild
    for out in rebuild(args.paths, args.results, figures=args.figures, redraw=args.redraw):
        print(f"{out['csv']}  ({len(out['table'])} rows, {len(out['figures'])} figures)")
    return 0
