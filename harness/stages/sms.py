"""Stage "sms": build the case's spring/mass system, score every stiffness rule as an
unoptimised baseline row, then optimise the first rule's constants with each optimiser
run of the case (see optimiser_runs: [optimizer] method, each of ``compare``, and the
``[optimizer.frequency]`` row that adds the natural frequencies to G, Deussen Section 8)
and score each result: one row per run, all from the same initial model, reference and
weights, so the table compares optimisers and not set-ups (the rows' columns:
harness/stages/sms_rows.py). With ``[optimizer.select]`` the springs' fit chooses its
capacity by validation (harness/stages/sms_select.py). Every scored row carries
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
from dataclasses import dataclass, field
from functools import partial
from typing import Any

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
from harness.stages import sms_rows, sms_training
from harness.stages.classes.base import Setting
from harness.stages.classes.springs import of_spec
from harness.stages.sms_fit import case_file
from harness.stages.sms_rules import fit_score_of, rank_score_of, solve_rules
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
    """The rows of model class ``cls`` (harness/stages/classes/) on the case: each stiffness
    rule's, each fit's, then every row's reference, frequency and engine columns."""
    opt = case.section("optimizer") or {}
    runs = cls.fit_runs(optimiser_runs(case, opt))  # case mistakes first, before any solve
    label = cls.label(spec, case)
    skip = cls.skip(case, label)
    if skip:
        return Result((skip,), (None,), ((),), (None,))
    n_modes = _check_modes(case, opt)
    weights = scoring.case_weights(case)
    base, rules, build_seconds = _build(case, ctx, spec, cls)
    ctx.status("reference solve")
    ref, why = _reference(case, ctx)
    names = tuple(l.name for l in case.loads)
    u_ref = scoring.reference_displacements(ref, base.points, names) if ref is not None else None
    common = _common(case, ctx, spec, cls, base, weights)
    _write_lloyd(ctx, base.info)
    nets, made = _rule_networks(case, base, rules)
    solved, bounds = _solve_rules(case, ctx, opt, base, nets, rules[0], u_ref, names, weights)
    kept, dropped = _training(case, ctx, ref, base, weights, names, u_ref, solved)
    common = {**common, **dropped}
    scorer = Scorer(kept.case, ctx, cls, kept.u_ref, kept.names, weights)
    seconds = {r: build_seconds + made[r] for r in rules}
    rows = _rule_rows(scorer, common, label, rules, nets, kept.solved, bounds, seconds, why)
    fem_f = measures.fem_frequencies(ref, n_modes, modal_load(scorer.case).name)
    opt_nets = {}
    if runs and u_ref is not None:
        setting = scorer.setting(spec, label, common, fem_f)
        solved = [
            (r, nets[r["stiffness"]], kept.solved[r["stiffness"]])
            for r in rows
            if r["stiffness"] in kept.solved
        ]
        opt_nets = _fits(setting, cls, runs, rows, _start(rows, nets, base, opt), solved)
    elif runs:
        rows[0]["note"] = rows[0].get("note") or ""
    if u_ref is not None:
        sms_rows.add_ref_columns(rows, ref, base, scorer)
    all_nets = {**nets, **opt_nets}
    freqs = measures.model_frequencies(scorer.case, ctx, fem_f, all_nets, n_modes)
    m = measures.error_modes(opt, n_modes)
    p1 = not cls.spring_constants
    networks, validations, heldout = sms_rows.beside_rows(
        rows, all_nets, scorer.shown, freqs, m, p1
    )
    return Result(tuple(rows), tuple(networks), tuple(validations), tuple(heldout))


