"""How much a validated fit fits, chosen before it runs from the network's size.

The counts a case sets (``[optimizer.select]`` candidates x the families' folds x maxiter
iterations, then starts x the final maxiter) cost ~1 min of one core on calibrate's 2k-node
lug, but each evaluation factorises the training states' stiffness, ~n^2 flops in 3-D: on a
50k-tet mesh (27k dofs) the same counts are ~50 min of CPU, ten times its rule-only path
(the reference and the rules' statics). So the counts are a ladder of levels, each cheaper
than the one before, and a fit takes the first level whose predicted work fits its budget:

- work: the Gflop of the factorisations its evaluations need, from the symbolic
  factorisation (harness/linalg/multifrontal.py ``Symbolic.estimate``): EVALS_PER_ITER
  evaluations per L-BFGS-B iteration (the candidates of FEW_BASES: one evaluation per
  iteration, harness/optimize/few.py, and one in all without a volume term's factor),
  each factorising the training states' load sets
  (shared by the sets, harness/linalg/shared.py, where the validation fits and the cheaper
  levels' final fit do so);
- budget: BUDGET x the rules' statics (every solved rule factorises each set once) or
  FLOOR_GFLOP, whichever is larger, so the meshes of up to a few thousand tetrahedra keep
  the case's counts exactly.

The choice is a function of the mesh and the case alone (flop counts, not seconds): the
same counts, and the same export, on any machine under any load. ``work = "fixed"`` in
``[optimizer.select]`` keeps the case's counts at any size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from harness.optimize.problem import DENSE_FACTOR_MAX, FitProblem

EVALS_PER_ITER = 1.2  # L-BFGS-B's evaluations per iteration on the fits (~1.1-1.3 measured)
FEW_BASES = ("scale",)  # the candidates fitted by Gauss-Newton (harness/optimize/few.py)
BUDGET = 2.0  # the fit's work at most this many times the rules' statics' ...
FLOOR_GFLOP = 3000.0  # ... or this (~8 min of one core's factorisations), whichever is larger


@dataclass(frozen=True)
class Counts:
    """One level of the ladder: the candidates (None: the case's; else base capacities, each
    with and without every volume term the case's candidates have), the folds ('families':
    one per family as harness/optimize/select_table.py make_folds, 'two': the free-traction
    families together and the clamped states), each validation fit's maxiter, the final
    fit's starts and maxiter (None: the case's), whether the final fit shares the sets'
    factorisation; ``work_gflop`` and ``budget_gflop`` once predicted."""

    level: int
    candidates: tuple | None
    folds: str
    maxiter: int | None
    starts: int | None
    final_maxiter: int | None
    shared_final: bool
    work_gflop: float = math.nan
    budget_gflop: float = math.nan


LADDER = (
    Counts(0, None, "families", None, None, None, False),
    Counts(1, None, "families", 10, 1, 40, True),
    Counts(2, ("springs-prior1",), "two", 5, 1, 20, True),
    Counts(3, ("scale",), "two", 4, 1, 8, True),
    Counts(4, ("scale",), "two", 2, 1, 3, True),
)
VOLUMES = ("", "volume", "node-volume")  # a candidate's volume term: its name's suffix


# what a fit records of its counts (the row's fit_<key> columns, the JSON's fit_counts)
RECORDED = (
    "level",
    "candidates",
    "folds",
    "maxiter",
    "starts",
    "final_maxiter",
    "work_gflop",
    "budget_gflop",
)


def resolved(level: Counts, case_candidates, maxiter: int, starts: int, final_maxiter: int):
    """``level`` with the case's counts where it keeps them; its base capacities each with
    the volume terms the case's candidates have (none for an engine that runs none)."""
    have = {_volume(c) for c in case_candidates}
    cands = tuple(case_candidates)
    if level.candidates is not None:
        terms = [v for v in VOLUMES if v in have]
        cands = tuple(b + (f"+{v}" if v else "") for b in level.candidates for v in terms)
    return replace(
        level,
        candidates=cands,
        maxiter=maxiter if level.maxiter is None else level.maxiter,
        starts=starts if level.starts is None else level.starts,
        final_maxiter=final_maxiter if level.final_maxiter is None else level.final_maxiter,
    )


def _volume(name: str) -> str:
    return name.split("+", 1)[1] if "+" in name else ""


def n_folds(counts: Counts, families) -> int:
    return 2 if counts.folds == "two" else len(set(families))


def gflop(problem: FitProblem, shared: bool) -> float:
    """One evaluation's factorisations (Gflop): each group of the problem's solve parts."""
    p = replace(problem, shared=shared)
    sets = p.load_sets()
    total = 0.0
    for idx, group in p.solve_parts():
        s = sets[idx[0]]
        if group is not None:
            total += group.estimate()
        elif s.B.shape[0] > DENSE_FACTOR_MAX:
            total += s.symbolic().estimate()["gflop"]
        else:
            total += s.B.shape[0] ** 3 / 3e9  # a dense Cholesky
    return total


def gbytes(problem: FitProblem, shared: bool) -> float:
    """The largest factorisation of one evaluation (GB: its symbolic estimate; an evaluation
    holds one at a time), of the problem's solve parts."""
    p = replace(problem, shared=shared)
    sets, most = p.load_sets(), 0.0
    for idx, group in p.solve_parts():
        s = sets[idx[0]]
        if group is not None:
            roots = sum(len(r) ** 2 for r in group.root_keep)
            most = max(most, group.sym.estimate()["gbytes"] + 8e-9 * roots)
        elif s.B.shape[0] > DENSE_FACTOR_MAX:
            most = max(most, s.symbolic().estimate()["gbytes"])
    return most


def evaluations(name: str, maxiter: int) -> float:
    """One fit's predicted evaluations of candidate ``name`` stopped by ``maxiter``: L-BFGS-B's
    EVALS_PER_ITER per iteration; a few-constants fit's one per iteration, and one in all
    for a single factor (the common scale is closed form, harness/optimize/few.py)."""
    if name.split("+", 1)[0] not in FEW_BASES:
        return EVALS_PER_ITER * maxiter
    return float(maxiter) if _volume(name) else 1.0


def work(counts: Counts, families, per_eval_shared: float, per_eval_sets: float) -> float:
    """The level's predicted Gflop: its validation fits' and its final fit's evaluations
    (the final fit's: its costliest candidate's)."""
    folds = n_folds(counts, families)
    val = sum(folds * evaluations(c, counts.maxiter) for c in counts.candidates)
    final = counts.starts * max(evaluations(c, counts.final_maxiter) for c in counts.candidates)
    per_final = per_eval_shared if counts.shared_final else per_eval_sets
    return val * per_eval_shared + final * per_final


def choose(
    problem: FitProblem,
    families,
    n_rules: int,
    case_candidates,
    maxiter: int,
    starts: int,
    final_maxiter: int,
    fixed: bool = False,
) -> Counts:
    """The first level of LADDER whose work fits the budget (module doc), or the last; with
    ``fixed`` the case's own counts (level 0)."""
    shared, apart = gflop(problem, True), gflop(problem, False)
    budget = max(FLOOR_GFLOP, BUDGET * max(n_rules, 1) * apart)
    levels = LADDER[:1] if fixed else LADDER
    for level in levels:
        c = resolved(level, case_candidates, maxiter, starts, final_maxiter)
        if not c.candidates:
            continue
        w = work(c, families, shared, apart)
        c = replace(c, work_gflop=w, budget_gflop=budget)
        if w <= budget or level is levels[-1]:
            return c
    return c
