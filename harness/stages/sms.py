"""Stage "sms": build the case's spring/mass system, score every stiffness rule as an
unoptimised baseline row, then optimise the first rule's constants with each optimiser
run of the case (see optimiser_runs: [optimizer] method, each of ``compare``, and the
``[optimizer.frequency]`` row that adds the natural frequencies to G, Deussen Section 8)
and score each result: one row per run, all from the same initial model, reference and
weights, so the table compares optimisers and not set-ups. With ``[optimizer.select]`` the
springs' fit chooses its capacity by validation (harness/stages/sms_select.py). Every scored row carries
``G_ref`` (the reference's own estimated error as a normalised G at the same nodes, loads
and weights), ``ref_error_max`` and ``ref_met_tol``; its ``status`` is "ref-coarse" when
G_ref exceeds 10 % of its ``G_norm_final`` or the reference missed its tol
(harness.scoring.ref_status). Loads the case holds out (``[loads] heldout``) are never
fitted: G_* and G_ref are on the fitted loads, ``G_heldout`` (normalised, the same weights),
``G_heldout_mean`` (the mean of the loads' own normalised G), ``G_heldout_<load>``,
``G_ref_heldout`` and ``ref_error_heldout`` on the held-out ones, ``freq_error_heldout`` on
the natural frequencies no fit used.

Files (in ctx.out_dir, formats of harness/report/build.py): ``model-<tag>.vtu`` (the network
with its displacements; tag = rule, or rule-method[-freq]), ``deformed-<tag>.npz``
(reference vs model), ``lloyd.csv`` (Lloyd statistics), ``frequencies.csv`` (SMS vs FEM
natural frequencies, one column per rule and optimised model), and ``trace.csv`` (G
against optimiser steps, one ``model`` per run).
"""

from __future__ import annotations

import math
import time

import numpy as np
import pandas as pd

from harness.case.loads import modal_load
from harness.errors import CaseError, ModelError, SpringbenchError
from harness.stages import sms_measures as measures

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
    """The case's rows; with ``[model] classes``, each class's rows in turn (its files in
    the sub-folder named after it)."""
    import dataclasses

    from harness.models.classes import class_spec
    from harness.models.sms import model_spec
    spec = model_spec(case)
    classes = list(spec.get("classes") or ())
    if not classes:
        return _run(case, ctx, spec)
    rows = []
    for name in classes:
        sub = dataclasses.replace(ctx, out_dir=ctx.out_dir / name)
        rows += _run(case, sub, class_spec(spec, name))
    return rows


