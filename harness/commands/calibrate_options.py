"""calibrate's command-line options in six groups, in the order --help lists them: the mesh
and its material, the model and its fit, the loads and their regions, the body's masses,
damping and units, the loads' size and the reference's accuracy, and the outputs."""

from __future__ import annotations

from pathlib import Path

from harness.case.default_loads import PEAK_STRAIN
from harness.commands.calibrate_case import (
    INITS,
    MASSES,
    METHODS,
    MODELS,
    REGION_FORMS,
    RULES,
    UNITS,
    model_name,
    positive,
    signed_numbers,
)
from harness.registry import EXPORT_ENGINES, EXPORT_TERMS, SOLVERS, TERMS, class_doc


def inputs(p):
    """calibrate's options: the mesh and its material."""
    p.add_argument(
        "mesh",
        type=Path,
        metavar="MESH",
        help="tri/quad/tet/hex mesh (any meshio format or bc2000)",
    )
    signed_numbers(p)
    p.add_argument(
        "--E",
        dest="E",
        type=positive("E", "Pa"),
        required=True,
        help="Young's modulus (Pa; below 100 Pa a warning: MPa?)",
    )
    p.add_argument("--nu", type=float, required=True, help="Poisson ratio in (-1, 0.5)")
    p.add_argument(
        "--density",
        type=positive("density", "kg/m^3"),
        default=1000.0,
        help="density (kg/m^3; default 1000; outside 10..30,000 a warning: g/cm^3?)",
    )


def model(p):
    """calibrate's options: the model, its fit and its start."""
    p.add_argument(
        "--method",
        choices=tuple(METHODS),
        default="lbfgs",
        help="rule: initial constants only; sa: simulated annealing; lbfgs: adjoint gradient "
        "(default); gauss-newton; equilibrium-gap: one linear least-squares solve",
    )
    p.add_argument(
        "--model",
        choices=MODELS,
        type=model_name,
        default="springs",
        help="the model class (default springs): "
        + "; ".join(f"{n}: {class_doc(n)}" for n in MODELS),
    )
    p.add_argument(
        "--engine",
        choices=EXPORT_ENGINES,
        default=None,
        help="the engine that will run the export: the validated fit chooses only among "
        "candidates whose volume term it runs natively ("
        + "; ".join(f"{e}: {', '.join(TERMS[t] for t in EXPORT_TERMS[e])}" for e in EXPORT_ENGINES)
        + "), and a --model with a term it cannot run is refused (default: every candidate)",
    )
    p.add_argument(
        "--prior-weight",
        dest="prior_weight",
        type=float,
        default=None,
        help="lbfgs: fit every spring with this weight a of the pull towards the start "
        "rule's constants, "
        "Phi = G^2/G0^2 + a mean(log(k/k_rule)^2), instead of the capacity chosen by validation "
        "(default: chosen; 0: no pull)",
    )
    p.add_argument(
        "--init",
        choices=INITS,
        default="none",
        help="start of lbfgs / gauss-newton: the rule's constants (none, default) or the "
        "equilibrium-gap estimate (much faster on large meshes)",
    )
    p.add_argument(
        "--rule",
        choices=RULES + ("best",),
        default="best",
        help="stiffness rule of the initial constants: best (default: the rule with the lowest "
        "G_rank_score, the error on the held-out loads' end-swapped twins, then G_fit_score on "
        "the fitted loads; the fit starts from it) or one of them",
    )


def loads(p):
    """calibrate's options: the loads and the regions they hold and load."""
    p.add_argument(
        "--loads",
        choices=("linear", "homogeneous", "basic"),
        default="linear",
        help="fitted loads: the equilibrated linear stress states (constant, bending, "
        "torsion, shear "
        "gradient, gravity) on the whole surface, exact for any shape (default); "
        "homogeneous: their "
        "constant part only; basic: the basic loads of the bounding box (boxes); with "
        "--heldout ends "
        "also clamped training states (the ends swapped, and each side face held)",
    )
    p.add_argument(
        "--heldout",
        choices=("ends", "none"),
        default="ends",
        help="held-out loads (default ends): sag, tip load, (3-D) a second tip load across "
        "and torsion "
        "with one end face clamped, and the sag with both end faces clamped (bridge); or none",
    )
    p.add_argument(
        "--clamp",
        metavar="REGION",
        default=None,
        help="clamp of the held-out loads (default: the end face at the low end of the longest "
        f"axis): {REGION_FORMS}",
    )
    p.add_argument(
        "--load-region",
        dest="load_region",
        metavar="REGION",
        default=None,
        help="where the held-out tip loads and torsion act (default: the end face at the high "
        "end of the longest axis; the torsion turns about the region's mean outward normal): "
        "as --clamp",
    )