@dataclass(frozen=True)
class Scorer:
    """How one class's networks are scored and saved: on the case (its unresolved training
    states dropped) against the reference displacements ``u_ref`` (loads x nodes x dim, None
    without a reference) of the loads ``names``, with the node-class weights; each saved
    row's held-out displacements go to ``shown`` by tag."""

    case: Any
    ctx: Any
    cls: Any
    u_ref: Any
    names: tuple
    weights: Any
    shown: dict = field(default_factory=dict)

    @property
    def fit(self) -> list[int]:
        """The indices of the fitted loads in ``names``."""
        return [self.names.index(n) for n in self.case.fit_loads]

    @property
    def held(self) -> list[int]:
        """The indices of the held-out loads in ``names``."""
        return [self.names.index(n) for n in self.case.heldout]

    def evaluate(self, net, res=None):
        """(statics (``res``, or solved here), score on the fitted loads, score on the
        held-out loads or None)."""
        res = statics.solve(net, self.case) if res is None else res
        if self.u_ref is None:
            return res, None, None
        sc, sh = scoring.fit_and_heldout(
            self.u_ref,
            res.u,
            net.classes,
            self.weights,
            self.names,
            self.case.fit_loads,
            self.case.heldout,
        )
        return res, sc, sh

    def validated(self, net, res) -> dict:
        """The validation loads' columns of a network with statics ``res``: G_<load> of each
        (its own normalised G) and G_val_mean, their mean; none without validation loads or
        a reference."""
        val = list(self.case.validation)
        if self.u_ref is None or not val:
            return {}
        at = [self.names.index(n) for n in val]
        idx = [res.names.index(n) for n in val]
        sv = scoring.g_arrays(self.u_ref[at], res.u[idx], net.classes, self.weights, val)
        per = {f"G_{n}": float(sv.per_load_norm[n]) for n in val}
        return {**per, "G_val_mean": float(np.mean(list(per.values())))}

    def setting(self, spec: dict, label: str, common: dict, fem_f) -> Setting:
        """What the class's fits share (``fem_f``: the FEM's natural frequencies or None)."""
        return Setting(
            self.case,
            self.ctx,
            spec,
            label,
            common,
            self.u_ref,
            self.names,
            self.fit,
            self.weights,
            fem_f,
            optimize,
            self.evaluate,
            self.write,
            self.validated,
        )

    def write(self, net, res, tag: str) -> None:
        """The row's files (``res`` None: the network alone): the class's, and the
        reference against the model as ``deformed-<tag>.npz``."""
        if res is None:
            write_vtu(self.ctx.file(f"model-{tag}.vtu"), net, {})
            return
        self.cls.save(self.ctx, net, res, tag)
        if self.u_ref is None:
            return
        held = self.held
        if held:
            at = [res.names.index(self.names[i]) for i in held]
            self.shown[tag] = Heldout(tuple(self.case.heldout), self.u_ref[held], res.u[at])
        arrays = {"points": net.points, "springs": net.springs}
        for i, n in enumerate(res.names):
            arrays[f"u_ref_{n}"] = self.u_ref[i]
            arrays[f"u_{n}"] = res.u[i]
        np.savez(self.ctx.file(f"deformed-{tag}.npz"), **arrays)


def _rule_rows(scorer, common, label, rules, nets, solved, bounds, seconds, why) -> list:
    """The row of each stiffness rule (``nets``: their networks; ``solved``: their statics;
    ``bounds``: the score bounds of the rules left unsolved; ``seconds``: their builds')."""
    return [
        sms_rows.unsolved_row(scorer, common, label, r, nets[r], bounds[r], seconds[r])
        if r in bounds
        else sms_rows.rule_row(scorer, common, label, r, nets[r], solved[r], seconds[r], why)
        for r in rules
    ]


def _build(case, ctx, spec, cls) -> tuple:
    """(the class's network on the case's nodes, with the first rule's constants; its
    stiffness rules; the build's seconds)."""
    t0 = time.perf_counter()
    ctx.status(cls.building)
    base = cls.build(case, spec, seed=ctx.seed)
    rules = cls.rules(spec)
    return base, rules, time.perf_counter() - t0