def _run(case, ctx, spec) -> list[dict]:
    from harness import scoring
    from harness.mechanics import statics
    from harness.mechanics.homogenize import case_report
    from harness.models.classes import build, class_of
    from harness.models.stiffness_rules import spring_constants
    from harness.stages import sms_mt
    p1, mt = bool(spec.get("p1")), bool(spec.get("mt"))
    opt = case.section("optimizer") or {}
    runs = optimiser_runs(case, opt)        # case mistakes first, before any solve
    runs = [] if p1 else sms_mt.runs(runs) if mt else runs     # P1 has no constants; MT: its own fit
    skip = sms_mt.skip_row(case, model_label(spec, case)) if mt else None
    if skip:
        return [skip]                       # 2-D: B&C have no element
    n_modes = _check_modes(case, opt)
    weights = scoring.case_weights(case)
    wlabel = ":".join(f"{w:g}" for w in weights)
    label = model_label(spec, case)
    t0 = time.perf_counter()
    ctx.status("building the P1 model" if p1 else "building the MT model" if mt else "building the spring/mass system")
    base = build(case, spec, seed=ctx.seed)     # springs, + volume (models/volume.py) or kn (models/kn.py), P1 or MT
    if spec["volume"] != "none":
        label += f"+volume-{spec['volume']}"
    if spec.get("kn", "none") != "none":
        label += f"+kn-{spec['kn']}"
    if p1 or mt:
        label = ("p1-" if p1 else "mt-") + label
    rules = ["p1"] if p1 else ["mt"] if mt else spec["stiffness"]
    build_seconds = time.perf_counter() - t0
    ctx.status("reference solve")
    ref, why = _reference(case, ctx)
    names = tuple(l.name for l in case.loads)
    fit = [names.index(n) for n in case.fit_loads]
    held = [names.index(n) for n in case.heldout]
    u_ref = scoring.reference_displacements(ref, base.points, names) if ref is not None else None
    common = {"case": case.name, "n_nodes": base.n_nodes, "n_springs": base.n_springs, "weights": wlabel,
              "seed": ctx.seed, "model_seed": base.info["seed"], "masses": spec["masses"], "mass_residual": base.info["mass_residual"],
              "negative_masses": base.info["negative_masses"], **_expect(case)}
    common.update(model_class=class_of(spec), nu=float(case.material.nu), dim=case.dim)
    if spec["volume"] != "none":
        common.update(volume=spec["volume"], n_volumes=base.volume.n_elements)
    if mt:
        common["n_elements"] = len(base.volume.body.cells)      # B&C's elements (the springs: connectivity)
    if spec.get("kn", "none") != "none":
        common.update(kn=spec["kn"], n_kn=base.volume.n_elements)
    if spec["placement"] == "lloyd":
        common["lloyd_iterations"] = spec["lloyd_iterations"]
    cauchy = None if p1 or mt else case_report(case, spec)     # the springs' lattice; P1 and MT have none
    if cauchy is not None:
        common.update(cauchy_misfit=cauchy["misfit"], cauchy_reachable=bool(cauchy["reachable"]),
                      cauchy_nu=cauchy["cauchy_nu"])
    if "lloyd_std_distance" in base.info:
        pd.DataFrame({"iteration": np.arange(len(base.info["lloyd_std_distance"])),
                      "std_distance": base.info["lloyd_std_distance"],
                      "std_area": base.info["lloyd_std_size"]}).to_csv(ctx.file("lloyd.csv"), index=False)

    def evaluate(net, res=None):
        """(statics (``res``, or solved here), score on the fitted loads, score on the
        held-out loads or None)."""
        res = statics.solve(net, case) if res is None else res
        if u_ref is None:
            return res, None, None
        sc, sh = scoring.fit_and_heldout(u_ref, res.u, net.classes, weights, names, case.fit_loads, case.heldout)
        return res, sc, sh

    def write(net, res, tag):
        """The row's files (``res`` None: the network alone)."""
        from harness.export.vtu import write_vtu
        if res is None:
            write_vtu(ctx.file(f"model-{tag}.vtu"), net, {})
            return
        if mt:          # theta and the element constants; the springs are only its connectivity
            sms_mt.save(ctx.file(f"mt-{tag}.npz"), net)
        elif not p1:    # a VTU holds springs; P1's are only its connectivity
            write_vtu(ctx.file(f"model-{tag}.vtu"), net, dict(zip(res.names, res.u)))
        if u_ref is not None:
            arrays = {"points": net.points, "springs": net.springs}
            for i, n in enumerate(res.names):
                arrays[f"u_ref_{n}"] = u_ref[i]
                arrays[f"u_{n}"] = res.u[i]
            np.savez(ctx.file(f"deformed-{tag}.npz"), **arrays)
        if getattr(net, "volume", None) is not None and not p1 and not mt:    # the VTU holds the springs only
            if spec.get("kn", "none") != "none":
                from harness.models.kn import save as save_kn
                save_kn(ctx.file(f"kn-{tag}.npz"), net)
            else:
                from harness.models.volume import save
                save(ctx.file(f"volume-{tag}.npz"), net)

    rows, nets, made = [], {}, {}
    for rule in rules:
        t1 = time.perf_counter()
        nets[rule] = base if rule == base.info["stiffness"] else base.with_k(
            spring_constants(rule, base.points, base.springs, base.cells, case.material), stiffness=rule)
        made[rule] = time.perf_counter() - t1
    from harness.stages.sms_rules import fit_score_of, solve_rules
    score = None if u_ref is None else lambda r: fit_score_of(r, case, u_ref, names, base.classes, weights)  # noqa: E731
    solved, bounds = solve_rules(case, nets, score, rules[0] if opt.get("start", "first") != "best" else None,
                                 ctx.status)
    for rule in rules:
        t1 = time.perf_counter()
        net = nets[rule]
        if rule in bounds:
            write(net, None, rule)
            rows.append({**common, "model": f"{label}[{rule}]", "stiffness": rule, "optimizer": "none",
                         "seconds": build_seconds + made[rule], "G_fit_score_bound": bounds[rule],
                         "note": "not solved under the clamps: half its free-traction score is above the best rule's "
                                 "G_fit_score (large meshes, harness/stages/sms_rules.py)"})
            continue
        res, sc, sh = evaluate(net, solved[rule])
        write(net, res, rule)
        row = {**common, "model": f"{label}[{rule}]", "stiffness": rule, "optimizer": "none",
               "seconds": build_seconds + made[rule] + res.seconds + time.perf_counter() - t1,
               **(sms_mt.constants(net) if mt else {})}
        if sc is not None:
            row.update(G_initial=sc.G, G_final=sc.G, G_norm_initial=sc.G_norm, G_norm_final=sc.G_norm,
                       G_s_initial=sc.G_s, G_s_final=sc.G_s, **measures.per_load_columns(sc, sh), **measures.fit_score(case, sc),
                       **measures.heldout_columns(sh))
        else:
            row.update(G_initial=math.nan, G_final=math.nan, G_norm_initial=math.nan, G_norm_final=math.nan,
                       note=f"no reference ({why})")
        rows.append(row)

    optimize = _optimizer()
    fem_f = measures.fem_frequencies(ref, n_modes, modal_load(case).name)
    opt_nets, traces = {}, []
    start_row, start = rows[0], base
    if opt.get("start", "first") == "best" and u_ref is not None:
        start_row = min(rows, key=measures.rank)
        start = nets[start_row["stiffness"]]
    if runs and optimize is not None and u_ref is not None:
        for run_ in runs:
            if run_.get("select") and not mt and not p1 and getattr(start, "volume", None) is None:
                from harness.stages import sms_select
                row, net, trace = sms_select.optimise(case, ctx, run_, start, u_ref, names, fit, weights, label,
                                                      common, start_row, evaluate, write,
                                                      solved.get(start_row["stiffness"]))
            else:
                row, net, trace = (sms_mt.optimise if mt else _optimise)(
                    case, ctx, optimize, run_, start, u_ref, names, fit, weights, spec, label, common, start_row,
                    evaluate, write, fem_f)
            rows.append(row)
            opt_nets[row["_tag"]] = net
            if trace is not None:
                traces.append(trace)
        if traces:
            pd.concat(traces, ignore_index=True).to_csv(ctx.file("trace.csv"), index=False)
        _time_to_reach(rows, traces)
    elif runs:
        rows[0]["note"] = rows[0].get("note", "") or ("optimiser not available" if optimize is None else "")

    if u_ref is not None:   # every net shares base's nodes, loads and weights: one G_ref for all rows
        refcols = scoring.ref_columns(ref, base.points, [names[i] for i in fit], u_ref[fit], base.classes, weights)
        heldcols = {}
        if held:
            hc = scoring.ref_columns(ref, base.points, [names[i] for i in held], u_ref[held], base.classes, weights)
            heldcols = {"G_ref_heldout": hc["G_ref"], "ref_error_heldout": hc["ref_error_max"]}
        for row in rows:
            if "G_norm_final" in row:
                row.update(refcols, **heldcols)
                row["status"] = scoring.ref_status(row["G_ref"], row["G_norm_final"], refcols.get("ref_met_tol"))
                if held and scoring.ref_status(row["G_ref_heldout"], row["G_heldout"], None) != "ok":
                    row["status"] = "ref-coarse"     # the held-out score is the reference's error too

    freqs = measures.model_frequencies(case, ctx, fem_f, {**nets, **opt_nets}, n_modes)
    m = measures.error_modes(opt, n_modes)
    all_nets = {**nets, **opt_nets}
    for row in rows:
        tag = row.pop("_tag", row["stiffness"])
        if tag in all_nets:
            row.update(measures.engine_columns(all_nets[tag], p1))
        if tag in freqs and "fem" in freqs and freqs["fem"][0] > 0:
            row["f1_ratio"] = float(freqs[tag][0] / freqs["fem"][0])
            row["freq_error_final"] = measures.freq_error(freqs[tag], freqs["fem"], m)
            start = row["stiffness"]         # the rule (an optimised row's start)
            row["freq_error_initial"] = measures.freq_error(freqs[start], freqs["fem"], m) if start in freqs else math.nan
            fitted = int(row.get("freq_modes", 0) or 0)     # modes the fit saw; the others are held out
            if len(freqs["fem"]) > fitted:
                row["freq_error_heldout"] = measures.freq_error(freqs[tag][fitted:], freqs["fem"][fitted:], m - fitted)
    return rows


