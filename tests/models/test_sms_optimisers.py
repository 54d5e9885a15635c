"""Several optimisers on one spring/mass case (the compare list, its errors), the
frequency term, the seed means and the fit diagnostics."""

import numpy as np
import pytest

from harness import cli
from harness.case.reader import load_case
from harness.export.vtu import read_vtu
from harness.geometry import grid_points
from harness.mechanics import statics
from harness.models.sms import build_network
from harness.models.topology import grid_structure
from tests.models.springcases import ClosedFormRef, case_file, dense_K


class ModalRef(ClosedFormRef):
    """ClosedFormRef plus target natural frequencies: ``scale`` times the initial
    network's own (a target the optimiser can approach but not meet with the statics)."""

    target = None

    def frequencies(self, k, load=None):
        return np.asarray(self.target[:k], float)


def _dense_frequencies(points, springs, k, masses, free, n):
    """Independent modal solve: dense K spring by spring, scipy's generalised eigh."""
    import scipy.linalg as sla

    K = dense_K(points, springs, k)
    M = np.diag(np.repeat(masses, points.shape[1]))
    lam = sla.eigh(K[np.ix_(free, free)], M[np.ix_(free, free)], eigvals_only=True)
    return np.sqrt(np.maximum(lam[:n], 0)) / (2 * np.pi)


def _optimiser_case(tmp_path, optimizer, grid="[4, 4]", modes=0):
    f = case_file(tmp_path, extra=f'grid = {grid}\nstructure = "structure1"\nmasses = "voronoi"')
    text = f.read_text().replace(
        '[optimizer]\nmethod = "none"\n', "[optimizer]\n" + optimizer + "\n"
    )
    f.write_text(text.replace("modes = 0", f"modes = {modes}"))
    return f


def test_compare_runs_each_optimiser_on_the_same_model(tmp_path, monkeypatch):
    from harness.stages import StageContext
    from harness.stages import sms as stage

    f = _optimiser_case(
        tmp_path,
        'method = "sa"\noptions = { temperatures = 3 }\n'
        'compare = ["lbfgs", "gauss-newton"]\n'
        'compare_options = { "gauss-newton" = { maxiter = 15 } }',
    )
    case = load_case(f)
    monkeypatch.setattr(stage, "_reference", lambda case, ctx: (ClosedFormRef(case), ""))
    rows = stage.run(case, StageContext(out_dir=tmp_path / "out"))
    opt = [r for r in rows if r["optimizer"] != "none"]
    assert [r["optimizer"] for r in opt] == ["sa", "lbfgs", "gauss-newton"]
    assert [r["budget"] for r in opt] == ["temperatures=3", "default", "maxiter=15"]
    base = rows[0]
    for r in opt:
        # same initial model, reference and weights: the same G_initial and sizes
        assert r["G_initial"] == base["G_initial"] and r["weights"] == base["weights"]
        assert (r["n_nodes"], r["n_springs"], r["model"]) == (
            base["n_nodes"],
            base["n_springs"],
            base["model"],
        )
        assert r["G_final"] <= r["G_initial"] and r["seconds"] > 0 and r["opt_evaluations"] > 0
        # the stage's own re-solve agrees with the optimiser's G
        assert r["G_final"] == pytest.approx(r["G_final_optimizer"], rel=1e-9)
        assert r["opt_at_bounds"] >= 0 and 1 <= r["jac_rank"] <= r["n_params"] == r["n_springs"]
        assert r["opt_seed"] == base["model_seed"]  # the seed is recorded
    # the gradient fits reach a stationary point that 3 SA temperatures do not, and the
    # trace says when lbfgs first got below SA's G
    assert opt[1]["G_final"] < opt[0]["G_final"]
    assert 1 <= opt[1]["evals_to_sa_G"] <= opt[1]["opt_evaluations"]
    assert 0 < opt[1]["seconds_to_sa_G"] <= opt[1]["seconds"]
    import pandas as pd

    models = set(pd.read_csv(tmp_path / "out" / "trace.csv")["model"])
    assert models == {"deussen+sa", "deussen+lbfgs", "deussen+gauss-newton"}
    for tag in ("deussen-sa", "deussen-lbfgs", "deussen-gauss-newton"):
        assert (tmp_path / "out" / f"model-{tag}.vtu").exists()