def _common(case, ctx, spec, cls, base, weights) -> dict:
    """The columns every row of the class shares: the case, the network's size, the
    weights, the seeds, the masses, the paper's values, the class's own columns, Lloyd's
    iterations and the Cauchy lattice's report of its springs."""
    common = {
        "case": case.name,
        "n_nodes": base.n_nodes,
        "n_springs": base.n_springs,
        "weights": ":".join(f"{w:g}" for w in weights),
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
    return common


def _write_lloyd(ctx, info: dict) -> None:
    """lloyd.csv: the spread of the Lloyd iterations' spring lengths and cell sizes."""
    if "lloyd_std_distance" not in info:
        return
    pd.DataFrame(
        {
            "iteration": np.arange(len(info["lloyd_std_distance"])),
            "std_distance": info["lloyd_std_distance"],
            "std_area": info["lloyd_std_size"],
        }
    ).to_csv(ctx.file("lloyd.csv"), index=False)


def _rule_networks(case, base, rules) -> tuple[dict, dict]:
    """({rule: the network with the rule's spring constants}, {rule: seconds to make it})."""
    nets, made = {}, {}
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
    return nets, made


def _solve_rules(case, ctx, opt, base, nets, first, u_ref, names, weights) -> tuple[dict, dict]:
    """Every rule's statics over every load and the G_fit_score bounds of the rules a large
    mesh leaves unsolved (harness/stages/sms_rules.py; ``first`` always solved unless the
    fits start from the best rule)."""
    score = rank = None
    if u_ref is not None:
        of = dict(case=case, u_ref=u_ref, names=names, classes=base.classes, weights=weights)
        score = partial(fit_score_of, **of)
        rank = partial(rank_score_of, **of) if case.rank_by else None
    first = first if opt.get("start", "first") != "best" else None
    return solve_rules(case, nets, score, first, ctx.status, rank)


def _training(case, ctx, ref, base, weights, names, u_ref, solved) -> tuple:
    """(:class:`sms_training.Training`: the case without the training states the reference
    does not resolve, the rows' ``training_dropped`` column); with no reference or no
    held-out loads the case as it is and no column."""
    if u_ref is None or not case.heldout:
        return sms_training.Training(case, names, u_ref, solved), {}
    kept = sms_training.resolved(
        case, ref, base.points, base.classes, weights, names, u_ref, solved
    )
    if kept.line:
        ctx.status(kept.line)
    return kept, {"training_dropped": " ".join(kept.dropped)}


def _start(rows, nets, base, opt) -> tuple:
    """(the fits' start row, its network): the first rule's, or with ``start = "best"``
    the rule ranked first on the fitted loads (:func:`sms_measures.rank`)."""
    if opt.get("start", "first") != "best":
        return rows[0], base
    row = min(rows, key=measures.rank)
    return row, nets[row["stiffness"]]


def _fits(setting, cls, runs, rows, start, solved) -> dict:
    """Appends each optimiser run's row to ``rows`` (``start``: the start row and network;
    ``solved``: (row, network, statics) of each solved rule, which a validated fit reuses
    and is judged against), writes trace.csv and the time each run took to reach the SA
    row's G; returns {tag: fitted network}."""
    start_row, net0 = start
    statics_of = {r["stiffness"]: res for r, _, res in solved}
    nets, traces = {}, []
    for run_ in runs:
        if run_.get("select") and cls.selects and getattr(net0, "volume", None) is None:
            from harness.stages import sms_select

            row, net, trace = sms_select.optimise(
                setting, run_, net0, start_row, statics_of.get(start_row["stiffness"]), solved
            )
        else:
            row, net, trace = cls.fit(setting, run_, net0, start_row)
        rows.append(row)
        nets[row["_tag"]] = net
        if trace is not None:
            traces.append(trace)
    if traces:
        pd.concat(traces, ignore_index=True).to_csv(setting.ctx.file("trace.csv"), index=False)
    time_to_reach(rows, traces)
    return nets


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
