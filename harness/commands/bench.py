"""springbench bench NAME: benchmarks registered in harness.bench.BENCHES."""

from __future__ import annotations

import importlib
from pathlib import Path

from harness.errors import SpringbenchError

HELP = "run a benchmark (reference, sa, fit, dynamics, ...) and write results/bench/NAME.csv"


def add_arguments(p):
    from harness.bench import BENCHES
    p.add_argument("name", choices=sorted(BENCHES), help="which benchmark")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: results/bench)")
    p.add_argument("--quick", action="store_true", help="smaller sizes, for a smoke test")


def main(args) -> int:
    from harness.bench import BENCHES
    from harness.runner import DEFAULT_RESULTS
    out = args.out or DEFAULT_RESULTS / "bench"
    out.mkdir(parents=True, exist_ok=True)
    mod = importlib.import_module(BENCHES[args.name])
    df = mod.run(quick=args.quick)
    path = out / f"{args.name}.csv"
    df.to_csv(path, index=False)
    print(df.to_string(index=False))
    print(f"-> {path}")
    return 0
