"""springbench bench sa: simulated-annealing steps per second, the paper's way (every
proposal re-factorises K for each load set) against incremental rank-1 G, same process.

Both engines run the same seeded chain (same proposals, same accept/reject decisions),
so the rate includes accepted steps at the acceptance rate of a real run (the paper's
defaults: T0 = 1e-3 relative, r = 0.98, nlimit = 2e, glimit = e) and every proposal
pays for the full solve of every load case (4 in 2-D, 9 in 3-D). Networks: regular grids
with diagonals (harness.optimize.synthetic), recoverable reference. ``e_squared_hours``
says how long the paper's e^2 proposals would take at the measured rate and
``e_squared_out_of_reach`` flags more than a day: from a few thousand springs on, even
the incremental engine cannot run the paper's budget, so SA is budgeted by steps or time.
Both engines run with one BLAS thread (the second core is for a second chain).
The two engines alternate ``repeats`` times on the same network and the table reports each
engine's median rate (and the spread): on a shared 2-core machine single timings of the
same run vary by 10-20 %, and alternating spreads slow phases over both engines.
"""

from __future__ import annotations

import time

import numpy as np
import pandas as pd

from harness.optimize import optimize
from harness.optimize.synthetic import recoverable_problem
from harness.progress import steps

# (grid shape, incremental budget, refactor budget): a float is wall seconds of the SA
# loop after setup, an int a number of proposals. The incremental budgets are proposal
# counts that span several renewals of the base (the auto interval is 64-350 accepts), so
# the rate includes the refactorisations amortised, but stay early enough in the chain
# that the acceptance rate matches the baseline's (a long cold run accepts less and
# looks faster); the 3-D 8000-node baseline needs ~6 s per proposal, so it gets a handful.
# Last entry: repeats (alternating incremental / baseline runs, medians reported).
FULL = [
    ((5, 5), 10.0, 10.0, 1),
    ((20, 20), 10.0, 10.0, 1),
    ((50, 50), 5000, 20.0, 3),
    ((100, 100), 3000, 30.0, 3),
    ((5, 5, 5), 6000, 10.0, 1),
    ((10, 10, 10), 3000, 20.0, 3),
    ((20, 20, 20), 1500, 3, 1),
]
QUICK = [
    ((5, 5), 3.0, 3.0, 1),
    ((20, 20), 3.0, 3.0, 1),
    ((30, 30), 1500, 3.0, 2),
    ((5, 5, 5), 3000, 3.0, 1),
]


def _budget(b, setup_guess: float) -> dict:
    return {"max_steps": b} if isinstance(b, int) else {"max_seconds": b + setup_guess}


def run(quick: bool = False) -> pd.DataFrame:
    rows = []
    for shape, inc_seconds, base_budget, repeats in steps(
        QUICK if quick else FULL, "bench sa", "network"
    ):
        t = time.perf_counter()
        prob, _ = recoverable_problem(shape, sigma=0.3, seed=0, diagonals="face")
        build = time.perf_counter() - t
        n_nodes = int(np.prod(shape))
        common = dict(
            dim=len(shape),
            n_nodes=n_nodes,
            n_springs=prob.n_springs,
            n_dofs=sum(b.B.shape[0] for b in prob.blocks) // len(prob.blocks),
            n_loads=len(prob.blocks),
            n_load_sets=len(prob.load_sets()),
        )
        # max_seconds counts from the start (setup included): add a measured setup time
        t = time.perf_counter()
        prob.G(prob.k0)
        setup_guess = 3 * (time.perf_counter() - t)
        runs: dict = {"incremental": [], "refactor": []}
        for _ in range(repeats):
            runs["incremental"].append(
                optimize(prob, "sa", _budget(inc_seconds, setup_guess), seed=0)
            )
            runs["refactor"].append(
                optimize(prob, "sa-refactor", _budget(base_budget, setup_guess), seed=0)
            )
        for method in ("refactor", "incremental"):
            rates = [r.info["steps_per_s"] for r in runs[method]]
            res = runs[method][int(np.argsort(rates)[len(rates) // 2])]  # the median run
            rows.append(
                dict(
                    **common,
                    method=method,
                    engine=res.info["engine"],
                    steps=res.n_steps,
                    seconds=round(res.info["loop_seconds"], 3),
                    steps_per_s=res.info["steps_per_s"],
                    acceptance=res.info["acceptance"],
                    repeats=repeats,
                    steps_per_s_min=min(rates),
                    steps_per_s_max=max(rates),
                    setup_seconds=round(res.info["setup_seconds"], 3),
                    G_ratio=res.G_final / res.G_initial,
                    e_squared_hours=res.info["e_squared_hours"],
                    build_seconds=round(build, 2),
                    e_squared_out_of_reach=bool(res.info["e_squared_hours"] > 24.0),
                    rebases=res.info["rebases"],
                    refactor_every=res.info["refactor_every"],
                )
            )
        rows[-1]["speedup"] = rows[-1]["steps_per_s"] / rows[-2]["steps_per_s"]
        rows[-2]["speedup"] = 1.0
        print(
            f"  sa bench {shape}: refactor {rows[-2]['steps_per_s']:.3g}/s, incremental "
            f"{rows[-1]['steps_per_s']:.3g}/s ({rows[-1]['engine']}), x{rows[-1]['speedup']:.1f}",
            flush=True,
        )
    df = pd.DataFrame(rows)
    return df