def body(p):
    """calibrate's options: masses, damping, units and the plane."""
    p.add_argument(
        "--masses",
        choices=MASSES,
        default="lumped",
        help="lumped element masses (default, never negative), moments-nonneg, or moments "
        "(Deussen's moment matching: may be negative, which explicit engines cannot run)",
    )
    p.add_argument(
        "--damping-ratio",
        dest="damping_ratio",
        type=float,
        default=0.05,
        help="spring damping as a fraction of each spring's critical damping (default 0.05)",
    )
    p.add_argument(
        "--k-ratio",
        dest="k_ratio",
        type=float,
        default=None,
        help="cap the fitted constants at this multiple of their median (max/median): a larger "
        "stable step for some G; the table shows both",
    )
    p.add_argument(
        "--length-unit",
        dest="length_unit",
        choices=tuple(UNITS),
        default="m",
        help="unit of the mesh's coordinates (default m; exports are in m; a body over 10 m or "
        "under 0.1 mm across gets a warning)",
    )
    p.add_argument(
        "--plane",
        choices=("stress", "strain"),
        default="stress",
        help="2-D meshes: plane stress/strain",
    )


def reference(p):
    """calibrate's options: the loads' size and the reference's accuracy."""
    p.add_argument(
        "--magnitude",
        type=float,
        default=None,
        help="stress of the fitted loads (Pa; default 1e-3 E: small strains)",
    )
    p.add_argument(
        "--peak-strain",
        dest="peak_strain",
        type=float,
        default=PEAK_STRAIN,
        help=f"the held-out loads' size: a peak strain of about this by beam theory on the body's "
        f"section (default {PEAK_STRAIN:g}: the linear answer is the physical one)",
    )
    p.add_argument(
        "--tol",
        type=float,
        default=1e-2,
        help="reference (FEM) target: every held-out load's estimated error relative to its "
        "largest displacement at the mesh's nodes (default 1e-2)",
    )
    p.add_argument(
        "--max-refine",
        dest="max_refine",
        type=int,
        default=100,
        help="reference refinements at most (default 100: not counted, tri/tet meshes are "
        "refined adaptively until --tol on every held-out load or 600k dofs in 3-D, 400k in "
        "2-D, a mesh too large for that estimated from coarser meshes of its body; below 100: "
        "that many, 2-3 adaptive bisection steps each within 200k dofs; quad/hex: uniform, "
        "x4-8 dofs; 0: no estimate)",
    )
    p.add_argument(
        "--solver",
        choices=tuple(SOLVERS),
        default="auto",
        help="FEM linear solver (default auto: sparse Cholesky, or for large P2 systems CG with a "
        "two-level P1 preconditioner (two-level); AMG and Cholesky as fallbacks)",
    )
    p.add_argument(
        "--budget",
        type=float,
        default=None,
        help="a wall-time cap in seconds on the fit (default: none): fits stop by iteration "
        "counts fixed before the run, so the answer does not depend on the machine or its load; "
        "a fit that runs longer than the cap aborts with an error",
    )


def outputs(p):
    """calibrate's options: the outputs, the seed and what is printed."""
    p.add_argument(
        "--format",
        default=None,
        help="mesh format if the file name does not tell (meshio name or bc2000)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the optimiser (sa; >= 0)")
    p.add_argument(
        "--out", type=Path, required=True, metavar="MODEL.vtu", help="output network (VTU)"
    )
    p.add_argument(
        "--wide",
        action="store_true",
        help="print every column of the table (MODEL.csv always has them); default: the key "
        "columns, within 100 characters a line",
    )
    p.add_argument(
        "--save-case",
        dest="save_case",
        type=Path,
        default=None,
        metavar="CASE.toml",
        help="also write the case calibrate runs as a TOML case file (springbench run takes it)",
    )
    p.add_argument(
        "--quiet",
        action="store_true",
        help="no progress line (phase, elapsed time, ETA; never drawn when stderr is not a "
        "terminal)",
    )
