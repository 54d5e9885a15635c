"""The capacity chosen by leave-one-family-out validation (harness/optimize/select.py):
its pieces against hand computations, and whole selections on networks whose truth is
known (the rule exact: the rule is kept; the rule off by a factor: a fit wins)."""

import math

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from harness.optimize import select as sel
from harness.optimize.problem import FitProblem
from harness.optimize.synthetic import basic_loads, grid_network, solve_network

FAMILIES = ["constant", "constant", "bending", "bending", "clamped", "clamped"]


def problem(truth_factor, seed=0):
    """A 2-D grid network under six loads (the basic four and two more clamped ones),
    reference = the same network with constants k0 * truth_factor (per spring)."""
    p, springs, _ = grid_network((6, 4))
    names, free, forces = basic_loads(p)
    rng = np.random.default_rng(seed)
    extra_free = np.ones((2, p.size), bool)
    left = np.flatnonzero(p[:, 0] == 0)
    right = np.flatnonzero(p[:, 0] == p[:, 0].max())
    extra_forces = np.zeros((2, p.size))
    for j, (held, pulled) in enumerate(((left, right), (right, left))):
        extra_free[j, 2 * held], extra_free[j, 2 * held + 1] = False, False
        extra_forces[j, 2 * pulled + 1] = rng.uniform(0.5, 1.5, len(pulled))
    free, forces = np.vstack([free, extra_free]), np.vstack([forces, extra_forces])
    names = list(names) + ["clamp-left", "clamp-right"]
    L = np.linalg.norm(p[springs[:, 1]] - p[springs[:, 0]], axis=1)
    k0 = 1.0 / L
    u = solve_network(p, springs, k0 * truth_factor, free, forces)
    return (
        FitProblem.from_network(p, springs, k0, free, forces, u, np.ones(p.size), names),
        p,
        springs,
    )


def test_balanced_sums_the_loads_own_normalised_g():
    prob, _, _ = problem(np.full(1, 1.7))
    k = prob.k0 * 1.3
    own = []
    for b, u in zip(prob.blocks, prob.solve(k)):
        # no constrained part here
        own.append(np.sum(b.w * (b.u_ref - u) ** 2) / np.sum(b.w * b.u_ref**2))
    assert sel.balanced(prob).G2(k) == pytest.approx(sum(own), rel=1e-12)
    assert np.allclose(sel.per_load(prob, k) ** 2, own, rtol=1e-12)


def test_balanced_weighs_the_clamped_states_as_much_as_the_free_ones_together():
    """Four free-traction states and two clamped ones: each clamped state's own normalised
    G^2 counts 6 / (2 * 2) times, each free one's 6 / (2 * 4); the scores stay each load's own."""
    prob, _, _ = problem(np.full(1, 1.7))
    k = prob.k0 * 1.3
    own = sel.per_load(prob, k) ** 2
    part = np.array([6 / 8] * 4 + [6 / 4] * 2)
    assert sel.balanced(prob, FAMILIES).G2(k) == pytest.approx(float(part @ own), rel=1e-12)
    assert np.allclose(sel.per_load(sel.balanced(prob, FAMILIES), k) ** 2, own, rtol=1e-12)
    # no clamped state, or only clamped ones: every state alike
    for fams in (["constant"] * 6, ["clamped"] * 6):
        assert sel.balanced(prob, fams).G2(k) == pytest.approx(float(own.sum()), rel=1e-12)


def test_best_scale_is_the_minimum_of_g_over_a_global_factor():
    rng = np.random.default_rng(1)
    prob, _, _ = problem(2.5 * np.exp(0.3 * rng.standard_normal(1)))
    s = sel.best_scale(prob)
    num = minimize_scalar(
        lambda t: prob.G2(prob.k0 * t), bounds=(0.1, 10), method="bounded", options={"xatol": 1e-10}
    )
    assert s == pytest.approx(num.x, rel=1e-6)
    exact, _, _ = problem(np.full(1, 2.5))
    assert sel.best_scale(exact) == pytest.approx(2.5, rel=1e-10)  # u scales as 1 / s exactly


