"""The fit of a springs network in the sms stage (harness/stages/sms.py): one optimiser
run of the case on the fitted loads, re-scored by a statics solve, as a table row."""

from __future__ import annotations

import math
import time

import numpy as np
import pandas as pd

from harness.case.loads import modal_load
from harness.errors import ModelError, SpringbenchError
from harness.mechanics import statics
from harness.optimize.diagnostics import fit_diagnostics
from harness.optimize.problem import FitProblem
from harness.scoring import node_weights
from harness.stages import sms_measures as measures
from harness.stages.classes.base import Setting

BUDGET_KEYS = (
    "temperatures",
    "max_steps",
    "max_seconds",
    "maxiter",
    "maxfun",
    "target",
    "tol",
    "ftol",
    "gtol",
    "xatol",
    "fatol",
    "cg_maxiter",
    "chains",
)


def case_file(case) -> str | None:
    """The case file, for error messages (None for an in-memory case)."""
    return str(case.path) if case.path is not None else None


def budget_label(options: dict) -> str:
    """The options that bound an optimiser's effort, as 'key=value, ...' ('default' if none)."""
    parts = [f"{k}={options[k]}" for k in BUDGET_KEYS if options.get(k) is not None]
    return ", ".join(parts) or "default"


def optimise(setting: Setting, run_: dict, base, first: dict):
    """One optimiser run of a springs network on the fitted loads and its row."""
    method, objective = run_["method"], run_["objective"]
    stiff = base.info["stiffness"]
    tag = f"{stiff}-{method}" + ("-freq" if objective != "G" else "")
    freq_kw = frequency_terms(setting, run_, base) if objective != "G" else {}
    problem = fit_problem(setting, base, freq_kw)
    t0 = time.perf_counter()
    setting.ctx.status(f"optimising ({method}{', frequencies' if freq_kw else ''})")
    seed = int(base.info["seed"])
    res = _optimised(setting, run_, problem, seed)
    seconds = time.perf_counter() - t0
    name = f"{stiff}+{method}" + ("+freq" if freq_kw else "")
    net = base.with_k(res.k, stiffness=name)
    sres, sc, sh = setting.evaluate(net)
    setting.write(net, sres, tag)
    columns = setting.fit_columns(
        first,
        stiff,
        method,
        sc,
        grouped=bool(setting.spec["grouped"]),
        seconds=seconds,
        G_final_optimizer=float(getattr(res, "G_final", math.nan)),
        objective=objective,
        budget=budget_label(run_["options"]),
        n_params=problem.n_params,
    )
    row = columns.row(setting.common, scored=measures.scored_columns(setting.case, sc, sh, first))
    row["_tag"] = tag
    if freq_kw:
        row.update(freq_modes=run_["modes"], freq_weight=run_["weight"])
    row.update(optimiser_columns(res, seed))
    row.update(fit_diagnostics(problem, np.asarray(res.k, float)))
    return row, net, trace_frame(getattr(res, "trace", None), name)


def frequency_terms(setting: Setting, run_: dict, base) -> dict:
    """FitProblem's keywords of the frequency term (Deussen Section 8): the masses, the
    FEM's first ``modes`` frequencies as the target, the term's weight and the dofs free
    under the modal load's constraints."""
    case, fem_f = setting.case, setting.fem_f
    file = case_file(case)
    if fem_f is None or len(fem_f) < run_["modes"]:
        raise SpringbenchError(
            "the frequency term needs the reference's natural frequencies",
            file=file,
            field="optimizer.frequency",
            fix="use a reference with modes, or remove [optimizer.frequency]",
        )
    if np.any(base.masses <= 0):
        raise ModelError(
            f"{int(np.sum(base.masses <= 0))} nodes have masses <= 0: no natural frequencies",
            file=file,
            field="optimizer.frequency",
            fix="use [model] masses = 'moments-nonneg', 'voronoi' or 'uniform'",
        )
    modal_free = ~statics.fixed_mask(base.points, case, modal_load(case)).ravel()
    return dict(
        masses=base.masses,
        freq_target=np.asarray(fem_f[: run_["modes"]], float),
        freq_weight=run_["weight"],
        modal_free=modal_free,
    )