@pytest.mark.parametrize(
    "optimizer,field",
    [
        ('method = "sa"\ncompare = ["lbfgs", "bfgs"]', "optimizer.compare"),
        (
            'method = "sa"\ncompare = ["lbfgs"]\ncompare_options = { bfgs = {} }',
            "optimizer.compare_options",
        ),
    ],
)
def test_unknown_compared_optimiser_is_a_one_line_case_error(tmp_path, optimizer, field):
    from harness.errors import CaseError

    with pytest.raises(CaseError) as err:
        load_case(_optimiser_case(tmp_path, optimizer))
    msg = str(err.value)
    assert (
        "\n" not in msg
        and "tiny.toml" in msg
        and field in msg
        and "'bfgs'" in msg
        and "lbfgs" in msg
    )
    assert cli.main(["validate", str(tmp_path / "tiny.toml")]) == 2


def test_compare_repeating_the_method_is_a_case_error(tmp_path, monkeypatch):
    from harness.errors import CaseError
    from harness.stages import StageContext
    from harness.stages import sms as stage

    case = load_case(_optimiser_case(tmp_path, 'method = "lbfgs"\ncompare = ["lbfgs"]'))
    monkeypatch.setattr(stage, "_reference", lambda case, ctx: (ClosedFormRef(case), ""))
    with pytest.raises(CaseError, match="optimizer.compare: compare repeats 'lbfgs'"):
        stage.run(case, StageContext(out_dir=tmp_path / "out"))


def test_frequency_term_reduces_the_frequency_error(tmp_path, monkeypatch):
    """lbfgs on G + the first 3 frequencies against targets 0.8x the initial network's:
    the frequency error falls, checked by a dense generalised eigensolve of the written
    model; the G-only lbfgs row on the same case leaves the frequencies far off."""
    from harness.stages import StageContext
    from harness.stages import sms as stage

    f = _optimiser_case(
        tmp_path,
        'method = "lbfgs"\noptions = { maxiter = 200 }\n'
        "[optimizer.frequency]\nmodes = 3\nweight = 1.0\noptions = { maxiter = 200 }",
        modes=4,
    )
    case = load_case(f)
    net0 = build_network(case)
    from harness.case.loads import modal_load

    free = ~statics.fixed_mask(net0.points, case, modal_load(case)).ravel()
    f0 = _dense_frequencies(net0.points, net0.springs, net0.k, net0.masses, free, 4)
    ref = ModalRef(case)
    ref.target = 0.8 * f0
    monkeypatch.setattr(stage, "_reference", lambda case, ctx: (ref, ""))
    rows = stage.run(case, StageContext(out_dir=tmp_path / "out"))
    static, freq = [r for r in rows if r["optimizer"] == "lbfgs"]
    assert (static["objective"], freq["objective"]) == ("G", "G+freq") and freq["freq_modes"] == 3
    err0 = np.sqrt(np.mean((f0[:3] / ref.target[:3] - 1) ** 2))  # = 0.25 by construction
    assert freq["freq_error_initial"] == pytest.approx(err0, rel=1e-9)
    net1, _ = read_vtu(tmp_path / "out" / "model-deussen-lbfgs-freq.vtu")
    f1 = _dense_frequencies(net1.points, net1.springs, net1.k, net1.masses, free, 3)
    err1 = np.sqrt(np.mean((f1 / ref.target[:3] - 1) ** 2))
    assert freq["freq_error_final"] == pytest.approx(err1, rel=1e-6)
    assert err1 < 0.2 * err0 and freq["f1_ratio"] == pytest.approx(f1[0] / ref.target[0], rel=1e-6)
    assert static["freq_error_final"] > 2 * err1
    assert freq["G_final"] <= freq["G_initial"]


def test_seed_means_and_optimiser_table_keep_optimisers_apart():
    """An optimised row shares ``model`` with its unoptimised row: seeds.csv and the
    optimisers table must not average them together (hand-computed means)."""
    import pandas as pd

    from harness.report.build import optimizer_frame, seeds_frame

    rows = []
    for seed, (g0, gsa, glb) in enumerate([(1.0, 0.2, 0.1), (3.0, 0.4, 0.1)]):
        common = dict(
            case="c", model="m[deussen]", stage="sms", seed=seed, status="ok", G_initial=g0
        )
        rows += [
            dict(common, optimizer="none", G_final=g0),
            dict(common, optimizer="sa", objective="G", G_final=gsa, budget="temperatures=2"),
            dict(common, optimizer="lbfgs", objective="G", G_final=glb, budget="default"),
        ]
    df = pd.DataFrame(rows)
    s = seeds_frame(df).set_index("optimizer")
    assert s.loc["none", "G_final_mean"] == pytest.approx(2.0)
    assert (
        s.loc["sa", "G_final_mean"] == pytest.approx(0.3) and s.loc["lbfgs", "G_final_std"] == 0.0
    )
    o = optimizer_frame(df).set_index("optimizer")
    assert list(o.index) == ["sa", "lbfgs"] and (o["n_seeds"] == 2).all()
    assert o.loc["lbfgs", "G_final_vs_sa"] == pytest.approx((0.1 / 0.2 + 0.1 / 0.4) / 2)
    assert o.loc["sa", "budget"] == "temperatures=2"