# -- optimisers -------------------------------------------------------------------------

BUDGET_KEYS = ("temperatures", "max_steps", "max_seconds", "maxiter", "maxfun", "target", "tol", "ftol", "gtol",
               "xatol", "fatol", "cg_maxiter", "chains")


def _file(case) -> str | None:
    """The case file, for error messages (None for an in-memory case)."""
    return str(case.path) if case.path is not None else None


def check(case):
    """The [model] and [optimizer] mistakes the schema cannot see (for ``springbench validate``)."""
    from harness.models.sms import model_spec
    spec = model_spec(case)
    grid = spec.get("grid")
    if spec["placement"] == "grid" and not (isinstance(grid, (list, tuple)) and len(grid) == case.dim
                                            and all(isinstance(g, int) and g >= 2 for g in grid)):
        raise CaseError(f"grid = {grid!r} does not list {case.dim} node counts >= 2", file=_file(case),
                        field="model.grid", fix=f"e.g. grid = {[5] * case.dim}")
    if spec["placement"] == "grid" and spec.get("structure") is not None:
        from harness.models.topology import ALIASES, STRUCTURES_2D, STRUCTURES_3D
        known = STRUCTURES_2D if case.dim == 2 else STRUCTURES_3D
        if ALIASES.get(spec["structure"], spec["structure"]) not in known:
            raise CaseError(f"unknown {case.dim}-D grid structure '{spec['structure']}'", file=_file(case),
                            field="model.structure", fix=f"one of {', '.join(known)}")
    opt = case.section("optimizer") or {}
    from harness.optimize import check_method_options
    for run_ in optimiser_runs(case, opt):
        try:
            check_method_options(run_["method"], run_["options"])
        except SpringbenchError as exc:   # named by the case field the options came from
            field = (exc.field or "optimizer.options").replace("optimizer.options", run_["where"], 1)
            raise CaseError(exc.message, file=_file(case), field=field, fix=exc.fix) from None
    _check_modes(case, opt)


