"""The validated fit's counts chosen from the network's size (harness/optimize/select_counts.py):
the predicted work against hand counts, the ladder's order, the choice at, below and above
the budget, and the cheaper levels' folds and shared final fit in a whole selection."""

import math

import numpy as np
import pytest

from harness.case.sections import SELECT_DEFAULT
from harness.optimize import select as sel
from harness.optimize import select_counts as sc
from tests.optimize.test_select import FAMILIES, problem

CASE = dict(case_candidates=SELECT_DEFAULT, maxiter=30, starts=3, final_maxiter=100)
SIX = ["constant", "bending", "torsion", "shear-gradient", "gravity", "clamped"]


def test_the_work_is_the_fits_evaluations_times_their_factorisations():
    c = sc.resolved(sc.LADDER[0], SELECT_DEFAULT, 30, 3, 100)
    # 4 candidates x 6 folds x 30 iterations (shared sets: 2 Gflop an evaluation) and
    # 3 starts x 100 iterations of the final fit (each set apart: 5 Gflop)
    assert sc.work(c, SIX, 2.0, 5.0) == pytest.approx(1.2 * (4 * 6 * 30 * 2.0 + 3 * 100 * 5.0))
    two = sc.resolved(sc.LADDER[2], SELECT_DEFAULT, 30, 3, 100)
    assert two.candidates == ("springs-prior1", "springs-prior1+node-volume")
    assert sc.work(two, SIX, 2.0, 5.0) == pytest.approx(1.2 * (2 * 2 * 5 * 2.0 + 1 * 20 * 2.0))
    # the few-constants fits: one evaluation per iteration, one in all for the scale alone
    three = sc.resolved(sc.LADDER[3], SELECT_DEFAULT, 30, 3, 100)
    assert three.candidates == ("scale", "scale+node-volume")
    assert sc.work(three, SIX, 2.0, 5.0) == pytest.approx(2 * (1 + 4) * 2.0 + 1 * 8 * 2.0)


@pytest.mark.parametrize("shared,apart", [(1.0, 1.0), (2.0, 9.0), (30.0, 115.0)])
def test_each_level_costs_less_than_the_one_before(shared, apart):
    works = [
        sc.work(sc.resolved(level, SELECT_DEFAULT, 30, 3, 100), SIX, shared, apart)
        for level in sc.LADDER
    ]
    assert all(b < a for a, b in zip(works, works[1:])), works


def test_the_few_constants_candidates_are_the_one_group_ones():
    one = {c.name.split("+")[0] for c in sel.CANDIDATES if c.groups == "one"}
    assert set(sc.FEW_BASES) == one
    assert sc.evaluations("scale", 8) == 1 and sc.evaluations("scale+node-volume", 8) == 8
    assert sc.evaluations("springs-prior1", 10) == pytest.approx(12.0)


def test_an_engine_without_volume_terms_keeps_none_at_any_level():
    springs_only = ("springs-prior1", "springs-prior0.1")
    assert sc.resolved(sc.LADDER[2], springs_only, 30, 3, 100).candidates == ("springs-prior1",)
    assert sc.resolved(sc.LADDER[3], springs_only, 30, 3, 100).candidates == ("scale",)
    # a case of element volume terms keeps them (their columns are the problem's)
    element = ("springs-prior1+volume",)
    assert sc.resolved(sc.LADDER[3], element, 30, 3, 100).candidates == ("scale+volume",)
    every = sc.resolved(sc.LADDER[2], ("features", "springs-prior1+node-volume"), 30, 3, 100)
    assert every.candidates == ("springs-prior1", "springs-prior1+node-volume")
    names = {c.name for c in sel.CANDIDATES}
    for level in sc.LADDER:
        assert set(sc.resolved(level, SELECT_DEFAULT, 30, 3, 100).candidates) <= names


