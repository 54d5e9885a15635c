"""Every column a suite's summary.csv holds: its name (or a pattern: ``<load>``, ``<col>``,
``<i>``, ``<candidate>`` stand for any text), unit and meaning. The glossary of the results
page (``page``: the columns a reader meets first) and docs/columns.md are made from it;
tests/report/test_columns.py checks that every column of every committed summary.csv has
an entry. A stage that adds a column adds its line here."""

from __future__ import annotations

import re
from dataclasses import dataclass

from harness.report.columns_bc2000 import BC2000


@dataclass(frozen=True)
class Column:
    """One column: ``unit`` "" for a pure number, "m" (lengths are metres), "s", ... ."""

    name: str
    unit: str
    meaning: str
    page: bool = False

    def pattern(self) -> re.Pattern:
        parts = re.split(r"<\w+>", self.name)
        return re.compile("(?:.+)".join(map(re.escape, parts)) + r"\Z")


G_TEXT = (
    "G_{a:b:c} = sqrt(sum over loads and nodes of w_p |u_ref - u|^2), with the case's "
    "weights a:b:c for "
    "inner, border and corner nodes (Deussen 1995 eq. 12)"
)

CORE = [  # every suite: the runner's and the reference's columns
    Column("case", "", "the case file's name (its stem under cases/<suite>/)"),
    Column(
        "model",
        "",
        "the row's model: a label naming its class, placement and stiffness rule or fit",
        page=True,
    ),
    Column(
        "stage",
        "",
        "the stage that wrote the row (harness/stages: reference_check, sms, bc2000, engines)",
    ),
    Column(
        "seed",
        "",
        "the run's seed (the case's [run] seeds); every random draw of the row derives from it",
    ),
    Column(
        "status",
        "",
        "ok; ref-coarse: scored, but G_ref is above 10 % of the row's G or the reference missed "
        "its tol (kept in every table, flagged); error: the row failed (its message in note); "
        "skip: the class does not apply to the case",
        page=True,
    ),
    Column(
        "mode",
        "",
        "quick or full: the budgets the row ran with (the published results are full)",
        page=True,
    ),
    Column("seconds", "s", "wall time of the row's work (for a case-level row: the case's)"),
    Column(
        "seconds_validation",
        "s",
        "a validated fit: the wall time of its leave-one-family-out validation (within seconds)",
    ),
    Column(
        "seconds_final", "s", "a validated fit: the wall time of its final fit (within seconds)"
    ),
    Column("note", "", "why a row failed, was skipped or what an engine reported"),
    Column("dim", "", "the case's dimension, 2 or 3"),
    Column("nu", "", "the material's Poisson ratio"),
    Column(
        "load",
        "",
        "the load case the row scores (verification, engines: one row per load; mean: their mean)",
    ),
    Column("n_nodes", "count", "nodes of the model (masses)"),
    Column("n_springs", "count", "springs of the model"),
    Column(
        "n_elements",
        "count",
        "elements of the model's cells (B&C's element model: its tetrahedra or hexahedra)",
    ),
    Column("mesh", "", "the mesh the row ran on (the original program's file name)"),
    Column(
        "cached",
        "",
        "true when the FEM reference was read from the solution cache instead of solved",
    ),
    Column(
        "ref_method",
        "",
        "the reference's method: graded (a graded Q2 lattice), refine (adaptive P2) or closed",
    ),
    Column("n_dofs", "count", "unknowns of the reference's finest solve"),
    Column("ref_n_dofs", "count", "unknowns of the reference's finest solve"),
    Column(
        "ref_tol",
        "",
        "the tolerance the reference aimed at ([reference] tol), relative to its largest "
        "displacement",
    ),
    Column(
        "error_estimate",
        "",
        "the reference's estimated error of the load, relative to its largest displacement",
        page=True,
    ),
    Column(
        "closed_form_error",
        "",
        "the reference's true error against the load's closed-form solution, "
        "relative to its largest displacement (empty without one)",
        page=True,
    ),
    Column(
        "ref_error_estimate",
        "",
        "the reference's largest estimated error over the loads, relative to its "
        "largest displacement",
    ),
    Column(
        "f1_eb_ratio",
        "",
        "the reference's first natural frequency of the cantilever / Euler-Bernoulli's",
    ),
    Column(
        "G_ref",
        "",
        "the reference's own estimated error as a normalised G at the row's nodes: a G below a few "
        "times G_ref says more about the reference than about the model",
        page=True,
    ),
    Column("G_ref_heldout", "", "G_ref on the held-out loads"),
    Column(
        "ref_error_max",
        "",
        "the reference's largest estimated point error at the row's nodes, relative to "
        "its largest displacement",
        page=True,
    ),
    Column("ref_error_heldout", "", "ref_error_max on the held-out loads"),
    Column("ref_met_tol", "", "whether the reference's estimate met its tol at the row's nodes"),
    Column(
        "ref_met_tol_body",
        "",
        "whether the reference's estimate met its tol everywhere in the body",
    ),
]