@pytest.mark.parametrize("grouped", [False, True])
def test_fit_diagnostics_jacobian_matches_finite_differences(grouped):
    """jac_* columns: the dense Jacobian of the weighted residual over log k (or log group
    factor) against central differences of the problem's own sparse re-solve."""
    from harness.optimize.diagnostics import fit_diagnostics, weighted_jacobian
    from harness.optimize.problem import FitProblem

    rng = np.random.default_rng(3)
    p = grid_points([0, 0], [2, 2], (3, 3))
    top = grid_structure((3, 3), "structure1")
    free = np.ones(p.size, bool)
    free[[0, 1, 3]] = False  # node 0 pinned, node 1 on a roller
    forces = rng.normal(size=(2, p.size)) * free
    u_ref = rng.normal(size=(2, p.size)) * 0.1
    w = rng.uniform(1, 3, p.size)
    k0 = rng.uniform(0.5, 2.0, len(top.springs))
    prob = FitProblem.from_network(
        p,
        top.springs,
        k0,
        [free, free],
        forces,
        u_ref,
        w,
        ["a", "b"],
        groups=top.groups if grouped else None,
    )
    x = rng.normal(scale=0.3, size=prob.n_params)
    k = prob.k_of(np.exp(x))
    J = weighted_jacobian(prob, k)

    def residual(x):
        return np.concatenate(
            [
                np.sqrt(b.w) * (b.u_ref - u)
                for b, u in zip(prob.blocks, prob.solve(prob.k_of(np.exp(x))))
            ]
        )

    h = 1e-6
    fd = np.stack(
        [(residual(x + h * e) - residual(x - h * e)) / (2 * h) for e in np.eye(prob.n_params)], 1
    )
    assert J.shape == fd.shape and np.allclose(J, fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())
    d = fit_diagnostics(prob, k)
    s = np.linalg.svd(fd, compute_uv=False)
    assert d["jac_rank"] == int(np.sum(s > 1e-8 * s[0]))
    assert d["jac_cond_logk"] == pytest.approx(s[0] / s[d["jac_rank"] - 1], rel=1e-4)
    assert (
        d["opt_at_bounds"] == 0
        and fit_diagnostics(prob, prob.k_of(np.full(prob.n_params, 1e3)))["opt_at_bounds"]
        == prob.n_params
    )


def _plain_gradient_descent(problem, n_evals):
    """Steepest descent on the spring constants themselves (per group in grouped mode),
    Armijo backtracking, growing step: the paper's 'pure gradient descent'. Returns G."""
    from harness.optimize.gradient import value_and_grad

    groups = problem.groups if problem.groups is not None else np.arange(problem.n_springs)
    kg = np.array([problem.k0[groups == g][0] for g in range(problem.n_params)])

    def f(x):
        G2, g = value_and_grad(problem, problem.k_of(x / kg))
        return G2, np.bincount(
            groups, weights=g * problem.k0 / kg[groups], minlength=problem.n_params
        )

    x = kg.copy()
    fx, g = f(x)
    step, ev = 1e-3 * np.linalg.norm(x) / np.linalg.norm(g), 1
    while ev < n_evals:
        xn = np.maximum(x - step * g, 1e-3 * kg)
        fn, gn = f(xn)
        ev += 1
        if fn <= fx - 1e-4 * g @ (x - xn):
            x, fx, g, step = xn, fn, gn, step * 1.5
        else:
            step *= 0.5
    return float(np.sqrt(fx))


