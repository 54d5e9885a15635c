"""Benchmarks: name -> module with ``run(quick: bool) -> pandas.DataFrame``.

Each reports speeds as ratios against a baseline measured in the same process; the
CSV goes to runs/bench/<name>.csv (``--results results``: the published
results/bench/). A new benchmark is one module added here.
"""

BENCHES = {
    "reference": "harness.bench.reference",
    "sa": "harness.bench.sa",
    "fit": "harness.bench.fit",
    "dynamics": "harness.bench.dynamics",
    "calibrate": "harness.bench.calibrate",
    "heldout": "harness.bench.heldout",
    "engines": "harness.bench.engines",
}