SCORES = [  # the G criteria (harness/scoring.py)
    Column(
        "G_initial", "m", G_TEXT + ", before the fit (the starting rule's constants)", page=True
    ),
    Column("G_final", "m", G_TEXT + ", after the fit", page=True),
    Column(
        "G_norm_initial",
        "",
        "G_initial divided by sqrt(sum w_p |u_ref|^2): comparable across cases (0.05 = "
        "5 % RMS error)",
        page=True,
    ),
    Column("G_norm_final", "", "G_final normalised as G_norm_initial", page=True),
    Column("G_s_initial", "m", "G_s = G_{1:1:1} (every node weighs alike) before the fit"),
    Column("G_s_final", "m", "G_s = G_{1:1:1} after the fit"),
    Column(
        "G_final_optimizer",
        "m",
        "the G the optimiser reported at its end (equals G_final up to rounding; a check)",
    ),
    Column(
        "G_initial_optimizer",
        "",
        "p1, p1-global: the fit's balanced misfit at its start (sqrt of the sum over the "
        "fitted loads of each load's squared normalised G; its end is G_final_optimizer)",
    ),
    Column(
        "G_fit_score",
        "",
        "the validation's score of the row's model on the fitted loads: each load's own "
        "normalised G averaged per family (linear states, clamped), families alike",
    ),
    Column(
        "G_rank_score",
        "",
        "the mean of the own normalised G of the fitted loads [loads] rank_by names "
        "(calibrate: each held-out load's end-swapped twin); rules are ranked by it first",
    ),
    Column(
        "G_fit_score_bound",
        "",
        "a rule left unsolved under the clamps: a lower bound of its G_fit_score (half its "
        "free-traction score), above the best rule's",
    ),
    Column(
        "G_heldout",
        "",
        "normalised G on the held-out loads, which no fit ever used, pooled over them",
        page=True,
    ),
    Column("G_heldout_initial", "", "G_heldout of the fit's start"),
    Column(
        "G_heldout_mean",
        "",
        "the mean over the held-out loads of each load's own normalised G (a small load "
        "counts as much as a large one)",
        page=True,
    ),
    Column("G_heldout_mean_initial", "", "G_heldout_mean of the fit's start"),
    Column(
        "G_heldout_mean_spread",
        "",
        "a validated fit: max - min of G_heldout_mean over its starts (gaps inside it are ties)",
    ),
    Column("G_heldout_<load>", "", "the normalised G of one held-out load", page=True),
    Column(
        "G_norm",
        "",
        "normalised G: RMS displacement error / RMS FEM displacement over the nodes",
        page=True,
    ),
    Column("G_<load>", "m", "G_{a:b:c} of one load (fitted or held out)"),
    Column("max_error", "", "the largest nodal displacement error / the largest FEM displacement"),
    Column("weights", "", "a:b:c of G_{a:b:c} (inner, border, corner)"),
]

