"""Stage "sms": build the case's spring/mass system, score every stiffness rule as an
unoptimised baseline row, and, when ``harness.optimize.optimize`` exists and
[optimizer] method != "none", optimise the first rule's constants and score that.

Files (in ctx.out_dir, formats of harness/report.py): ``model-<rule>.vtu`` (the network
with its displacements), ``deformed-<label>.npz`` (reference vs model), ``lloyd.csv``
(Lloyd statistics), ``frequencies.csv`` (SMS vs FEM natural frequencies), and the
optimiser's ``trace.csv``.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pandas as pd

from harness.errors import ModelError, SpringbenchError

NAME = "sms"


def applies(case) -> bool:
    sec = case.section("model")
    return sec is not None and sec.get("kind") == "sms"


def _reference(case, ctx):
    try:
        import reference
    except ImportError:
        return None, "reference package not available"
    try:
        return reference.solve(case, status=ctx.status), ""
    except TypeError:
        return reference.solve(case), ""
    except SpringbenchError:
        raise
    except NotImplementedError as exc:
        return None, f"reference: {exc}"


def _optimizer():
    try:
        from harness.optimize import optimize
    except ImportError:
        return None
    return optimize


def _expect(case) -> dict:
    sec = case.section("expect") or {}
    vals = dict(sec.get("values") or {})
    return {"paper_G_initial": vals.get("G_initial", math.nan), "paper_G_final": vals.get("G_final", math.nan)}


def model_label(spec, case) -> str:
    p = spec["placement"]
    if p == "grid":
        structure = spec["structure"] or ("structure1" if case.dim == 2 else "edges+face+body")
        return f"sms-grid{'x'.join(map(str, spec['grid']))}-{structure}"
    if p == "lloyd":
        return f"sms-lloyd{spec['lloyd_iterations']}-n{spec['n_points']}"
    if p == "random":
        return f"sms-random-n{spec['n_points']}"
    return "sms-mesh"


def run(case, ctx) -> list[dict]:
    from harness import statics
    from harness.homogenize import case_report
    from harness.models.sms import build_network, model_spec
    from harness.models.stiffness_rules import spring_constants
    from harness.scoring import case_weights, g_arrays, reference_displacements

    spec = model_spec(case)
    weights = case_weights(case)
    wlabel = ":".join(f"{w:g}" for w in weights)
    label = model_label(spec, case)
    t0 = time.perf_counter()
    ctx.status("building the spring/mass system")
    base = build_network(case, spec, seed=ctx.seed)
    build_seconds = time.perf_counter() - t0
    ctx.status("reference solve")
    ref, why = _reference(case, ctx)
    names = tuple(l.name for l in case.loads)
    u_ref = reference_displacements(ref, base.points, names) if ref is not None else None
    common = {"case": case.name, "n_nodes": base.n_nodes, "n_springs": base.n_springs, "weights": wlabel,
              "seed": ctx.seed, "model_seed": base.info["seed"], "masses": spec["masses"], "mass_residual": base.info["mass_residual"],
              "negative_masses": base.info["negative_masses"], **_expect(case)}
    if spec["placement"] == "lloyd":
        common["lloyd_iterations"] = spec["lloyd_iterations"]
    cauchy = case_report(case, spec)
    if cauchy is not None:
        common.update(cauchy_misfit=cauchy["misfit"], cauchy_reachable=bool(cauchy["reachable"]),
                      cauchy_nu=cauchy["cauchy_nu"])
    if "lloyd_std_distance" in base.info:
        pd.DataFrame({"iteration": np.arange(len(base.info["lloyd_std_distance"])),
                      "std_distance": base.info["lloyd_std_distance"],
                      "std_area": base.info["lloyd_std_size"]}).to_csv(ctx.file("lloyd.csv"), index=False)

    def evaluate(net):
        res = statics.solve(net, case)
        sc = g_arrays(u_ref, res.u, net.classes, weights, res.names) if u_ref is not None else None
        return res, sc

    def write(net, res, tag):
        from harness.io_vtu import write_vtu
        write_vtu(ctx.file(f"model-{tag}.vtu"), net, dict(zip(res.names, res.u)))
        if u_ref is not None:
            arrays = {"points": net.points, "springs": net.springs}
            for i, n in enumerate(res.names):
                arrays[f"u_ref_{n}"] = u_ref[i]
                arrays[f"u_{n}"] = res.u[i]
            np.savez(ctx.file(f"deformed-{tag}.npz"), **arrays)

    rows, nets = [], {}
    for rule in spec["stiffness"]:
        t1 = time.perf_counter()
        net = base if rule == base.info["stiffness"] else base.with_k(
            spring_constants(rule, base.points, base.springs, base.cells, case.material), stiffness=rule)
        nets[rule] = net
        res, sc = evaluate(net)
        write(net, res, rule)
        row = {**common, "model": f"{label}[{rule}]", "stiffness": rule, "optimizer": "none",
               "seconds": build_seconds + time.perf_counter() - t1}
        if sc is not None:
            row.update(G_initial=sc.G, G_final=sc.G, G_norm_initial=sc.G_norm, G_norm_final=sc.G_norm,
                       G_s_initial=sc.G_s, G_s_final=sc.G_s, **{f"G_{k}": v for k, v in sc.per_load.items()})
        else:
            row.update(G_initial=math.nan, G_final=math.nan, G_norm_initial=math.nan, G_norm_final=math.nan,
                       note=f"no reference ({why})")
        rows.append(row)

    ratios = _frequencies(case, ctx, ref, nets, spec)
    for row in rows:
        if row["stiffness"] in ratios:
            row["f1_ratio"] = ratios[row["stiffness"]]

    opt = case.section("optimizer") or {}
    method = opt.get("method", "none")
    optimize = _optimizer()
    if method != "none" and optimize is not None and u_ref is not None:
        rows.append(_optimise(case, ctx, optimize, opt, base, u_ref, names, weights, spec, label, common,
                              rows[0], evaluate, write))
    elif method != "none":
        rows[0]["note"] = rows[0].get("note", "") or ("optimiser not available" if optimize is None else "")
    return rows


def _optimise(case, ctx, optimize, opt, base, u_ref, names, weights, spec, label, common, first, evaluate, write):
    from harness import statics
    from harness.optimize.problem import FitProblem
    from harness.scoring import node_weights
    _, free, forces = statics.all_load_arrays(base, case)
    wdof = np.repeat(node_weights(base.classes, weights), base.dim)
    problem = FitProblem.from_network(base.points, base.springs, base.k, free, forces,
                                      u_ref.reshape(len(names), -1), wdof, list(names),
                                      groups=base.groups if spec["grouped"] else None)
    t0 = time.perf_counter()
    ctx.status(f"optimising ({opt['method']})")
    res = optimize(problem, opt["method"], dict(opt.get("options") or {}), int(base.info["seed"]), status=ctx.status)
    seconds = time.perf_counter() - t0
    net = base.with_k(res.k, stiffness=f"{base.info['stiffness']}+{opt['method']}")
    sres, sc = evaluate(net)
    write(net, sres, f"{base.info['stiffness']}-{opt['method']}")
    trace = getattr(res, "trace", None)
    if trace is not None and len(trace):
        try:
            if isinstance(trace, pd.DataFrame):
                df = trace
            else:
                arr = np.asarray(trace, float)
                arr = arr[:, None] if arr.ndim == 1 else arr
                df = pd.DataFrame(arr, columns=["step", "G"] if arr.shape[1] == 2 else None)
            if "G" not in df.columns and df.shape[1] == 1:
                df.columns = ["G"]
            if "step" not in df.columns:
                df.insert(0, "step", np.arange(len(df)))
            df["model"] = f"{base.info['stiffness']}+{opt['method']}"
            df.to_csv(ctx.file("trace.csv"), index=False)
        except (ValueError, TypeError):
            pass
    row = {**common, "model": f"{label}[{base.info['stiffness']}]", "stiffness": base.info["stiffness"],
           "optimizer": opt["method"], "grouped": bool(spec["grouped"]), "seconds": seconds,
           "G_initial": first["G_initial"], "G_norm_initial": first["G_norm_initial"],
           "G_s_initial": first.get("G_s_initial", math.nan),
           "G_final": sc.G, "G_norm_final": sc.G_norm, "G_s_final": sc.G_s,
           "G_final_optimizer": float(getattr(res, "G_final", math.nan)),
           **{f"G_{k}": v for k, v in sc.per_load.items()}}
    for key in ("n_steps", "accepted"):
        if hasattr(res, key):
            row[f"opt_{key}"] = getattr(res, key)
    return row


def _frequencies(case, ctx, ref, nets, spec):
    """frequencies.csv: the first few SMS frequencies per rule next to the FEM ones;
    returns {rule: first SMS frequency / first FEM frequency}."""
    n = int(case.reference.modes or 0)
    if n <= 0:
        return {}
    from harness.modal_sms import frequencies
    cols = {"mode": np.arange(1, n + 1)}
    if ref is not None:
        try:
            f = np.asarray(ref.frequencies(n), float)
            cols["fem"] = np.pad(f, (0, n - len(f)), constant_values=np.nan)[:n]
        except Exception:  # noqa: BLE001 - the reference's modal solve is optional here
            pass
    for rule, net in nets.items():
        try:
            f = frequencies(net, case, n)
            cols[rule] = np.pad(f, (0, n - len(f)), constant_values=np.nan)[:n]
        except ModelError:
            continue
    if len(cols) > 1:
        pd.DataFrame(cols).to_csv(ctx.file("frequencies.csv"), index=False)
    if "fem" not in cols or not cols["fem"][0] > 0:
        return {}
    return {r: float(cols[r][0] / cols["fem"][0]) for r in nets if r in cols}
