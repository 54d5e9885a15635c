"""Benchmarks: modules with ``run(quick: bool) -> pandas.DataFrame``, registered by name in
``harness.registry.BENCHES``.

Each reports speeds as ratios against a baseline measured in the same process; the
CSV goes to runs/bench/<name>.csv (``--results results``: the published
results/bench/). A new benchmark is one module and its name in the registry.
"""