FITS = [  # spring/mass models and their fits (harness/stages/sms*.py)
    Column(
        "stiffness",
        "",
        "the stiffness rule the row starts from (deussen, vangelder, lloyd, uniform, cauchy, "
        "learned; p1, mt for those classes)",
    ),
    Column(
        "optimizer",
        "",
        "the fit (sa, lbfgs, gauss-newton, nelder-mead, equilibrium-gap; none: the rule)",
    ),
    Column(
        "grouped",
        "",
        "true when the fit varies one constant per spring group (horizontal, vertical, diagonal)",
    ),
    Column("masses", "", "the mass rule (moments, moments-nonneg, voronoi, uniform, lumped)"),
    Column(
        "mass_residual", "", "relative residual of the mass moments the masses were asked to match"
    ),
    Column("negative_masses", "count", "nodes whose mass came out negative (moments rule)"),
    Column("model_seed", "", "the seed of the random placement (the run's seed plus [model] seed)"),
    Column(
        "model_class",
        "",
        "the row's model class: a name of [model] classes (harness/registry.py MODEL_CLASSES, "
        "docs/models.md)",
    ),
    Column("volume", "", "the volume term: element, shared, node or node-shared"),
    Column("n_volumes", "count", "volume terms (elements or nodes)"),
    Column("kn", "", "Kot & Nagahashi's term: node (one kn per node) or shared"),
    Column("n_kn", "count", "Kot & Nagahashi terms"),
    Column("lloyd_iterations", "count", "Lloyd steps of the placement"),
    Column(
        "cauchy_nu",
        "",
        "the Poisson ratio a central-spring lattice can represent (1/4 in 3-D, 1/3 in 2-D "
        "plane stress)",
    ),
    Column(
        "cauchy_misfit",
        "",
        "how far the lattice's best homogenised stiffness is from the material's, relative",
    ),
    Column(
        "cauchy_reachable",
        "",
        "whether the lattice can reach the material's stiffness (misfit within tolerance)",
    ),
    Column("objective", "", "what the fit minimised: G, or G+freq (G and natural frequencies)"),
    Column("budget", "", "the fit's options that bound its work (iterations, seconds)"),
    Column(
        "n_params",
        "count",
        "constants the fit varies (3 when grouped, else one per spring, plus volume or kn "
        "constants)",
        page=True,
    ),
    Column("n_starts", "count", "starts of a validated fit's final fit"),
    Column(
        "fit_level",
        "",
        "the validated fit's counts: 0 the case's, 1-3 fewer fits on a large network "
        "(harness/optimize/select_counts.py), chosen before the fit from flop counts",
    ),
    Column("fit_candidates", "", "the candidates the validation fitted at that level"),
    Column("fit_folds", "", "families: a fold per family; two: free-traction and clamped"),
    Column(
        "fit_maxiter",
        "count",
        "iterations of each validation fit (L-BFGS-B; the scale candidates' Gauss-Newton)",
    ),
    Column("fit_starts", "count", "starts of the final fit at that level"),
    Column(
        "fit_final_maxiter", "count", "iterations of each start of the final fit (as fit_maxiter)"
    ),
    Column(
        "fit_work_gflop",
        "Gflop",
        "the level's predicted factorisation work (its evaluations' symbolic flop counts)",
    ),
    Column(
        "fit_budget_gflop",
        "Gflop",
        "the work allowed: twice the rules' statics' factorisations, at least 3,000 Gflop",
    ),
    Column(
        "choice",
        "",
        "the capacity validation chose ([optimizer.select]; rule: the rule's constants kept)",
        page=True,
    ),
    Column("val_families", "", "the load families validation left out one at a time"),
    Column("val_rule", "", "the rule's validation score"),
    Column(
        "val_<candidate>",
        "",
        "a candidate capacity's validation score (below the rule's: it predicts the "
        "left-out families better)",
    ),
    Column("opt_accepted", "count", "SA: accepted proposals"),
    Column("opt_n_steps", "count", "SA: proposals"),
    Column("opt_seed", "", "the optimiser's random stream (SA)"),
    Column("opt_stop", "", "why the fit stopped (converged, maxiter, max_seconds ...)"),
    Column(
        "opt_prior", "", "weight of the pull towards the start's constants (L-BFGS-B, Nelder-Mead)"
    ),
    Column(
        "opt_evaluations",
        "count",
        "evaluations of G (SA: proposals; Gauss-Newton: outer iterations)",
    ),
    Column("opt_iterations", "count", "the optimiser's iterations"),
    Column("opt_nit", "count", "L-BFGS-B's iterations of a material fitted per element (p1)"),
    Column("opt_nfev", "count", "L-BFGS-B's evaluations of a material fitted per element (p1)"),
    Column(
        "opt_stops",
        "",
        "why each start of the validated fit's final fit stopped (the exported one first)",
    ),
    Column("start_rule", "", "the stiffness rule the validated fit started from (its k0, its row)"),
    Column(
        "training_dropped",
        "",
        "training states left out of the fit: the FEM's error on them above a third of the "
        "best rule's (space-separated)",
    ),
    Column(
        "ref_note",
        "",
        "why the reference missed its tolerance: the loads above tol and how its levels ended",
    ),
    Column("E_fit_min", "Pa", "the smallest Young's modulus of a material fitted per element"),
    Column("E_fit_max", "Pa", "the largest Young's modulus of a material fitted per element"),
    Column("nu_fit_min", "", "the smallest Poisson's ratio of a material fitted per element"),
    Column("nu_fit_max", "", "the largest Poisson's ratio of a material fitted per element"),
    Column(
        "E_effective",
        "Pa",
        "the one Young's modulus every element shares (p1-global's fitted pair; empty when "
        "the elements differ)",
    ),
    Column(
        "nu_effective",
        "",
        "the one Poisson's ratio every element shares (p1-global's fitted pair; empty when "
        "the elements differ)",
    ),
    Column("opt_solves", "count", "Gauss-Newton: linear solves"),
    Column("opt_at_bounds", "count", "constants the fit left at a bound"),
    Column(
        "jac_rank",
        "count",
        "identifiable directions: singular values of the weighted residual's Jacobian "
        "above a tolerance",
    ),
    Column("jac_cond_logk", "", "condition of the weighted Jacobian at the result over log k"),
    Column("jac_cond_k", "", "condition of the weighted Jacobian at the result over k"),
    Column("evals_to_sa_G", "count", "G evaluations a fit needed to reach SA's final G", page=True),
    Column(
        "seconds_to_sa_G",
        "s",
        "seconds a fit needed to reach SA's final G (pro rata of its evaluations)",
    ),
    Column(
        "freq_error_initial",
        "",
        "RMS relative error of the first natural frequencies against the FEM's, before the fit",
    ),
    Column(
        "freq_error_final",
        "",
        "RMS relative error of the first natural frequencies against the FEM's",
        page=True,
    ),
    Column("freq_modes", "count", "natural frequencies in the frequency term or measure"),
    Column("freq_weight", "", "weight of the frequency term beside G"),
    Column("k_spread", "", "max / median spring constant"),
    Column(
        "dt_stable",
        "s",
        "largest stable explicit step of the free, undamped model (symplectic Euler)",
    ),
    Column(
        "improvement",
        "",
        "G_initial / G_final: comparable with paper_improvement although the paper's G is "
        "in units it does not state",
        page=True,
    ),
    Column("paper_<col>", "", "the paper's number for <col>", page=True),
    Column("ratio_<col>", "", "ours / the paper's for <col>", page=True),
]

