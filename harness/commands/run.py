"""springbench run [PATH ...]: run case files or suites and write results/."""

from __future__ import annotations

from pathlib import Path

HELP = (
    "run case files or folders of them and write tables to runs/ (default: the quick tier, "
    "one case per capability, minutes; --full or a folder such as cases/ runs every case; "
    "the published results/ are the --full run: --full --results results)"
)


def _positive_int(text):
    import argparse

    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number (e.g. --jobs 2)")
    if n < 1:
        raise argparse.ArgumentTypeError(f"{n} must be at least 1 (e.g. --jobs 2)")
    return n


def add_arguments(p):
    p.add_argument(
        "paths",
        nargs="*",
        metavar="PATH",
        help="case files or folders (default: the quick tier of cases/, one case per "
        "capability; with --full every case under cases/)",
    )
    mode = p.add_mutually_exclusive_group()
    mode.add_argument(
        "--quick",
        dest="mode",
        action="store_const",
        const="quick",
        help="the case's quick budget (default)",
    )
    mode.add_argument(
        "--full",
        dest="mode",
        action="store_const",
        const="full",
        help="the case's full budget: reproduces the papers (without PATH: every case "
        "under cases/, hours)",
    )
    p.set_defaults(mode="quick")
    p.add_argument(
        "--results",
        type=Path,
        default=None,
        help="output folder (default: runs/; results/ holds the published --full run and takes "
        "only --full)",
    )
    p.add_argument(
        "--jobs",
        "-j",
        type=_positive_int,
        default=None,
        metavar="N",
        help="parallel cases/seeds (default: the number of cores; 1 runs in this process)",
    )
    p.add_argument(
        "--executor",
        choices=("local", "dask"),
        default="local",
        help="local process pool (default) or a Dask cluster",
    )
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="Dask scheduler address, e.g. tcp://10.0.0.5:8786 (with --executor dask; "
        "without it a local Dask cluster of --jobs workers is started)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="recompute finished cases even if their inputs are unchanged",
    )
    p.add_argument("--no-figures", dest="figures", action="store_false", help="tables only")
    p.add_argument(
        "--quiet",
        action="store_true",
        help="no progress bar (cases done, time left; never drawn when stderr is not a "
        "terminal, where one line per finished case and every 30 s one with the time left "
        "go to stdout instead) and no such lines",
    )


def default_paths(mode: str) -> list[Path]:
    """The cases run without PATH: the quick tier (said in one line), or with --full every
    case under cases/ (an empty list: the runner's default)."""
    from harness.suites import QUICK, QUICK_SECONDS, quick_cases

    if mode == "full":
        return []
    print(
        f"springbench run: the quick tier, {len(QUICK)} cases, one per capability (about "
        f"{QUICK_SECONDS / 60:.0f} min of CPU); every case: springbench run --full, or a folder "
        "(springbench run cases/)",
        flush=True,
    )
    return quick_cases()


def main(args) -> int:
    from harness.errors import SpringbenchError
    from harness.paths import DEFAULT_RESULTS, DEFAULT_RUNS
    from harness.run.runner import run_suite

    results = args.results or DEFAULT_RUNS
    if args.mode != "full" and Path(results).resolve() == Path(DEFAULT_RESULTS).resolve():
        raise SpringbenchError(
            "results/ holds the published --full run; a quick run would overwrite it",
            file=str(results),
            field="--results",
            fix="drop --results (quick runs go to runs/) or add --full to republish",
        )
    paths = args.paths or default_paths(args.mode)
    rep = run_suite(
        paths,
        args.mode,
        results,
        jobs=args.jobs,
        executor=args.executor,
        scheduler=args.scheduler,
        force=args.force,
        figures=args.figures,
        progress=False if getattr(args, "quiet", False) else None,
    )
    import pandas as pd

    from harness.report.findings import case_lines, legend, summary_text

    seen = []
    for suite in rep.suites:
        csv = suite / "summary.csv"
        df = pd.read_csv(csv)
        lines = case_lines(df)
        seen += list(lines["findings"])
        print(
            f"\n== {suite.name}: {len(df)} rows in {csv} (all columns; tables and figures: "
            "summary.md)"
        )
        print("\n".join(summary_text(suite.name, lines)))
    if rep.suites:
        print(
            "\n".join(
                [
                    "\nmodel: each case's best fit on the fitted loads (else its best "
                    "stiffness rule); held-out: "
                    "the mean of each held-out load's G where recorded, else the pooled G"
                ]
                + legend(seen)
            )
        )
    n = len(rep.results)
    print(
        f"\n{n} jobs: {len(rep.ran)} ran, {len(rep.skipped)} unchanged (skipped; --force "
        "recomputes), "
        f"{len(rep.failed)} failed{' (one line each above)' if rep.failed else ''}. "
        f"Index: {Path(results) / 'index.html'}"
    )
    return 2 if rep.failed else 0