def optimiser_runs(case, opt) -> list[dict]:
    """The optimiser runs of a case, in table order: [optimizer] method, then each name
    in ``compare`` (options from ``compare_options``), then the ``frequency`` row.
    Each is {method, options, objective, where (the case field of its options)[, modes,
    weight]}. Mistakes the schema cannot see (a repeated optimiser, options that are not
    a table, options with method = "none") are CaseErrors naming the file and field."""
    method = opt.get("method", "none")
    file = _file(case)
    compare = list(opt.get("compare") or ())
    extra = dict(opt.get("compare_options") or {})
    if method in compare or len(set(compare)) != len(compare):
        raise CaseError(f"compare repeats '{method if method in compare else compare[0]}'", file=file,
                        field="optimizer.compare", fix="name each optimiser once (method is run already)")
    stray = sorted(set(extra) - set(compare))
    if stray:
        raise CaseError(f"options for '{stray[0]}', which compare does not list", file=file,
                        field="optimizer.compare_options", fix=f"add '{stray[0]}' to compare or remove its options")

    def options(value, where):
        if not isinstance(value or {}, dict):
            raise CaseError(f"expected a table of options, got {value!r}", file=file, field=where,
                            fix="e.g. { maxiter = 100 }")
        return dict(value or {})

    mine = options(opt.get("options"), "optimizer.options")
    if method == "none" and mine:          # would be silently ignored: no run takes them
        raise CaseError(f"options {sorted(mine)} but method = 'none' runs no optimiser", file=file,
                        field="optimizer.options", fix="set [optimizer] method, or remove the options")
    runs = [] if method == "none" else [dict(method=method, options=mine, objective="G", where="optimizer.options")]
    if runs and opt.get("select"):      # the validated fit (harness/stages/sms_select.py)
        runs[0]["select"] = dict(opt["select"])
    runs += [dict(method=m, options=dict(extra.get(m) or {}), objective="G", where=f"optimizer.compare_options.{m}")
             for m in compare]
    fq = opt.get("frequency")
    if fq:
        where = "optimizer.frequency.options"
        runs.append(dict(method=fq["method"], options=options(fq.get("options"), where), objective="G+freq",
                         modes=int(fq["modes"]), weight=float(fq["weight"]), where=where))
    return runs