ENGINES = [  # harness/stages/engines.py
    Column("body", "", "the body's name"),
    Column("resolution", "", "the mesh's resolution label (coarse, fine)"),
    Column("n_tets", "count", "tetrahedra of the body's mesh"),
    Column("engine", "", "the engine adapter (springbench engines run ENGINE)"),
    Column(
        "engine_status",
        "",
        "settled, not-settled, diverged, not-installed or failed: whether the engine "
        "reached equilibrium",
    ),
    Column("steps", "count", "time steps run (engines: to equilibrium; B&C: of the run)"),
    Column("wall_s", "s", "the engine's wall time to equilibrium"),
]

COLUMNS: tuple[Column, ...] = tuple(CORE + SCORES + FITS + ENGINES + [Column(*c) for c in BC2000])


def describe(name: str) -> Column | None:
    """The entry of column ``name``: an exact name first, else the first pattern that matches."""
    for c in COLUMNS:
        if c.name == name:
            return c
    for c in COLUMNS:
        if "<" in c.name and c.pattern().match(name):
            return c
    return None


def glossary(page_only: bool = True) -> list[tuple[str, str]]:
    """(name, meaning with its unit) of the page's columns (all with ``page_only`` False)."""
    return [
        (c.name, c.meaning + (f" ({c.unit})" if c.unit and c.unit != "count" else ""))
        for c in COLUMNS
        if c.page or not page_only
    ]
