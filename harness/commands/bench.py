"""springbench bench NAME: benchmarks registered in harness.registry.BENCHES. Every row of the
CSV carries the provenance of the run (harness/provenance.py FIELDS: format version, git
commit and dirty flag, library versions, CPU model, cores, load average at the start)."""

from __future__ import annotations

import inspect
import sys
from pathlib import Path

from harness import registry

HELP = (
    "run a benchmark (reference, sa, fit, dynamics, ...) and write runs/bench/NAME.csv "
    "(--results results: the published results/bench/)"
)


def add_arguments(p):
    p.add_argument("name", choices=sorted(registry.BENCHES), help="which benchmark")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: RESULTS/bench)")
    p.add_argument(
        "--results",
        type=Path,
        default=None,
        help="results root whose bench/ folder gets the CSV (default: runs/; results/ holds the "
        "published benchmarks: --results results)",
    )
    p.add_argument("--quick", action="store_true", help="smaller sizes, for a smoke test")
    p.add_argument(
        "--quiet",
        action="store_true",
        help="no progress bar (sizes done, ETA; never drawn when stderr is not a terminal)",
    )


def main(args) -> int:
    from harness.outputs import atomic_write, check_out_dir, check_out_file
    from harness.paths import DEFAULT_RESULTS, DEFAULT_RUNS

    out = args.out or Path(getattr(args, "results", None) or DEFAULT_RUNS) / "bench"
    flag = "--out" if args.out else "--results" if getattr(args, "results", None) else None
    path = out / f"{args.name}.csv"
    if args.quick and Path(out).resolve() == (Path(DEFAULT_RESULTS) / "bench").resolve():
        from harness.errors import SpringbenchError

        raise SpringbenchError(
            "results/bench holds the published benchmarks; a --quick run would overwrite them",
            file=str(out),
            field=flag,
            fix="drop --results (quick runs go to runs/bench)",
        )
    check_out_dir(out, flag)  # before a bench that takes minutes
    check_out_file(path, flag)
    from harness.progress import configure
    from harness.provenance import collect, columns

    configure(getattr(args, "quiet", False))
    started = collect()  # the load average at the start, before the bench loads the machine
    mod = registry.BENCHES.load(args.name)
    extra = {}
    if "work" in inspect.signature(mod.run).parameters:  # a bench that resumes its units
        extra["work"] = Path(out) / "_work" / (args.name + ("-quick" if args.quick else ""))
        print(
            f"finished units are kept in {extra['work']}: a run that stops resumes there "
            "(delete the folder to start over)",
            file=sys.stderr,
        )
    df = mod.run(quick=args.quick, **extra)
    df = df.assign(**{k: v for k, v in columns(started).items() if k not in df.columns})
    atomic_write(path, df.to_csv(index=False).encode(), flag)
    from harness.provenance import FIELDS, describe

    print(
        df.drop(columns=[c for c in FIELDS if c in df.columns and c in columns(started)]).to_string(
            index=False
        )
    )
    print(f"code and machine: {describe(started)}")
    print(f"-> {path}")
    return 0