def _check_modes(case, opt) -> int:
    n = int(case.reference.modes or 0)
    fq = opt.get("frequency")
    if fq and fq["modes"] > n:
        raise CaseError(f"frequency modes = {fq['modes']} but the reference computes {n}",
                        file=_file(case), field="optimizer.frequency.modes",
                        fix=f"set [reference] modes >= {fq['modes']} or lower frequency.modes")
    return n


def budget_label(options: dict) -> str:
    """The options that bound an optimiser's effort, as 'key=value, ...' ('default' if none)."""
    parts = [f"{k}={options[k]}" for k in BUDGET_KEYS if options.get(k) is not None]
    return ", ".join(parts) or "default"


def _optimise(case, ctx, optimize, run_, base, u_ref, names, fit, weights, spec, label, common, first, evaluate, write,
              fem_f):
    """One optimiser run on the fitted loads (indices ``fit`` of ``names``) and its row."""
    from harness.mechanics import statics
    from harness.optimize.diagnostics import fit_diagnostics
    from harness.optimize.problem import FitProblem
    from harness.scoring import node_weights
    method, objective = run_["method"], run_["objective"]
    stiff = base.info["stiffness"]
    tag = f"{stiff}-{method}" + ("-freq" if objective != "G" else "")
    _, free, forces = statics.all_load_arrays(base, case)
    free, forces, u_fit, names = free[fit], forces[fit], u_ref[fit], [names[i] for i in fit]
    wdof = np.repeat(node_weights(base.classes, weights), base.dim)
    file = _file(case)
    freq_kw = {}
    if objective != "G":
        if fem_f is None or len(fem_f) < run_["modes"]:
            raise SpringbenchError("the frequency term needs the reference's natural frequencies", file=file,
                                   field="optimizer.frequency", fix="use a reference with modes, or remove [optimizer.frequency]")
        if np.any(base.masses <= 0):
            raise ModelError(f"{int(np.sum(base.masses <= 0))} nodes have masses <= 0: no natural frequencies", file=file,
                             field="optimizer.frequency", fix="use [model] masses = 'moments-nonneg', 'voronoi' or 'uniform'")
        modal_free = ~statics.fixed_mask(base.points, case, modal_load(case)).ravel()
        freq_kw = dict(masses=base.masses, freq_target=np.asarray(fem_f[:run_["modes"]], float),
                       freq_weight=run_["weight"], modal_free=modal_free)
    k0, groups, extra = base.k, base.groups if spec["grouped"] else None, None
    if getattr(base, "volume", None) is not None:    # springs + volume / kn: [k, kv], columns beside B
        k0, groups, extra = base.params(), base.param_groups(spec["grouped"]), base.volume.columns(base.points)
    problem = FitProblem.from_network(base.points, base.springs, k0, free, forces,
                                      u_fit.reshape(len(names), -1), wdof, list(names),
                                      groups=groups, extra_columns=extra, **freq_kw)
    t0 = time.perf_counter()
    ctx.status(f"optimising ({method}{', frequencies' if freq_kw else ''})")
    seed = int(base.info["seed"])
    try:
        res = optimize(problem, method, dict(run_["options"]), seed, status=ctx.status)
    except SpringbenchError as exc:      # name the case file, and compare_options / frequency where they apply
        if exc.file is not None:
            raise
        field = exc.field or "optimizer"
        if field.startswith("optimizer.options"):
            field = run_["where"] + field[len("optimizer.options"):]
        elif field == "optimizer.method" and run_["where"] != "optimizer.options":   # the method came from there
            field = "optimizer.frequency.method" if objective != "G" else "optimizer.compare"
        raise type(exc)(exc.message, file=file, field=field, fix=exc.fix) from None
    seconds = time.perf_counter() - t0
    name = f"{stiff}+{method}" + ("+freq" if freq_kw else "")
    net = base.with_k(res.k, stiffness=name)
    sres, sc, sh = evaluate(net)
    write(net, sres, tag)
    info = dict(getattr(res, "info", {}) or {})
    row = {**common, "model": f"{label}[{stiff}]", "stiffness": stiff,
           "optimizer": method, "grouped": bool(spec["grouped"]), "seconds": seconds,
           "G_initial": first["G_initial"], "G_norm_initial": first["G_norm_initial"],
           "G_s_initial": first.get("G_s_initial", math.nan),
           "G_final": sc.G, "G_norm_final": sc.G_norm, "G_s_final": sc.G_s,
           "G_final_optimizer": float(getattr(res, "G_final", math.nan)),
           **measures.per_load_columns(sc, sh), **measures.fit_score(case, sc), **measures.heldout_columns(sh, first),
           "objective": objective, "budget": budget_label(run_["options"]), "n_params": problem.n_params,
           "_tag": tag}
    if freq_kw:
        row.update(freq_modes=run_["modes"], freq_weight=run_["weight"])
    for key in ("n_steps", "accepted"):
        if hasattr(res, key):
            row[f"opt_{key}"] = getattr(res, key)
    row["opt_seed"] = seed                   # the optimiser's random stream (SA); = model_seed
    if "stop" in info:
        row["opt_stop"] = str(info["stop"])
    if info.get("init", "none") != "none":
        row["opt_init"] = str(info["init"]) + (" (rejected: worse than k0)" if info.get("init_rejected") else "")
    if "prior" in info:     # lbfgs / nelder-mead: the weight of the pull towards the start (gradient.py)
        row["opt_prior"] = float(info["prior"])
    row["opt_evaluations"] = int(info.get("evaluations", getattr(res, "n_steps", 0)))
    if "iterations" in info:
        row["opt_iterations"] = int(info["iterations"])
    if "solves" in info:  # gauss-newton: linear solves (one evaluation of G is one per load set)
        row["opt_solves"] = int(info["solves"])
    row.update(fit_diagnostics(problem, np.asarray(res.k, float)))
    return row, net, _trace_frame(getattr(res, "trace", None), name)