def test_folds_leave_families_out_and_the_clamped_states_together():
    assert sel.make_folds(FAMILIES) == {"constant": [0, 1], "bending": [2, 3], "clamped": [4, 5]}


def _row(name, a, b, rule=None):
    folds = ("constant", "clamped")
    r = {
        "model": name,
        "constant": a,
        "clamped": b,
        **sel.summary({"constant": a, "clamped": b}, folds),
    }
    r["ratio"] = sel.ratio_to_rule(r, rule or r)
    return r


def test_choose_by_score_keeps_the_rule_unless_a_candidate_beats_it_under_the_clamps():
    rule = _row("rule", 0.40, 0.05)
    # far better without a clamp, worse with one: never
    free_only = _row("free-only", 0.10, 0.08, rule)
    assert sel.choose([rule, free_only], "score")["model"] == "rule"
    both = _row("both", 0.30, 0.04, rule)
    assert sel.choose([rule, free_only, both], "score")["model"] == "both"
    assert both["score"] == pytest.approx(0.5 * (0.30 + 0.04))
    no_clamp = [
        {"model": "rule", "constant": 0.4, **sel.summary({"constant": 0.4}, ("constant",))},
        {"model": "c", "constant": 0.3, **sel.summary({"constant": 0.3}, ("constant",))},
    ]
    assert sel.choose(no_clamp, "score")["model"] == "c"


def test_choose_by_ratio_weighs_the_clamps_as_much_as_every_free_family():
    rule = _row("rule", 0.40, 0.05)
    # 4x better without a clamp, 1.6x worse with one: sqrt(0.25 * 1.6) = 0.632 of the rule's errors
    free_only = _row("free-only", 0.10, 0.08, rule)
    assert free_only["ratio"] == pytest.approx(np.sqrt(0.10 / 0.40 * 0.08 / 0.05), rel=1e-12)
    assert sel.choose([rule, free_only])["model"] == "free-only"
    # 1.6x better free, 1.6x worse clamped: a tie, so the rule; and 0.5 % better is a tie too
    tie = _row("tie", 0.25, 0.08, rule)
    near = _row("near", 0.398, 0.0499, rule)
    assert tie["ratio"] == pytest.approx(1.0) and sel.choose([rule, tie, near])["model"] == "rule"
    better = _row("better", 0.30, 0.045, rule)
    assert sel.choose([rule, tie, near, better, free_only])["model"] == "free-only"
    no_clamp = [
        {"model": "rule", "constant": 0.4, **sel.summary({"constant": 0.4}, ("constant",))},
        {"model": "c", "constant": 0.3, **sel.summary({"constant": 0.3}, ("constant",))},
    ]
    no_clamp[1]["ratio"] = sel.ratio_to_rule(no_clamp[1], no_clamp[0])
    no_clamp[0]["ratio"] = 1.0
    assert no_clamp[1]["ratio"] == pytest.approx(0.75) and sel.choose(no_clamp)["model"] == "c"
    with pytest.raises(ValueError):
        sel.choose([rule], "best")


CANDS = [c for c in sel.CANDIDATES if c.name in ("scale", "springs-prior1")]


@pytest.mark.parametrize("factor,choice", [(1.0, "rule"), (2.0, "not rule")])
def test_select_keeps_an_exact_rule_and_fits_a_wrong_one(factor, choice):
    prob, p, springs = problem(np.full(1, factor))
    groups = np.zeros(prob.n_springs, int)
    s = sel.select(
        prob, prob.n_springs, FAMILIES, 1.0, groups, CANDS, {"maxiter": 60}, {"maxiter": 200}, 3
    )
    assert [r["model"] for r in s.table] == ["rule", "scale", "springs-prior1"]
    if choice == "rule":
        assert s.choice == "rule" and np.array_equal(s.k, prob.k0)
        assert s.table[0]["score"] <= 1e-12
    else:
        assert s.choice != "rule" and len(s.starts) == 3
        assert s.table[0]["score"] == pytest.approx(1.0, rel=1e-9)  # u twice the truth: 100 % off
        assert sel.per_load(prob, s.k).max() < 1e-3  # the factor is recovered
        assert all(math.isfinite(r["score"]) for r in s.table)