@pytest.mark.slow
def test_plain_gradient_descent_is_slow_on_separate_constants_only(tmp_path, monkeypatch):
    """README claim(why the paper's gradient descent did badly): with the same
    number of G evaluations as L-BFGS-B over log k, steepest descent on k stays well above
    it when all 72 constants of the 5 x 5 grid are free (an ill-conditioned problem), and
    matches it with the 3 grouped constants."""
    from harness.optimize import optimize
    from harness.stages import StageContext
    from harness.stages import sms as stage

    out = {}
    for grouped in (False, True):
        f = _optimiser_case(tmp_path, 'method = "lbfgs"', grid="[5, 5]")
        f.write_text(
            f.read_text().replace(
                'masses = "voronoi"', f'masses = "voronoi"\ngrouped = {str(grouped).lower()}'
            )
        )
        box = {}

        def grab(problem, method, options, seed, status=None):
            box["p"] = problem
            return optimize(problem, "none", {}, 0)

        monkeypatch.setattr(stage, "_reference", lambda case, ctx: (ClosedFormRef(case), ""))
        monkeypatch.setattr(stage, "optimize", grab)
        stage.run(load_case(f), StageContext(out_dir=tmp_path / f"out{grouped}"))
        res = optimize(box["p"], "lbfgs", {}, 0)
        out[grouped] = (
            res.G_final,
            _plain_gradient_descent(box["p"], max(res.n_steps, 1000)),
            res.G_initial,
        )
    (lb, gd, g0), (lbg, gdg, _) = out[False], out[True]
    assert lb < 0.1 * g0 and gd > 1.2 * lb
    assert gdg == pytest.approx(lbg, rel=0.02) and lb < lbg


@pytest.mark.parametrize(
    "optimizer,field,text",
    [
        (
            'method = "sa"\noptions = { temperatures = 2 }\ncompare = ["gauss-newton"]\n'
            'compare_options = { "gauss-newton" = { maxiterr = 4 } }',
            "optimizer.compare_options.gauss-newton",
            "maxiterr",
        ),
        (
            'method = "lbfgs"\noptions = { maxiter = "forty" }',
            "optimizer.options.maxiter",
            "'forty'",
        ),
        ('method = "lbfgs"\noptions = 5', "optimizer.options", "table"),
        ('method = "none"\noptions = { temperatures = 5 }', "optimizer.options", "method = 'none'"),
        (
            'method = "none"\n[optimizer.frequency]\noptions = 3',
            "optimizer.frequency.options",
            "table",
        ),
        (
            'method = "none"\n[optimizer.frequency]\noptions = { init = "sa" }',
            "optimizer.frequency.options.init",
            "'sa'",
        ),
    ],
)
def test_bad_optimiser_options_name_the_case_file_and_field(
    tmp_path, monkeypatch, optimizer, field, text
):
    """Option mistakes surface as one line naming tiny.toml and the field where the options
    were written (compare_options / frequency, not a generic optimizer.options)."""
    from harness.errors import SpringbenchError
    from harness.stages import StageContext
    from harness.stages import sms as stage

    case = load_case(_optimiser_case(tmp_path, optimizer, modes=4))
    ref = ModalRef(case)
    ref.target = np.ones(4)
    monkeypatch.setattr(stage, "_reference", lambda case, ctx: (ref, ""))
    with pytest.raises(SpringbenchError) as err:
        stage.run(case, StageContext(out_dir=tmp_path / "out"))
    msg = str(err.value)
    assert (
        "\n" not in msg and msg.startswith(f"{tmp_path / 'tiny.toml'}: {field}: ") and text in msg
    )


def test_a_compared_method_refusing_the_problem_names_optimizer_compare(tmp_path, monkeypatch):
    from harness.errors import SpringbenchError
    from harness.stages import StageContext
    from harness.stages import sms as stage

    case = load_case(
        _optimiser_case(tmp_path, 'method = "none"\ncompare = ["nelder-mead"]', grid="[6, 6]")
    )
    monkeypatch.setattr(stage, "_reference", lambda case, ctx: (ClosedFormRef(case), ""))
    with pytest.raises(
        SpringbenchError, match=r"tiny.toml: optimizer.compare: nelder-mead with 110 parameters"
    ):
        stage.run(case, StageContext(out_dir=tmp_path / "out"))


@pytest.mark.parametrize(
    "optimizer,field",
    [
        ('method = "lbfgs"\ncompare = ["lbfgs"]', "optimizer.compare"),
        ('method = "lbfgs"\noptions = 5', "optimizer.options"),
        ('method = "none"\noptions = { temperatures = 5 }', "optimizer.options"),
        ('method = "none"\n[optimizer.frequency]\nmodes = 6', "optimizer.frequency.modes"),
    ],
)
def test_validate_sees_the_stage_checks(tmp_path, capsys, optimizer, field):
    """Mistakes only the sms stage can see are reported by `springbench validate`, before
    any run; a correct file still validates."""
    f = _optimiser_case(tmp_path, optimizer, modes=4)
    assert cli.main(["validate", str(f)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{f}: {field}: " in err[0]
    f.write_text(f.read_text().replace(optimizer.split("\n", 1)[1], ""))
    assert cli.main(["validate", str(f)]) == 0
