"""Model class "mt": Bourguignon & Cani's element model (harness/models/mt.py) on the
model's cells, its three constants theta (axial, angular, volume; Pa) fitted on the case's
fitted loads by the B&C suite's own least squares in log theta
(harness/stages/bc2000_linear.fit: scipy trf, finite-difference Jacobian), because its
linearised stiffness is not symmetric and the optimisers of harness/optimize assume
K = B diag(k) B^T. The case's [optimizer] runs with the G objective become this one fit
(``optimizer`` = "least-squares"); frequency-objective runs have no MT counterpart. A 2-D
case gets one row with status "skip" and the reason in ``note`` (B&C define no 2-D
element)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from harness.errors import naming
from harness.mechanics import statics
from harness.models.mt import PARAMS, unsupported, with_mt
from harness.models.sms import build_network
from harness.scoring import node_weights
from harness.stages.classes.base import ModelClass

METHOD = "least-squares"
BUDGET = "max_nfev=200"  # bc2000_linear.fit's budget


def skip_row(case, label: str) -> dict | None:
    """The row of a case the class has no model for (2-D), or None."""
    why = unsupported(case.dim)
    if why is None:
        return None
    return {
        "case": case.name,
        "model": label,
        "model_class": "mt",
        "nu": float(case.material.nu),
        "dim": case.dim,
        "stiffness": "mt",
        "optimizer": "none",
        "status": "skip",
        "note": why,
    }


def runs(case_runs: list) -> list:
    """The class's fit runs: one least-squares fit if the case fits G at all."""
    if not any(r["objective"] == "G" for r in case_runs):
        return []
    return [dict(method=METHOD, options={}, objective="G", where="optimizer.method")]


def fit_theta(base, case, u_ref, names, fit, weights):
    """theta fitted on the loads ``fit`` (indices of ``names``) and the fit's G before/after."""
    from harness.stages import bc2000_linear as linear

    _, free, forces = statics.all_load_arrays(base, case)
    loads = linear.Loads([names[i] for i in fit], free[fit], forces[fit])
    term = base.volume
    return linear.fit(
        list(term.units), term.kv, u_ref[fit], loads, node_weights(base.classes, weights)
    )


def optimise(setting, run_, base, first):
    """The fitted row, its network and no trace (``setting``: the class's
    :class:`harness.stages.classes.base.Setting`)."""
    s = setting
    s.ctx.status(f"mt: fitting {', '.join(PARAMS)} ({METHOD})")
    t0 = time.perf_counter()
    theta, g0, g1 = fit_theta(base, s.case, s.u_ref, s.names, s.fit, s.weights)
    seconds = time.perf_counter() - t0
    net = base.with_k(np.concatenate([base.k, theta]), stiffness=f"mt+{METHOD}")
    res, sc, sh = s.evaluate(net)
    tag = f"mt-{METHOD}"
    s.write(net, res, tag)
    columns = s.fit_columns(
        first,
        "mt",
        METHOD,
        sc,
        grouped=False,
        seconds=seconds,
        G_final_optimizer=g1,
        objective="G",
        budget=BUDGET,
        n_params=len(theta),
    )
    row = {**columns.row(s.common), "_tag": tag}
    row.update({f"G_{k}": v for k, v in sc.per_load.items()})
    if sh is not None:
        row.update(
            {f"G_{k}": v for k, v in sh.per_load.items()},
            G_heldout=sh.G_norm,
            G_heldout_initial=first.get("G_heldout", math.nan),
        )
    row.update({f"mt_{k}": float(v) for k, v in zip(PARAMS, theta)})
    return row, net, None


def constants(net) -> dict:
    """Columns of a row: theta (mt_axial, mt_angular, mt_volume, Pa)."""
    return {f"mt_{k}": float(v) for k, v in zip(PARAMS, net.volume.kv)}


def save(path, net) -> None:
    """The model as .npz: theta, cells, the per-element constants (ks1..ks6, kvs) and the
    axes (faces' node ids and weights), enough to rebuild the nonlinear model."""
    m = net.volume.model()
    np.savez(
        path,
        theta=net.volume.kv,
        params=np.array(PARAMS),
        cells=m.cells,
        ks=m.ks,
        kvs=m.kvs,
        L0=m.L0,
        cos0=m.cos0,
        D0=m.D0,
        axis_nodes=m.axes.nodes,
        axis_weights=m.axes.weights,
    )


@dataclass(frozen=True)
class MTClass(ModelClass):
    building: str = "building the MT model"

    def skip(self, case, label: str) -> dict | None:
        return skip_row(case, label)

    def build(self, case, spec: dict, seed: int = 0):
        net = build_network(case, spec, seed=seed)
        with naming(case):
            return with_mt(net, case.material)

    def fit_runs(self, runs_: list[dict]) -> list[dict]:
        return runs(runs_)

    def fit(self, setting, run: dict, start, first: dict):
        return optimise(setting, run, start, first)

    def columns(self, case, spec: dict, net) -> dict:
        # B&C's elements (the springs: connectivity)
        return {"n_elements": len(net.volume.body.cells)}

    def constants(self, net) -> dict:
        return constants(net)

    def save(self, ctx, net, res, tag: str) -> None:
        save(ctx.file(f"mt-{tag}.npz"), net)


MT = MTClass("mt")