def test_training_score_weighs_families_and_the_clamped_states_alike():
    """By hand: free families constant (0.1, 0.3) and bending (0.5), clamped (0.2, 0.4):
    free = mean(0.2, 0.5) = 0.35, clamped = 0.3, score = 0.325; the pooled mean would be 0.3."""
    fams = ["constant", "constant", "bending", sel.CLAMPED, sel.CLAMPED]
    assert sel.training_score([0.1, 0.3, 0.5, 0.2, 0.4], fams) == pytest.approx(0.325, rel=1e-14)
    assert sel.training_score([0.1, 0.3], ["constant", "bending"]) == pytest.approx(0.2, rel=1e-14)
    assert sel.training_score([0.2, 0.4], [sel.CLAMPED] * 2) == pytest.approx(0.3, rel=1e-14)
    # the rule's row of a validation table scores the same
    row = {"model": "rule", "constant": 0.2, "bending": 0.5, "clamped": 0.3}
    assert sel.summary(row, ("constant", "bending", "clamped"))["score"] == pytest.approx(
        0.325, rel=1e-14
    )


def test_best_ranks_rules_by_the_balanced_score_not_the_pooled_g():
    from harness.stages.sms_measures import rank

    rows = [
        {
            "stiffness": "uniform",
            "G_norm_final": 0.11,
            "G_fit_score": 0.29,
        },  # pooled best, balanced worse
        {"stiffness": "learned", "G_norm_final": 0.15, "G_fit_score": 0.21},
        {"stiffness": "mt", "G_norm_final": 0.05, "G_fit_score": math.nan},
    ]
    assert min(rows, key=rank)["stiffness"] == "learned"
    assert min(rows[2:], key=rank)["stiffness"] == "mt"  # without a score: the pooled G


def test_features_fit_recovers_planted_coefficients():
    """Truth k = k0 exp(c0 + X c) for features X of the springs: the 'features' fit of a
    rule k0 finds c0 and c (G to ~0), from the rule and from the best-scale start."""
    p, springs, _ = grid_network((6, 4))
    L = np.linalg.norm(p[springs[:, 1]] - p[springs[:, 0]], axis=1)
    d = (p[springs[:, 1]] - p[springs[:, 0]]) / L[:, None]
    # direction, height
    X = np.column_stack([np.abs(d[:, 0]), p[springs].mean(axis=1)[:, 1] / p[:, 1].max()])
    planted = np.array([0.4, -0.5, 0.3])
    names, free, forces = basic_loads(p)
    k0 = 1.0 / L
    u = solve_network(p, springs, k0 * np.exp(planted[0] + X @ planted[1:]), free, forces)
    prob = sel.balanced(
        FitProblem.from_network(p, springs, k0, free, forces, u, np.ones(p.size), names)
    )
    cand = next(c for c in sel.CANDIDATES if c.name == "features")
    M = sel.basis(prob, prob.n_springs, X)
    for x0 in sel.starts(prob, 2, 0, M):
        k = sel.fit(prob, cand, {"maxiter": 300}, x0, features=X)
        assert sel.per_load(prob, k).max() < 1e-5
        np.testing.assert_allclose(np.log(k / k0), planted[0] + X @ planted[1:], atol=1e-4)
    assert sel.starts(prob, 2, 0, M)[1] == pytest.approx(
        [math.log(sel.best_scale(prob)), 0, 0], abs=1e-12
    )


def test_features_candidates_need_features_and_are_skipped_without():
    prob, _, _ = problem(np.full(1, 2.0))
    groups = np.zeros(prob.n_springs, int)
    cands = [c for c in sel.CANDIDATES if c.name in ("scale", "features")]
    s = sel.select(
        prob, prob.n_springs, FAMILIES, 1.0, groups, cands, {"maxiter": 30}, {"maxiter": 60}, 2
    )
    assert [r["model"] for r in s.table] == ["rule", "scale"]