def fit_problem(setting: Setting, base, freq_kw: dict) -> FitProblem:
    """The fit of ``base``'s constants on the fitted loads: ks alone, or [ks, kv] with the
    volume or kn term's columns beside B; ``freq_kw``: the frequency term, if any."""
    fit, spec = setting.fit, setting.spec
    _, free, forces = statics.all_load_arrays(base, setting.case)
    names = [setting.names[i] for i in fit]
    u_fit = setting.u_ref[fit]
    wdof = np.repeat(node_weights(base.classes, setting.weights), base.dim)
    k0, groups, extra = base.k, base.groups if spec["grouped"] else None, None
    if getattr(base, "volume", None) is not None:
        k0, groups, extra = (
            base.params(),
            base.param_groups(spec["grouped"]),
            base.volume.columns(base.points),
        )
    return FitProblem.from_network(
        base.points,
        base.springs,
        k0,
        free[fit],
        forces[fit],
        u_fit.reshape(len(names), -1),
        wdof,
        list(names),
        groups=groups,
        extra_columns=extra,
        **freq_kw,
    )


def _optimised(setting: Setting, run_: dict, problem: FitProblem, seed: int):
    """The optimiser's result; its errors name the case file and the field the method and
    options came from (compare_options, frequency)."""
    try:
        return setting.optimize(
            problem,
            run_["method"],
            dict(run_["options"]),
            seed,
            status=setting.ctx.status,
        )
    except SpringbenchError as exc:
        if exc.file is not None:
            raise
        field = exc.field or "optimizer"
        if field.startswith("optimizer.options"):
            field = run_["where"] + field[len("optimizer.options") :]
        # the method came from there
        elif field == "optimizer.method" and run_["where"] != "optimizer.options":
            field = (
                "optimizer.frequency.method" if run_["objective"] != "G" else "optimizer.compare"
            )
        raise type(exc)(
            exc.message, file=case_file(setting.case), field=field, fix=exc.fix
        ) from None


def optimiser_columns(res, seed: int) -> dict:
    """The opt_* columns: what the optimiser reports of its run (steps, stop, start,
    prior, evaluations, iterations, linear solves) and its random stream's seed."""
    info = dict(getattr(res, "info", {}) or {})
    out = {}
    for key in ("n_steps", "accepted"):
        if hasattr(res, key):
            out[f"opt_{key}"] = getattr(res, key)
    out["opt_seed"] = seed  # the optimiser's random stream (SA); = model_seed
    if "stop" in info:
        out["opt_stop"] = str(info["stop"])
    if info.get("init", "none") != "none":
        out["opt_init"] = str(info["init"]) + (
            " (rejected: worse than k0)" if info.get("init_rejected") else ""
        )
    # lbfgs / nelder-mead: the weight of the pull towards the start (gradient.py)
    if "prior" in info:
        out["opt_prior"] = float(info["prior"])
    out["opt_evaluations"] = int(info.get("evaluations", getattr(res, "n_steps", 0)))
    if "iterations" in info:
        out["opt_iterations"] = int(info["iterations"])
    if "solves" in info:  # gauss-newton: linear solves (one evaluation of G is one per load set)
        out["opt_solves"] = int(info["solves"])
    return out


def trace_frame(trace, name):
    """An optimiser's trace ((step, G) rows, a G column or a DataFrame) as trace.csv rows
    with ``model`` = name; None if there is none. A trace that is none of these (ragged, not
    numbers) is the optimiser's bug: numpy's error says so."""
    if trace is None or not len(trace):
        return None
    if isinstance(trace, pd.DataFrame):
        df = trace.copy()
    else:
        arr = np.asarray(trace, float)
        arr = arr[:, None] if arr.ndim == 1 else arr
        df = pd.DataFrame(arr, columns=["step", "G"] if arr.shape[1] == 2 else None)
    if "G" not in df.columns and df.shape[1] == 1:
        df.columns = ["G"]
    if "step" not in df.columns:
        df.insert(0, "step", np.arange(len(df)))
    df["model"] = name
    return df
