"""springbench bench NAME: benchmarks registered in harness.bench.BENCHES."""

from __future__ import annotations

import importlib
from pathlib import Path


HELP = "run a benchmark (reference, sa, fit, dynamics, ...) and write results/bench/NAME.csv"


def add_arguments(p):
    from harness.bench import BENCHES
    p.add_argument("name", choices=sorted(BENCHES), help="which benchmark")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: results/bench)")
    p.add_argument("--quick", action="store_true", help="smaller sizes, for a smoke test")


def main(args) -> int:
    from harness.bench import BENCHES
    from harness.paths import DEFAULT_RESULTS
    from harness.outputs import atomic_write, check_out_dir, check_out_file
    out = args.out or DEFAULT_RESULTS / "bench"
    path = out / f"{args.name}.csv"
    check_out_dir(out, "--out" if args.out else None)      # before a bench that takes minutes
    check_out_file(path, "--out" if args.out else None)
    mod = importlib.import_module(BENCHES[args.name])
    df = mod.run(quick=args.quick)
    atomic_write(path, df.to_csv(index=False).encode(), "--out" if args.out else None)
    print(df.to_string(index=False))
    print(f"-> {path}")
    return 0