def jumping_clock(monkeypatch, hours: float = 3.0):
    """time.perf_counter, everywhere, jumping ``hours`` further at every call: a machine
    so loaded that each solve seems to take hours."""
    import time

    real, calls = time.perf_counter, [0]

    def clock():
        calls[0] += 1
        return real() + 3600.0 * hours * calls[0]

    monkeypatch.setattr(time, "perf_counter", clock)
    return calls


def _select(prob, **kw):
    groups = np.zeros(prob.n_springs, int)
    return sel.select(
        prob,
        prob.n_springs,
        FAMILIES,
        1.0,
        groups,
        CANDS,
        {"maxiter": 20},
        {"maxiter": 40},
        2,
        **kw,
    )


def test_the_validated_fit_is_the_same_whatever_the_clock_says(monkeypatch):
    """A wrong rule (off by 2): the validation runs and a fit wins, and the choice, the
    validation table and the constants of every start are the same bit for bit when each
    reading of the clock is hours after the last, with or without a cap that the jumps
    never reach: nothing is chosen or stopped by the clock."""
    prob, _, _ = problem(np.full(1, 2.0))
    idle = _select(prob)
    assert idle.choice != "rule" and [r["model"] for r in idle.table] == [
        "rule",
        *map(lambda c: c.name, CANDS),
    ]
    calls = jumping_clock(monkeypatch)
    for busy in (_select(prob), _select(prob, max_seconds=1e300)):
        assert busy.choice == idle.choice and busy.stops == idle.stops
        assert len(busy.starts) == len(idle.starts) == 2
        for a, b in zip(busy.starts, idle.starts):
            assert np.array_equal(a, b)
        assert busy.table == idle.table  # every score, bit for bit
    assert calls[0] > 0  # the clock was read (and ignored)


def test_a_validated_fit_past_its_cap_aborts_in_one_line(monkeypatch):
    """max_seconds caps the whole validated fit and only aborts: a cap the (jumping) clock
    passes is a one-line error naming the phase, the time it ran, the budget and the fix;
    never a selection from fits cut short."""
    from harness.optimize.deadline import BudgetExceeded

    prob, _, _ = problem(np.full(1, 2.0))
    jumping_clock(monkeypatch)
    with pytest.raises(BudgetExceeded) as err:
        _select(prob, max_seconds=60.0)
    text = str(err.value)
    assert "\n" not in text and "past its budget max_seconds = 60 s;" in text
    assert "validation (scale without constant (fit 1 of 6))" in text
    assert "raise --budget (or max_seconds) or coarsen the mesh" in text


def test_the_fits_options_hold_no_cap_of_their_own():
    prob, _, _ = problem(np.full(1, 2.0))
    groups = np.zeros(prob.n_springs, int)
    with pytest.raises(ValueError, match="max_seconds="):
        sel.select(prob, prob.n_springs, FAMILIES, 1.0, groups, CANDS, {"max_seconds": 5.0})


def test_select_takes_the_rules_scores_from_the_caller_without_solving(monkeypatch):
    """``rule_scores`` (the caller's per-load errors at the rule): the rule's row is theirs
    averaged per fold, and the candidates' rows, the choice and the constants are those of
    a select that solves the rule itself."""
    prob, _, _ = problem(np.full(1, 2.0))
    own = _select(prob)
    given = np.linspace(0.1, 0.6, len(FAMILIES))
    solved = []
    real = sel.per_load
    monkeypatch.setattr(sel, "per_load", lambda p, k: solved.append(p) or real(p, k))
    s = _select(prob, rule_scores=given)
    want = {"constant": given[:2].mean(), "bending": given[2:4].mean(), "clamped": given[4:].mean()}
    assert {f: s.table[0][f] for f in want} == pytest.approx(want, rel=1e-12)
    assert len(solved) == len(CANDS) * 3  # the left-out folds' scores only, not the rule's
    fitted = ("constant", "bending", "clamped", "free", "score")  # not the ratio: the rule's
    assert [[r[f] for f in fitted] for r in s.table[1:]] == [
        [r[f] for f in fitted] for r in own.table[1:]
    ]
    assert s.choice == own.choice != "rule"
    assert all(np.array_equal(a, b) for a, b in zip(s.starts, own.starts))
