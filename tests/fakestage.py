"""A fake stage for the runner tests: behaviour is driven by the case's ``description``,
tokens ``key=value``: rows=N, sleep=S, fail=case|bug, files=1. Every call appends a line
to ``calls.log`` next to the case file. ``FAKE`` is its module name (what a registry
entry or a worker imports), ``write_case`` writes a case file for it, ``calls`` reads
the log; the ``fake`` fixture (tests/conftest.py) puts it in place of the real stages."""

from __future__ import annotations

import json
import time
from pathlib import Path

from harness.errors import CaseError
from tests.plate_case import plate_case

NAME = "fake"
FAKE = "tests.fakestage"


def write_case(
    folder: Path, name: str, desc: str = "", extra: str = "", tags=(), file=None
) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    p = folder / (file or f"{name}.toml")
    p.write_text(
        plate_case(
            name, top=f'description = "{desc}"\ntags = {json.dumps(list(tags))}', loads=extra
        )
    )
    return p


def calls(folder: Path) -> list[str]:
    f = folder / "calls.log"
    return f.read_text().split("\n")[:-1] if f.exists() else []


def applies(case):
    return "skip" not in case.tags


def _opts(case):
    return dict(t.split("=", 1) for t in case.description.split() if "=" in t)


def run(case, ctx):
    o = _opts(case)
    with open(case.path.parent / "calls.log", "a") as fh:
        fh.write(f"{case.name} {ctx.seed}\n")
    for i in range(int(float(o.get("sleep", 0)) * 10)):
        ctx.status(f"sleeping {i}")
        time.sleep(0.1)
    if o.get("fail") == "case":
        raise CaseError(
            "E must be positive", file=str(case.path), field="material.E", fix="give E > 0"
        )
    if o.get("die") and ctx.seed == 0:
        import multiprocessing

        if multiprocessing.parent_process() is not None:  # only ever kill a worker process
            import os

            os._exit(3)
        raise RuntimeError("die=1 outside a worker process")
    if o.get("fail") == "bug":
        return [{"model": "x", "G": 1 / 0}]
    rng = ctx.rng()
    rows = []
    for m in range(int(o.get("rows", 1))):
        g0 = float(rng.uniform(1, 3))
        rows.append(
            {
                "model": f"m{m}",
                "n_nodes": 25,
                "n_springs": 72,
                "optimizer": "sa",
                "weights": (1, 3, 15),
                "G_initial": g0,
                "G_final": g0 * float(rng.uniform(0.1, 0.5)),
                "lloyd_iterations": m,
                "wall_seconds": time.perf_counter(),
                "mode": ctx.mode,
            }
        )
    if o.get("files"):
        import numpy as np
        import pandas as pd

        pd.DataFrame({"step": range(20), "G": np.linspace(2, 0.5, 20), "model": "m0"}).to_csv(
            ctx.file("trace.csv"), index=False
        )
        t = np.linspace(0, 1, 11)
        pd.DataFrame({"t": t, "MS": -3 * t, "MT0": -t, "MT": 0.1 * t}).to_csv(
            ctx.file("volume.csv"), index=False
        )
        pd.DataFrame({"mode": [1, 2, 3], "fem": [1.0, 2.0, 3.5], "sms": [1.1, 2.2, 3.0]}).to_csv(
            ctx.file("frequencies.csv"), index=False
        )
        ang = np.arange(0, 360, 30)
        pd.DataFrame(
            {
                "angle": np.r_[ang, ang],
                "model": ["MS"] * 12 + ["MT"] * 12,
                "stiffness": np.r_[1 + 0.3 * np.cos(np.deg2rad(4 * ang)), np.ones(12)],
            }
        ).to_csv(ctx.file("anisotropy.csv"), index=False)
        pd.DataFrame(
            {
                "iteration": range(5),
                "std_distance": [1, 0.5, 0.3, 0.2, 0.1],
                "std_area": [2, 1, 0.5, 0.3, 0.2],
            }
        ).to_csv(ctx.file("lloyd.csv"), index=False)
        x, y = np.meshgrid(np.linspace(0, 1, 3), np.linspace(0, 1, 3))
        p = np.c_[x.ravel(), y.ravel()]
        springs = np.array(
            [
                [0, 1],
                [1, 2],
                [3, 4],
                [4, 5],
                [6, 7],
                [7, 8],
                [0, 3],
                [3, 6],
                [1, 4],
                [4, 7],
                [2, 5],
                [5, 8],
            ]
        )
        np.savez(
            ctx.file("deformed.npz"),
            points=p,
            springs=springs,
            u_ref_stretch=0.01 * p,
            u_stretch=0.011 * p,
        )
        c = np.random.default_rng(0).random((10, 3))
        np.savez(ctx.file("fibres.npz"), points=c, directions=np.tile([0, 0, 1.0], (10, 1)))
    return rows
