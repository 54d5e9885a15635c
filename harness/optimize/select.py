"""Model capacity chosen by validation on the training states only (DESIGN.md,
"Training, validation, held-out").

A fit has choices the data must make: how many constants it may move (one scale for all
springs, a few groups, every spring with a pull towards the rule, springs plus a volume
term) and how hard the pull is. Leave-one-family-out validation makes them: for each
family of training states (constant, bending, torsion, shear-gradient, gravity, clamped),
every candidate is fitted on the other families and scored on the one left out; the
candidate with the lowest mean score is refitted on all training states. The rule itself
(no fit) is scored the same way; if no candidate beats it, the rule is the choice. The
held-out loads never choose anything: they are not in the problem given here.

Every training state counts alike: each load's misfit is divided by its own reference
norm (``balanced``), so the fit and the scores see the relative error of each state, not
the states with the largest displacements.

The problem holds the springs' columns first and, for the volume candidates, one column
per element after them (harness/models/volume.py: K = [B C] diag([k, kv]) [B C]^T).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from harness.optimize.problem import FitProblem


@dataclass(frozen=True)
class Candidate:
    """One model capacity: ``groups`` 'one' (one scale for all springs), 'direction'
    (one per spring direction class and length tercile), 'spring' (per spring, pulled
    towards the rule with weight ``prior``); ``volume``: the element volume columns join,
    with one shared kv (its own parameter)."""
    name: str
    groups: str
    prior: float = 0.0
    volume: bool = False


CANDIDATES = (Candidate("scale", "one"), Candidate("groups", "direction"),
              Candidate("springs-prior10", "spring", 10.0),
              Candidate("springs-prior1", "spring", 1.0), Candidate("springs-prior0.1", "spring", 0.1),
              Candidate("scale+volume", "one", volume=True),
              Candidate("springs-prior1+volume", "spring", 1.0, volume=True),
              Candidate("springs-prior0.1+volume", "spring", 0.1, volume=True))


@dataclass(frozen=True)
class Selection:
    """The choice ('rule' or a candidate's name), its constants over the problem's columns
    (spring-only choices: the springs' columns only), and the validation table: one row
    per model (the rule first) with its score on each left-out family and their mean."""
    choice: str
    k: np.ndarray
    table: tuple
    families: tuple

    @property
    def volume(self) -> bool:
        return self.choice != "rule" and next(c for c in CANDIDATES if c.name == self.choice).volume


def balanced(problem: FitProblem) -> FitProblem:
    """Each block's weights divided by its reference's weighted norm squared: G^2 becomes
    the sum of the loads' own normalised G^2."""
    blocks = []
    for b in problem.blocks:
        r2 = float(b.u_ref @ (b.w * b.u_ref)) + b.const
        s = 1.0 / r2 if r2 > 0 else 1.0
        blocks.append(dataclasses.replace(b, w=b.w * s, const=b.const * s))
    return dataclasses.replace(problem, blocks=tuple(blocks))


def subset(problem: FitProblem, keep) -> FitProblem:
    """The problem on the blocks ``keep`` (indices), nothing cached."""
    keep = list(keep)
    coords = None if problem.coords is None else tuple(problem.coords[i] for i in keep)
    return FitProblem(tuple(problem.blocks[i] for i in keep), problem.k0, problem.groups, problem.bounds,
                      problem.modal, coords)


def direction_groups(directions: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """(e,) group ids: the axis a spring points along most (|n_a| largest) times its
    length tercile: 9 groups in 3-D, 6 in 2-D (empty ones renumbered away)."""
    axis = np.argmax(np.abs(directions), axis=1)
    cuts = np.quantile(lengths, [1 / 3, 2 / 3])
    tercile = np.searchsorted(cuts, lengths, side="right")
    _, ids = np.unique(axis * 3 + tercile, return_inverse=True)
    return ids


def columns(problem: FitProblem, n_springs: int, cand: Candidate, kv0: float, groups: np.ndarray) -> FitProblem:
    """The candidate's problem: its columns (springs, + volume), start and parameter groups."""
    e = n_springs if not cand.volume else problem.n_springs
    sliced: dict = {}              # blocks with one B (the same free dofs) keep sharing one
    for b in problem.blocks:
        if id(b.B) not in sliced:
            sliced[id(b.B)] = b.B[:, :e].tocsc() if e < b.B.shape[1] else b.B
    blocks = tuple(dataclasses.replace(b, B=sliced[id(b.B)]) for b in problem.blocks)
    k0 = problem.k0[:e].copy()
    if cand.volume:
        k0[n_springs:] = kv0
    g = {"one": np.zeros(n_springs, int), "direction": groups, "spring": None}[cand.groups]
    if cand.volume:
        top = (int(g.max()) + 1) if g is not None else n_springs
        springs = g if g is not None else np.arange(n_springs)
        g = np.concatenate([springs, np.full(e - n_springs, top)])
    return FitProblem(blocks, k0, g, problem.bounds, None, problem.coords)


def fit(problem: FitProblem, cand: Candidate, options: dict) -> np.ndarray:
    """The candidate's constants fitted on ``problem`` (L-BFGS-B, adjoint gradient)."""
    from harness.optimize.gradient import lbfgs
    opts = dict(options)
    if cand.groups == "spring":
        opts["prior"] = cand.prior
    return lbfgs(problem, opts)["k"]


def per_load(problem: FitProblem, k: np.ndarray) -> np.ndarray:
    """Each block's own normalised G at k (balanced problems: sqrt of its G^2)."""
    out = []
    for b, u in zip(problem.blocks, problem.solve(k)):
        d = b.u_ref - u
        r2 = float(b.u_ref @ (b.w * b.u_ref)) + b.const
        out.append(math.sqrt((float(d @ (b.w * d)) + b.const) / r2))
    return np.array(out)


def select(problem: FitProblem, n_springs: int, families, kv0: float, groups: np.ndarray,
           candidates=CANDIDATES, options: dict | None = None, status=lambda msg: None) -> Selection:
    """Leave-one-family-out choice among ``candidates`` and the rule (module doc).
    ``problem``: the training states, columns [springs | volume elements] (k0 the rule's
    springs, anything positive for the elements); ``families`` (one per block)."""
    options = dict(options or {"maxiter": 200})
    problem = balanced(problem)
    families = list(families)
    names = sorted(set(families), key=families.index)
    idx = {f: [i for i, g in enumerate(families) if g == f] for f in names}
    rule = columns(problem, n_springs, Candidate("rule", "one"), kv0, groups)
    scores = per_load(rule, rule.k0)
    table = [dict(model="rule", **{f: float(scores[idx[f]].mean()) for f in names})]
    for cand in candidates:
        cp = columns(problem, n_springs, cand, kv0, groups)
        row = {"model": cand.name}
        for f in names if len(names) > 1 else ():
            status(f"validation: {cand.name} without {f}")
            rest = [i for i in range(len(families)) if families[i] != f]
            k = fit(subset(cp, rest), cand, options)
            row[f] = float(per_load(subset(cp, idx[f]), k).mean())
        table.append(row)
    for row in table:
        row["mean"] = float(np.mean([row[f] for f in names])) if all(f in row for f in names) else math.nan
    best = min(table, key=lambda r: r["mean"] if math.isfinite(r["mean"]) else math.inf)
    if best["model"] == "rule" or not math.isfinite(best["mean"]):
        return Selection("rule", problem.k0[:n_springs].copy(), tuple(table), tuple(names))
    cand = next(c for c in candidates if c.name == best["model"])
    status(f"fitting {cand.name} on every training state")
    k = fit(columns(problem, n_springs, cand, kv0, groups), cand, options)
    return Selection(cand.name, k, tuple(table), tuple(names))
