"""Stage "sms": build the case's spring/mass system, score every stiffness rule as an
unoptimised baseline row, then optimise the first rule's constants with each optimiser
run of the case (see optimiser_runs: [optimizer] method, each of ``compare``, and the
``[optimizer.frequency]`` row that adds the natural frequencies to G, Deussen Section 8)
and score each result: one row per run, all from the same initial model, reference and
weights, so the table compares optimisers and not set-ups. With ``[optimizer.select]`` the
springs' fit chooses its capacity by validation (harness/stages/sms_select.py). Every scored row
carries
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

import dataclasses
import math
import time
from dataclasses import dataclass

import numpy as np
import pandas as pd

import reference
from harness import registry, scoring
from harness.case.loads import modal_load
from harness.errors import CaseError, SpringbenchError
from harness.export.vtu import write_vtu
from harness.mechanics import statics
from harness.models.sms import model_spec
from harness.models.stiffness_rules import spring_constants
from harness.models.topology import ALIASES, STRUCTURES_2D, STRUCTURES_3D
from harness.optimize import check_method_options, optimize
from harness.stages import sms_measures as measures
from harness.stages import sms_training
from harness.stages.classes.base import Setting
from harness.stages.classes.springs import of_spec
from harness.stages.sms_fit import case_file
from harness.stages.sms_rules import fit_score_of, solve_rules
from harness.stages.sms_runs import optimiser_runs, time_to_reach

NAME = "sms"


def applies(case) -> bool:
    sec = case.section("model")
    return sec is not None and sec.get("kind") == "sms"


def _reference(case, ctx):
    """(the case's reference solution, "") or (None, why) for a case the FEM cannot solve."""
    try:
        return reference.solve(case, status=ctx.status), ""
    except NotImplementedError as exc:
        return None, f"reference: {exc}"


def _expect(case) -> dict:
    sec = case.section("expect") or {}
    vals = dict(sec.get("values") or {})
    return {
        "paper_G_initial": vals.get("G_initial", math.nan),
        "paper_G_final": vals.get("G_final", math.nan),
    }


@dataclass(frozen=True)
class Heldout:
    """The held-out loads' displacements at a row's nodes, (L, n, dim) each: the FEM's and
    the model's, as they were scored (for a picture of the fit without solving again)."""

    names: tuple[str, ...]
    u_fem: np.ndarray
    u_model: np.ndarray


@dataclass(frozen=True)
class Result:
    """The stage's rows and, beside each, its network (None for a row without one: a rule
    not solved), the validation table of a validated fit (empty for other rows) and its
    held-out displacements (:class:`Heldout`; None without held-out loads or a solve)."""

    rows: tuple
    networks: tuple
    validations: tuple
    heldout: tuple


def run(case, ctx) -> list[dict]:
    """The case's rows (the runner's view of :func:`models`)."""
    return list(models(case, ctx).rows)


def models(case, ctx) -> Result:
    """The case's rows and networks; with ``[model] classes``, each class's in turn (its
    files in the sub-folder named after it)."""
    spec = model_spec(case)
    names = list(spec.get("classes") or ())
    if not names:
        return _run(case, ctx, spec, of_spec(spec))
    parts = []
    for name in names:
        cls = registry.MODEL_CLASSES.load(name)
        parts.append(
            _run(case, dataclasses.replace(ctx, out_dir=ctx.out_dir / name), cls.spec(spec), cls)
        )
    return Result(*(sum((getattr(p, f) for p in parts), ()) for f in Result.__match_args__))


def _run(case, ctx, spec, cls) -> Result:
    """The rows of model class ``cls`` (harness/stages/classes/) on the case."""
    opt = case.section("optimizer") or {}
    runs = cls.fit_runs(optimiser_runs(case, opt))  # case mistakes first, before any solve
    label = cls.label(spec, case)
    skip = cls.skip(case, label)
    if skip:
        return Result((skip,), (None,), ((),), (None,))
    n_modes = _check_modes(case, opt)
    weights = scoring.case_weights(case)
    wlabel = ":".join(f"{w:g}" for w in weights)
    t0 = time.perf_counter()
    ctx.status(cls.building)
    base = cls.build(case, spec, seed=ctx.seed)
    rules = cls.rules(spec)
    build_seconds = time.perf_counter() - t0
    ctx.status("reference solve")
    ref, why = _reference(case, ctx)
    names = tuple(l.name for l in case.loads)
    fit = [names.index(n) for n in case.fit_loads]
    held = [names.index(n) for n in case.heldout]
    u_ref = scoring.reference_displacements(ref, base.points, names) if ref is not None else None
    common = {
        "case": case.name,
        "n_nodes": base.n_nodes,
        "n_springs": base.n_springs,
        "weights": wlabel,
        "seed": ctx.seed,
        "model_seed": base.info["seed"],
        "masses": spec["masses"],
        "mass_residual": base.info["mass_residual"],
        "negative_masses": base.info["negative_masses"],
        **_expect(case),
    }
    common.update(
        model_class=cls.name,
        nu=float(case.material.nu),
        dim=case.dim,
        **cls.columns(case, spec, base),
    )
    if spec["placement"] == "lloyd":
        common["lloyd_iterations"] = spec["lloyd_iterations"]
    cauchy = cls.lattice(case, spec)
    if cauchy is not None:
        common.update(
            cauchy_misfit=cauchy["misfit"],
            cauchy_reachable=bool(cauchy["reachable"]),
            cauchy_nu=cauchy["cauchy_nu"],
        )
    if "lloyd_std_distance" in base.info:
        pd.DataFrame(
            {
                "iteration": np.arange(len(base.info["lloyd_std_distance"])),
                "std_distance": base.info["lloyd_std_distance"],
                "std_area": base.info["lloyd_std_size"],
            }
        ).to_csv(ctx.file("lloyd.csv"), index=False)

    def evaluate(net, res=None):
        """(statics (``res``, or solved here), score on the fitted loads, score on the
        held-out loads or None)."""
        res = statics.solve(net, case) if res is None else res
        if u_ref is None:
            return res, None, None
        sc, sh = scoring.fit_and_heldout(
            u_ref, res.u, net.classes, weights, names, case.fit_loads, case.heldout
        )
        return res, sc, sh

    def write(net, res, tag):
        """The row's files (``res`` None: the network alone)."""
        if res is None:
            write_vtu(ctx.file(f"model-{tag}.vtu"), net, {})
            return
        cls.save(ctx, net, res, tag)
        if u_ref is not None and held:
            at = [res.names.index(names[i]) for i in held]
            shown[tag] = Heldout(tuple(case.heldout), u_ref[held], res.u[at])
        if u_ref is not None:
            arrays = {"points": net.points, "springs": net.springs}
            for i, n in enumerate(res.names):
                arrays[f"u_ref_{n}"] = u_ref[i]
                arrays[f"u_{n}"] = res.u[i]
            np.savez(ctx.file(f"deformed-{tag}.npz"), **arrays)

    rows, nets, made, shown = [], {}, {}, {}
    for rule in rules:
        t1 = time.perf_counter()
        nets[rule] = (
            base
            if rule == base.info["stiffness"]
            else base.with_k(
                spring_constants(rule, base.points, base.springs, base.cells, case.material),
                stiffness=rule,
            )
        )
        made[rule] = time.perf_counter() - t1
    # noqa: E731
    score = (
        None
        if u_ref is None
        else lambda r: fit_score_of(r, case, u_ref, names, base.classes, weights)
    )
    solved, bounds = solve_rules(
        case, nets, score, rules[0] if opt.get("start", "first") != "best" else None, ctx.status
    )
    if u_ref is not None and held:
        kept = sms_training.resolved(
            case, ref, base.points, base.classes, weights, names, u_ref, solved
        )
        case, names, u_ref, solved = kept.case, kept.names, kept.u_ref, kept.solved
        fit, held = [names.index(n) for n in case.fit_loads], [names.index(n) for n in case.heldout]
        common["training_dropped"] = " ".join(kept.dropped)
        if kept.line:
            ctx.status(kept.line)
    for rule in rules:
        t1 = time.perf_counter()
        net = nets[rule]
        if rule in bounds:
            write(net, None, rule)
            rows.append(
                {
                    **common,
                    "model": f"{label}[{rule}]",
                    "stiffness": rule,
                    "optimizer": "none",
                    "seconds": build_seconds + made[rule],
                    "G_fit_score_bound": bounds[rule],
                    "note": "not solved under the clamps: half its free-traction score is "
                    "above the best rule's "
                    "G_fit_score (large meshes, harness/stages/sms_rules.py)",
                }
            )
            continue
        res, sc, sh = evaluate(net, solved[rule])
        write(net, res, rule)
        row = {
            **common,
            "model": f"{label}[{rule}]",
            "stiffness": rule,
            "optimizer": "none",
            "seconds": build_seconds + made[rule] + res.seconds + time.perf_counter() - t1,
            **cls.constants(net),
        }
        if sc is not None:
            row.update(
                G_initial=sc.G,
                G_final=sc.G,
                G_norm_initial=sc.G_norm,
                G_norm_final=sc.G_norm,
                G_s_initial=sc.G_s,
                G_s_final=sc.G_s,
                **measures.per_load_columns(sc, sh),
                **measures.fit_score(case, sc),
                **measures.heldout_columns(sh),
            )
        else:
            row.update(
                G_initial=math.nan,
                G_final=math.nan,
                G_norm_initial=math.nan,
                G_norm_final=math.nan,
                note=f"no reference ({why})",
            )
        rows.append(row)

    fem_f = measures.fem_frequencies(ref, n_modes, modal_load(case).name)
    opt_nets, traces = {}, []
    start_row, start = rows[0], base
    if opt.get("start", "first") == "best" and u_ref is not None:
        start_row = min(rows, key=measures.rank)
        start = nets[start_row["stiffness"]]
    if runs and u_ref is not None:
        setting = Setting(
            case,
            ctx,
            spec,
            label,
            common,
            u_ref,
            names,
            fit,
            weights,
            fem_f,
            optimize,
            evaluate,
            write,
        )
        for run_ in runs:
            if run_.get("select") and cls.selects and getattr(start, "volume", None) is None:
                from harness.stages import sms_select

                row, net, trace = sms_select.optimise(
                    setting, run_, start, start_row, solved.get(start_row["stiffness"])
                )
            else:
                row, net, trace = cls.fit(setting, run_, start, start_row)
            rows.append(row)
            opt_nets[row["_tag"]] = net
            if trace is not None:
                traces.append(trace)
        if traces:
            pd.concat(traces, ignore_index=True).to_csv(ctx.file("trace.csv"), index=False)
        time_to_reach(rows, traces)
    elif runs:
        rows[0]["note"] = rows[0].get("note") or ""

    # every net shares base's nodes, loads and weights: one G_ref for all rows
    if u_ref is not None:
        refcols = scoring.ref_columns(
            ref,
            base.points,
            [names[i] for i in fit],
            u_ref[fit],
            base.classes,
            weights,
            tol_loads=() if held else None,
        )
        heldcols, held_met = {}, None
        if held:
            hc = scoring.ref_columns(
                ref, base.points, [names[i] for i in held], u_ref[held], base.classes, weights
            )
            heldcols = {"G_ref_heldout": hc["G_ref"], "ref_error_heldout": hc["ref_error_max"]}
            held_met = hc.get("ref_met_tol")
            refcols["ref_met_tol"] = (
                held_met if held_met is not None else refcols.get("ref_met_tol")
            )
        for row in rows:
            if "G_norm_final" in row:
                row.update(refcols, **heldcols)
                row["status"] = scoring.ref_status(
                    row["G_ref"], row["G_norm_final"], refcols.get("ref_met_tol")
                )
                if (
                    held
                    and scoring.ref_status(row["G_ref_heldout"], row["G_heldout"], held_met) != "ok"
                ):
                    row["status"] = "ref-coarse"  # the held-out score is the reference's error too

    freqs = measures.model_frequencies(case, ctx, fem_f, {**nets, **opt_nets}, n_modes)
    m = measures.error_modes(opt, n_modes)
    all_nets = {**nets, **opt_nets}
    networks, validations, heldout = [], [], []
    for row in rows:
        tag = row.pop("_tag", row["stiffness"])
        networks.append(all_nets.get(tag))
        heldout.append(shown.get(tag))
        validations.append(tuple(row.pop("_validation", ())))
        if tag in all_nets:
            row.update(measures.engine_columns(all_nets[tag], not cls.spring_constants))
        if tag in freqs and "fem" in freqs and freqs["fem"][0] > 0:
            row["f1_ratio"] = float(freqs[tag][0] / freqs["fem"][0])
            row["freq_error_final"] = measures.freq_error(freqs[tag], freqs["fem"], m)
            start = row["stiffness"]  # the rule (an optimised row's start)
            row["freq_error_initial"] = (
                measures.freq_error(freqs[start], freqs["fem"], m) if start in freqs else math.nan
            )
            # modes the fit saw; the others are held out
            fitted = int(row.get("freq_modes", 0) or 0)
            if len(freqs["fem"]) > fitted:
                row["freq_error_heldout"] = measures.freq_error(
                    freqs[tag][fitted:], freqs["fem"][fitted:], m - fitted
                )
    return Result(tuple(rows), tuple(networks), tuple(validations), tuple(heldout))


# -- the case's optimiser runs ---------------------------------------------------------


def check(case):
    """The [model] and [optimizer] mistakes the schema cannot see (for ``springbench validate``)."""
    spec = model_spec(case)
    grid = spec.get("grid")
    if spec["placement"] == "grid" and not (
        isinstance(grid, (list, tuple))
        and len(grid) == case.dim
        and all(isinstance(g, int) and g >= 2 for g in grid)
    ):
        raise CaseError(
            f"grid = {grid!r} does not list {case.dim} node counts >= 2",
            file=case_file(case),
            field="model.grid",
            fix=f"e.g. grid = {[5] * case.dim}",
        )
    if spec["placement"] == "grid" and spec.get("structure") is not None:
        known = STRUCTURES_2D if case.dim == 2 else STRUCTURES_3D
        if ALIASES.get(spec["structure"], spec["structure"]) not in known:
            raise CaseError(
                f"unknown {case.dim}-D grid structure '{spec['structure']}'",
                file=case_file(case),
                field="model.structure",
                fix=f"one of {', '.join(known)}",
            )
    opt = case.section("optimizer") or {}
    for run_ in optimiser_runs(case, opt):
        try:
            check_method_options(run_["method"], run_["options"])
        except SpringbenchError as exc:  # named by the case field the options came from
            field = (exc.field or "optimizer.options").replace(
                "optimizer.options", run_["where"], 1
            )
            raise CaseError(exc.message, file=case_file(case), field=field, fix=exc.fix) from None
    _check_modes(case, opt)


def _check_modes(case, opt) -> int:
    n = int(case.reference.modes or 0)
    fq = opt.get("frequency")
    if fq and fq["modes"] > n:
        raise CaseError(
            f"frequency modes = {fq['modes']} but the reference computes {n}",
            file=case_file(case),
            field="optimizer.frequency.modes",
            fix=f"set [reference] modes >= {fq['modes']} or lower frequency.modes",
        )
    return n