def test_dense_sets_cost_n_cubed_over_three():
    prob, p, _ = problem(np.full(1, 1.3))
    # every load set of the 6 x 4 grid is below the dense size: a dense Cholesky each
    by_set = {b.B.toarray().tobytes(): len(b.f) for b in prob.blocks}  # loads of one matrix
    assert max(by_set.values()) <= 400 and len(by_set) == 5  # shear-y, clamp-left share one
    expected = sum(n**3 / 3e9 for n in by_set.values())
    assert sc.gflop(prob, False) == pytest.approx(expected, rel=1e-12)


def test_a_small_network_keeps_the_case_counts_and_a_large_one_climbs(monkeypatch):
    prob, _, _ = problem(np.full(1, 1.3))
    fams = FAMILIES
    c = sc.choose(prob, fams, 6, **CASE)
    assert (c.level, c.candidates, c.maxiter, c.starts, c.final_maxiter) == (
        0,
        SELECT_DEFAULT,
        30,
        3,
        100,
    )
    assert c.folds == "families" and not c.shared_final and c.work_gflop <= c.budget_gflop
    shared, apart = sc.gflop(prob, True), sc.gflop(prob, False)
    works = [
        sc.work(sc.resolved(level, SELECT_DEFAULT, 30, 3, 100), fams, shared, apart)
        for level in sc.LADDER
    ]
    # a budget between levels 2 and 1 (the rules' statics scaled to it): level 2
    monkeypatch.setattr(sc, "FLOOR_GFLOP", 0.0)
    monkeypatch.setattr(sc, "BUDGET", (works[1] + works[2]) / 2 / (6 * apart))
    c = sc.choose(prob, fams, 6, **CASE)
    assert c.level == 2 and c.work_gflop == pytest.approx(works[2])
    assert c.budget_gflop == pytest.approx((works[1] + works[2]) / 2)
    # nothing fits: the cheapest level; "fixed": the case's counts whatever the size
    monkeypatch.setattr(sc, "BUDGET", 0.0)
    assert sc.choose(prob, fams, 6, **CASE).level == len(sc.LADDER) - 1 == 4
    assert sc.choose(prob, fams, 6, **CASE, fixed=True).level == 0
    # the same problem, the same counts: nothing but the mesh and the case decide
    assert sc.choose(prob, fams, 6, **CASE) == sc.choose(prob, fams, 6, **CASE)


def test_two_folds_hold_the_free_families_together():
    assert sel.two_folds(FAMILIES) == {"free": [0, 1, 2, 3], "clamped": [4, 5]}
    # every clamped state dropped (an L-bracket's: the FEM's error on them too large): the
    # free families alternately in two folds, so the validation still runs
    free = ["constant", "constant", "bending", "torsion", "gravity", "gravity"]
    assert sel.two_folds(free) == {"free-a": [0, 1, 3], "free-b": [2, 4, 5]}
    assert sel.two_folds(["constant", "constant"]) == {"constant": [0, 1]}


def test_a_cheaper_level_without_clamped_states_still_validates():
    prob, _, _ = problem(np.full(1, 2.0))
    free = ["constant", "constant", "bending", "bending", "torsion", "torsion"]
    cands = [c for c in sel.CANDIDATES if c.name == "scale"]
    groups = np.zeros(prob.n_springs, int)
    s = sel.select(
        prob, prob.n_springs, free, 1.0, groups, cands, {"maxiter": 4}, {}, 1, folds="two"
    )
    assert s.families == ("free-a", "free-b")
    assert all(math.isfinite(r["free-a"]) and math.isfinite(r["free-b"]) for r in s.table)
    assert s.choice == "scale"