def _time_to_reach(rows, traces):
    """``evals_to_sa_G`` / ``seconds_to_sa_G``: when each other optimiser's trace first
    reaches the G_final of the case's SA row (seconds pro rata of its evaluations);
    NaN if it never does."""
    sa = next((r for r in rows if r["optimizer"] == "sa" and r.get("objective") == "G"), None)
    if sa is None:
        return
    by_model = {t["model"].iloc[0]: t for t in traces}
    for r in rows:
        if r["optimizer"] in ("none", "sa") or r.get("objective") != "G":
            continue
        t = by_model.get(f"{r['stiffness']}+{r['optimizer']}")
        if t is None:
            continue
        hit = np.flatnonzero(t["G"].to_numpy() <= sa["G_final"] * (1 + 1e-9))
        steps = float(t["step"].iloc[-1])
        r["evals_to_sa_G"] = float(t["step"].iloc[hit[0]]) if len(hit) else math.nan
        r["seconds_to_sa_G"] = r["seconds"] * r["evals_to_sa_G"] / steps if len(hit) and steps > 0 else math.nan


def _trace_frame(trace, name):
    """An optimiser's trace ((step, G) rows, a G column or a DataFrame) as trace.csv rows
    with ``model`` = name; None if there is none or it has no recognisable shape."""
    if trace is None or not len(trace):
        return None
    try:
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
    except (ValueError, TypeError):
        return None
