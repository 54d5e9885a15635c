"""springbench bench engines: how far is each engine's deformable body from linear elasticity?

The engines suite (cases/engines/, harness/stages/engines.py) as one benchmark CSV: four
gmsh bodies (a box beam 0.5 x 0.1 x 0.1 m, a round bar, the elbow, a 120-degree torus sector, and
the
tapered bar bolted through its hole) at two resolutions, E = 1e5 Pa, density 1000 kg/m^3,
nu = 0.3, 0.45 and 0.49; per case ``springbench pack`` and, on its held-out loads (sag,
tip, tip2, torsion, bridge; peak strain about 1e-3), ``newton-tets`` and ``mujoco-flex``
(the engines' own models from E and nu) and ``newton-springs`` running springbench's
exports of the same mesh (the best stiffness rule; the calibrated model, ``--budget``
BUDGET s), every answer scored against the pack's FEM. Quick: the coarse beam at nu 0.3,
calibrate's budget 5 s.

Rows as the suite's, with the engine's settled / not-settled / diverged / not-installed /
failed in ``status``: one per (body, n_tets, nu, engine, model, load) with G_norm,
max_error, G_ref, steps and wall seconds to equilibrium, and a ``mean`` row per (body,
n_tets, nu, engine, model).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import pandas as pd

from harness.case.reader import load_case
from harness.paths import DEFAULT_CASES
from harness.progress import steps
from harness.stages.engines import COLUMNS as STAGE_COLUMNS
from harness.stages.engines import case_rows

SUITE = DEFAULT_CASES / "engines"
QUICK_CASE, QUICK_BUDGET = "beam-coarse_nu0.30.toml", 5.0
COLUMNS = [c if c != "engine_status" else "status" for c in STAGE_COLUMNS]


def run(quick: bool = False) -> pd.DataFrame:
    files = [SUITE / QUICK_CASE] if quick else sorted(SUITE.glob("[!_]*.toml"))
    frames = []
    for path in steps(files, "bench engines", "case"):
        case = load_case(path, "full")
        spec = dict(case.section("model"), budget=QUICK_BUDGET) if quick else None
        with tempfile.TemporaryDirectory(prefix="springbench-engines-") as tmp:
            frames.append(case_rows(case, Path(tmp), spec))
    df = (
        pd.concat(frames, ignore_index=True)
        .rename(columns={"engine_status": "status"})
        .reindex(columns=COLUMNS)
    )
    print(
        df[df.load == "mean"][
            ["body", "n_tets", "nu", "engine", "model", "G_norm", "status"]
        ].to_string(index=False, float_format=lambda v: f"{v:.3g}")
    )
    return df