def test_a_cheaper_level_still_recovers_a_wrong_rule(monkeypatch):
    """A rule off by a factor 2 everywhere: with two folds, few iterations and a shared final
    fit the validation still prefers a fit and the fit finds the factor."""
    prob, _, _ = problem(np.full(1, 2.0))
    cands = [c for c in sel.CANDIDATES if c.name in ("scale", "springs-prior1")]
    seen, real = [], sel.fit_result
    monkeypatch.setattr(
        sel, "fit_result", lambda p, *a, **kw: seen.append(p.shared) or real(p, *a, **kw)
    )
    s = sel.select(
        prob,
        prob.n_springs,
        FAMILIES,
        1.0,
        np.zeros(prob.n_springs, int),
        cands,
        {"maxiter": 4},
        {"maxiter": 8},
        1,
        folds="two",
        shared_final=True,
    )
    assert s.families == ("free", "clamped") and len(s.starts) == 1
    assert len(seen) == 2 * 2 + 1 and all(seen)  # 2 candidates x 2 folds, 1 start: shared
    assert all(math.isfinite(r["free"]) and math.isfinite(r["clamped"]) for r in s.table)
    assert s.choice != "rule"
    assert sel.per_load(
        prob,
        sel.columns(
            prob, prob.n_springs, sel.CANDIDATES[0], 1.0, np.zeros(prob.n_springs, int), None
        ).k0,
    ).max() == pytest.approx(1.0, rel=1e-9)
    assert sel.per_load(prob, s.k).max() < 0.01


def test_the_predicted_memory_holds_the_largest_factorisation():
    """eval_gbytes bounds what one evaluation holds: the largest factorisation of its solve
    parts (sets apart and shared groups), measured as its arrays' bytes after it is made."""
    import dataclasses

    from tests.optimize.test_shared_factor import grid

    prob = grid()
    k = prob.k0 * 1.2
    for shared in (False, True):
        p = dataclasses.replace(prob, shared=shared)
        made = []
        for idx, group in p.solve_parts():
            if group is not None:
                f = group.factor(k)
                arrays = [*f.mf.L11, *f.mf.L21, f.mf.root, *[r for r in f.roots if r is not None]]
            else:
                f = p.load_sets()[idx[0]].factor(k)
                arrays = [*f.L11, *f.L21]
            made.append(sum(a.nbytes for a in arrays) / 1e9)
        predicted = sc.gbytes(prob, shared)
        assert max(made) <= predicted <= 10 * max(made), (shared, made, predicted)
    # no set above the dense size: nothing to bound
    assert sc.gbytes(problem(np.full(1, 1.3))[0], False) == 0.0


def test_the_fits_run_in_as_many_processes_as_the_free_memory_holds(monkeypatch):
    """Two CPUs and eight tasks: two workers with room for both, one when the free memory
    holds one fit's WORKER_MEMORY x its factorisation, never none; without a prediction the
    memory is not asked."""
    import os

    from harness import forkpool

    total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 1e9
    assert 0 < forkpool.free_gbytes() <= total
    monkeypatch.setattr(forkpool.os, "sched_getaffinity", lambda pid: {0, 1})
    for free, expected in ((100.0, 2), (7.0, 1), (0.5, 1)):
        monkeypatch.setattr(forkpool, "free_gbytes", lambda free=free: free)
        assert forkpool.available_workers(8, 5000, task_gbytes=3.0) == expected
    monkeypatch.setattr(forkpool, "free_gbytes", lambda: 0.0)
    assert forkpool.available_workers(8, 5000) == 2


def test_select_asks_for_workers_with_its_largest_factorisation(monkeypatch):
    """Every caller of select gets the memory bound: select itself passes forkpool the
    largest factorisation one evaluation holds (select_counts.gbytes, sets apart or shared),
    not 0, which would let as many fits start as there are CPUs."""
    from harness import forkpool
    from tests.optimize.test_shared_factor import grid

    class Asked(Exception):
        pass

    asked = []

    def available(tasks, n_columns, task_gbytes=0.0):
        asked.append(task_gbytes)
        raise Asked

    monkeypatch.setattr(forkpool, "available_workers", available)
    prob = grid()
    fams = ["constant", "constant", "bending", "clamped", "clamped", "clamped"]
    cands = [c for c in sel.CANDIDATES if c.name in ("scale", "springs-prior1")]
    with pytest.raises(Asked):
        sel.select(prob, prob.n_springs, fams, 1.0, np.zeros(prob.n_springs, int), cands)
    expected = max(sc.gbytes(prob, shared) for shared in (False, True))
    assert expected > 0 and asked == [pytest.approx(expected, rel=1e-12)]
