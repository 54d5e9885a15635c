"""springbench report [SUITE_DIR ...]: rebuild tables and figures from stored results.

Writes into the results root it reads: runs/ (where ``springbench run`` puts a user's runs)
unless ``--results`` names another, e.g. ``--results results`` for the published tables.
Its outputs depend only on the stored results and the code (no dates, no machine): re-run
on unchanged results it changes no file, and a figure is redrawn only when the data it
reads or the figure code changed."""

from __future__ import annotations

from pathlib import Path

HELP = (
    "rebuild summary tables, figures, index.html and README.md from stored results (no "
    "recomputation; "
    "runs/ by default, --results results for the published ones)"
)


def add_arguments(p):
    p.add_argument(
        "paths",
        nargs="*",
        metavar="SUITE_DIR",
        help="results/<suite> folders (default: every suite under --results)",
    )
    p.add_argument(
        "--results",
        type=Path,
        default=None,
        help="results root (default: runs/, where 'springbench run' writes; results/ holds the "
        "published --full run: --results results)",
    )
    p.add_argument("--no-figures", dest="figures", action="store_false", help="tables only")
    p.add_argument(
        "--redraw",
        action="store_true",
        help="redraw every figure (default: only folders whose data or figure code changed)",
    )


def main(args) -> int:
    from harness.report.build import rebuild

    for out in rebuild(args.paths, args.results, figures=args.figures, redraw=args.redraw):
        print(f"{out['csv']}  ({len(out['table'])} rows, {len(out['figures'])} figures)")
    return 0
