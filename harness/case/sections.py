"""Schemas of the case-file sections that later stages own. One entry per section;
the stage that reads a section owns its spec here. Free-form keys ("any") are
validated by their owner when the stage runs."""

from harness import registry
from harness.case.schema import Field
from harness.case.selectors import spelling_problem

# The vocabularies of the pluggable parts are the registries' names (harness/registry.py):
# reading a case imports none of them.
OPTIMIZER_METHODS = registry.OPTIMIZERS.names()  # [optimizer] method / compare
_METHODS = OPTIMIZER_METHODS
_COMPARE = tuple(m for m in OPTIMIZER_METHODS if m != "none")

# [optimizer.select] candidates: the model capacities a validated fit chooses among, labels of
# the validation, not model classes ('+volume', '+node-volume': terms sharing one kv);
# harness/optimize/select.py's CANDIDATES must hold exactly these names (it checks at import)
SELECT_CANDIDATES = (
    "scale",
    "groups",
    "springs-prior10",
    "springs-prior1",
    "springs-prior0.1",
    "scale+volume",
    "springs-prior1+volume",
    "springs-prior0.1+volume",
    "features",
    "features+volume",
    "scale+node-volume",
    "springs-prior1+node-volume",
    "springs-prior0.1+node-volume",
)
# how a candidate must beat the rule (harness/optimize/select.py choose)
SELECT_CRITERIA = ("ratio", "score")
# the validated fit's counts: within a budget from the mesh, or as set (select_counts.py)
SELECT_WORK = ("budget", "fixed")
SELECT_DEFAULT = (
    "springs-prior1",
    "springs-prior0.1",
    "springs-prior1+node-volume",
    "springs-prior0.1+node-volume",
)

# [model] kind = "sms": spring/mass systems of Deussen 1995 (harness/models/sms.py)
PLACEMENTS = ("grid", "random", "lloyd", "mesh")
MASS_RULES = ("moments", "moments-nonneg", "voronoi", "uniform", "lumped")
STIFFNESS_RULES = registry.STIFFNESS_RULES.names()
MODEL_CLASSES = registry.MODEL_CLASSES.names()  # [model] classes: scored on the same nodes

SMS = {
    "placement": Field(
        "str",
        "grid",
        choices=PLACEMENTS,
        doc="grid | random | lloyd (random + Lloyd iterations) | mesh (the body mesh's nodes)",
    ),
    "grid": Field(
        "any",
        None,
        doc="nodes per axis [nx, ny(, nz)] for placement = 'grid'",
        check=lambda v: (
            None
            if (
                isinstance(v, list)
                and len(v) in (2, 3)
                and all(isinstance(x, int) and not isinstance(x, bool) and x >= 2 for x in v)
            )
            else "expected 2 or 3 integers >= 2 (nodes per axis)"
        ),
    ),
    "structure": Field(
        "str",
        None,
        doc="grid structure: structure1, edges+diagonal, edges+diagonals+second, "
        "edges (2-D); edges+face+body, edges+face, edges+body (3-D)",
    ),
    "n_points": Field("int", None, min=4, doc="number of points for random / lloyd placement"),
    "n_boundary": Field(
        "int", None, min=0, doc="random points on the boundary (2-D; default: matched spacing)"
    ),
    "lloyd_iterations": Field(
        "int", 0, min=0, doc="Lloyd (iterated Voronoi) steps for placement = 'lloyd'"
    ),
    "seed": Field(
        "int", 0, min=0, doc="seed of the random placement (>= 0, added to the run's seed)"
    ),
    "masses": Field("str", "moments", choices=MASS_RULES),
    "stiffness": Field(
        "strs",
        ("deussen",),
        choices=STIFFNESS_RULES,
        doc="initial spring-constant rule(s); the first one starts the optimiser",
    ),
    "grouped": Field(
        "bool",
        False,
        doc="optimise one constant per spring group (Fig. 8: horizontal, "
        "vertical, diagonal) instead of one per spring",
    ),
    "min_quality": Field(
        "float", 1e-3, min=0, max=1, doc="Delaunay simplices below this quality are dropped"
    ),
    "mesh": Field(
        "str",
        None,
        doc="placement = 'mesh': a mesh file (relative to the case file) whose nodes and "
        "edges form the network; default: the body's own mesh",
    ),
    "mesh_format": Field(
        "str", None, doc="meshio format name or 'bc2000' for model.mesh; guessed if absent"
    ),
    "volume": Field(
        "str",
        "none",
        choices=("none", "element", "shared", "node", "node-shared"),
        doc="springs + volume (harness/models/volume.py): a volume energy (kv/2)(V - V0)^2/V0 per "
        "tetrahedron (2-D: triangle) of the model's cells, kv fitted with the springs, one per "
        "element or shared by the body; 'node', 'node-shared': per node, on its share of its "
        "elements' volume change (no locking under clamps); needs cells (placement mesh, "
        "random or lloyd)",
    ),
    "kn": Field(
        "str",
        "none",
        choices=("none", "node", "shared"),
        doc="springs + the adjustable-Poisson term of Kot & Nagahashi 2015 "
        "(harness/models/kn.py): per "
        "node (kn/2) V d^2 s^2, s the node's mean spring strain, kn (Pa; 2-D N/m) fitted with the "
        "springs, one per node or shared by the body; needs cells; not with volume",
    ),
    "classes": Field(
        "any",  # a list of names, checked here: an ambiguous spelling gets its own message
        (),
        choices=MODEL_CLASSES,
        check=lambda v: _classes_problem(v),
        doc="score several model classes on the same nodes, one after the other: "
        + ", ".join(MODEL_CLASSES)
        + " (harness/registry.py MODEL_CLASSES: each one's model and constants); overrides "
        "volume and kn; rows carry model_class",
    ),
    "kv": Field(
        "float",
        None,
        min=0,
        min_exclusive=True,
        doc="initial volume constant (Pa; 2-D N/m); default: the material's bulk modulus "
        "beyond its "
        "Cauchy-ratio value, at least 5 % of it",
    ),
}

# [model] kind = "bc2000": Bourguignon & Cani 2000 (harness/models/anisotropic.py,
# massspring.py). Damping constants are the program's per-step ones unless
# damping_units = "physical" (kd_physical = kd * dt).
BC2000 = {
    "models": Field(
        "strs",
        ("MS", "MT0", "MT"),
        choices=("MS", "MT0", "MT"),
        doc="MS classic springs on mesh edges, MT0 the element model without and MT with "
        "volume forces",
    ),
    "ks": Field(
        "floats", (2.5,), length=(1, 6), min=0, doc="ks1..ks6 (3 axial, 3 angular) or one value"
    ),
    "kd": Field("floats", (10.0,), length=(1, 3), min=0, doc="kd1..kd3 axial damping or one value"),
    "kvs": Field("float", 5.0, min=0, doc="volume stiffness"),
    "kvd": Field("float", 10.0, min=0, doc="hexa radial-spring damping"),
    "ms_ks": Field("float", 2.5, min=0, doc="classic spring stiffness"),
    "ms_kd": Field("float", 10.0, min=0, doc="classic spring damping"),
    "damping_units": Field("str", "per-step", choices=("per-step", "physical")),
    "rest_angle": Field(
        "str",
        "program",
        choices=("program", "rest"),
        doc="angular springs: 90 degrees (program) or the rest shape's angles",
    ),
    "fibre_field": Field(
        "str",
        None,
        choices=("vertical", "horizontal", "diagonal", "hemicircular", "helicoidal", "random"),
    ),
    "fibre_fields": Field(
        "strs",
        (),
        choices=("vertical", "horizontal", "diagonal", "hemicircular", "helicoidal", "random"),
        doc="one run per field (Fig. 6)",
    ),
    "fibre_origin": Field(
        "floats", None, length=2, doc="centre of the hemicircular/helicoidal field"
    ),
    "azimuth_deg": Field("float", None),
    "elevation_deg": Field("float", None),
    "direction": Field("floats", None, length=3),
    "seed": Field("int", 0, min=0, doc="seed of the random fibre field (>= 0)"),
    "mass": Field("float", 0.01, min=0, min_exclusive=True, doc="kg per node"),
}

# [dynamics]: time integration of the bc2000 experiments (harness/stages/bc2000.py)
DYNAMICS = {
    "experiment": Field("str", "run", choices=registry.EXPERIMENTS.names()),
    "calibrate": Field("bool", True, doc="fem: fit the model's constants to the FEM reference"),
    "dt": Field("float", 0.01, min=0, min_exclusive=True, doc="time step (s)"),
    "hexa_model_dt": Field(
        "float",
        None,
        min=0,
        min_exclusive=True,
        doc="time step of the element model on hexa meshes (the program's 0.004 s)",
    ),
    "steps": Field("int", 1000, min=0),
    "duration": Field(
        "float", None, min=0, doc="simulated time (s); overrides steps (steps = duration / dt)"
    ),
    "original": Field(
        "str", None, doc="the original program's volume file (relative to the case) to compare with"
    ),
    "integrator": Field("str", "verlet", choices=("verlet", "symplectic-euler", "backward-euler")),
    "gravity": Field("floats", (0.0, -9.8, 0.0), length=3),
    "push": Field(
        "floats", (0.0, -1.0, 0.0), length=3, doc="force (N) on each pulled node (flag 2)"
    ),
    "drag": Field(
        "float", 5e-3, min=0, doc="drag per step (the program's 5e-3), physical drag * dt"
    ),
    "meshes": Field(
        "strs", (), doc="more meshes (relative to the case file) run with the same settings"
    ),
    "snapshots": Field(
        "any",
        [],
        doc="step numbers whose particle states are written",
        check=lambda v: (
            None
            if isinstance(v, list)
            and all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in v)
            else "expected a list of step numbers (integers >= 0)"
        ),
    ),
    "static": Field("bool", False, doc="also solve the static equilibrium (Newton)"),
    "repeats": Field("int", 3, min=1, doc="timing repeats (best of)"),
}

# [model] kind = "engines": engines' deformable bodies against the FEM (harness/stages/engines.py)
ENGINE_NAMES = registry.ENGINES.names()
EXPORTS = ("rule", "calibrated")  # the default of [model] exports
PACK_LOADS = ("sag", "tip", "tip2", "torsion", "bridge")
ENGINES = {
    "body": Field("str", None, doc="the body's name in the table (default: the mesh file's stem)"),
    "resolution": Field("str", "", doc="the mesh's resolution label in the table, e.g. coarse"),
    "clamp": Field(
        "str",
        doc="region held in every load (springbench pack --clamp): a mesh group, nodes:FILE, "
        "box:... or sphere:...",
        check=spelling_problem,
    ),
    "load_region": Field(
        "str",
        doc="region the tip loads and the torsion act on (pack --load-region): as clamp",
        check=spelling_problem,
    ),
    "loads": Field(
        "strs", PACK_LOADS, choices=PACK_LOADS, doc="the pack's held-out loads run and scored"
    ),
    "peak_strain": Field(
        "float", 1e-3, min=0, min_exclusive=True, doc="the loads' size (pack --peak-strain)"
    ),
    "engines": Field(
        "strs",
        ("newton-tets", "mujoco-flex"),
        choices=tuple(n for n in ENGINE_NAMES if n not in registry.EXPORT_ENGINES),
        doc="engines run with their own model from E and nu (springbench engines run ENGINE)",
    ),
    "exports": Field(
        "strs",
        EXPORTS,
        choices=tuple(registry.ENGINE_EXPORTS),
        doc="springbench's models of the mesh, each run by the engines that take it: "
        + "; ".join(
            f"{n} ({e.about}; {', '.join(e.engines)})" for n, e in registry.ENGINE_EXPORTS.items()
        ),
    ),
    "budget": Field(
        "float",
        15.0,
        min=0,
        min_exclusive=True,
        doc="not used: the calibrated export's fit stops by iteration counts, the same on any "
        "machine (read so that case files setting it stay valid)",
    ),
}

# [model] kind = "..." selects the spec of the other keys; each model owner adds its kind.
MODEL_KINDS: dict[str, dict[str, Field]] = {
    "sms": SMS,  # spring/mass systems of Deussen 1995 (harness/models/sms.py)
    "bc2000": BC2000,  # the anisotropic element model of Bourguignon & Cani 2000
    "engines": ENGINES,  # engines' own models and springbench's exports against the FEM
}

SECTIONS: dict[str, dict[str, Field] | str] = {
    # [model]: how the spring/mass system or element model is built (harness/models)
    # keys depend on kind: see MODEL_KINDS
    "model": "model",
    # [optimizer]: spring-constant calibration (harness/optimize)
    "optimizer": {
        "method": Field(
            "str",
            "none",
            choices=_METHODS,
            doc="harness.optimize.OPTIMIZERS: sa = Deussen Fig. 6 annealing (incremental), "
            "sa-refactor = same, re-factorising per proposal, lbfgs / gauss-newton = adjoint "
            "gradient fits, nelder-mead = grouped mode, none = keep the initial constants",
        ),
        "options": Field(
            "any",
            {},
            doc="method options, checked by the optimiser (unknown keys are errors); "
            "see harness/optimize/annealing.py DEFAULTS and gradient.py *_DEFAULTS",
        ),
        "start": Field(
            "str",
            "first",
            choices=("first", "best"),
            doc="the fits start from the first rule of [model] stiffness (first) or from the rule "
            "with the lowest G on the fitted loads (best)",
        ),
        "compare": Field(
            "strs",
            (),
            choices=_COMPARE,
            doc='e.g. compare = ["lbfgs", "gauss-newton"]: more optimisers on the same '
            "initial model, "
            "reference and weights, one row each",
        ),
        "compare_options": Field(
            "any",
            {},
            check=lambda v: _compare_options_problem(v),
            doc="options per compared method, e.g. compare_options = { lbfgs = { maxiter = 500 } }",
        ),
        "select": Field(
            "table",
            None,
            spec={
                "candidates": Field(
                    "strs",
                    SELECT_DEFAULT,
                    choices=SELECT_CANDIDATES,
                    doc="the capacities validated (harness/optimize/select.py), besides the rule",
                ),
                "maxiter": Field(
                    "int", 30, min=1, doc="iterations of each validation fit (or evaluations)"
                ),
                "starts": Field(
                    "int",
                    1,
                    min=1,
                    max=10,
                    doc="starts of the final fit (the rule; then its best global "
                    "scale, perturbed ones): with two or more the spread is reported",
                ),
                "work": Field(
                    "str",
                    "budget",
                    choices=SELECT_WORK,
                    doc="budget: the counts above while their predicted factorisation work "
                    "fits twice the rules' statics (or 3,000 Gflop), else fewer candidates, "
                    "folds, iterations and starts, chosen from the mesh before the fit "
                    "(harness/optimize/select_counts.py); fixed: the counts above at any size",
                ),
                "criterion": Field(
                    "str",
                    "ratio",
                    choices=SELECT_CRITERIA,
                    doc="ratio: the lowest geometric mean of a candidate's free-traction "
                    "and clamped "
                    "validation errors each relative to the rule's, below 0.99; score: the lowest "
                    "mean of the two that beats the rule's by 1 % and is no worse on the clamped "
                    "states",
                ),
            },
            doc="choose the fit's capacity by leave-one-family-out validation on the fitted "
            "loads (families: "
            "the linear sets' and 'clamped'); the rule when nothing beats it (method = "
            "'lbfgs' only)",
        ),
        "frequency": Field(
            "table",
            None,
            spec={
                "modes": Field(
                    "int",
                    4,
                    min=1,
                    doc="the first k natural frequencies in the objective (<= [reference] modes)",
                ),
                "weight": Field(
                    "float",
                    1.0,
                    min=0,
                    min_exclusive=True,
                    doc="weight of sum_j (f_j / f_FEM_j - 1)^2 beside G^2 / G(k0)^2",
                ),
                "method": Field(
                    "str",
                    "lbfgs",
                    choices=("lbfgs",),
                    doc="the optimiser that takes the frequency term",
                ),
                "options": Field("any", {}, doc="options of that optimiser"),
            },
            doc="an extra row fitting G and the first modes' frequencies to the FEM ones",
        ),
    },
    # [score]: G criteria weights (harness/scoring)
    "score": {
        "weights": Field(
            "floats",
            (1.0, 1.0, 1.0),
            length=3,
            min=0,
            check=lambda v: None if any(v) else "all zero (G would be 0/0)",
            doc="G_{a:b:c} weights: inner, border, corner, not all zero",
        )
    },
    # [expect]: the paper's numbers, reported beside ours
    "expect": {
        "source": Field("str", ""),
        "values": Field(
            "any",
            {},
            check=lambda v: _values_problem(v),
            doc="the paper's numbers by column, e.g. values = { G_final = 0.47 }, or by model, "
            "e.g. values = { MT = { peak_abs_dV_percent = 1.5 } }",
        ),
    },
    # [dynamics]: time integration settings of the bc2000 experiments
    "dynamics": DYNAMICS,
    # [run]: what `springbench run` does with the case and its seeds
    "run": {
        "seeds": Field(
            "any",
            [0],
            check=lambda v: _seeds_problem(v),
            doc="an integer >= 0 or a list of distinct ones, e.g. seeds = [0, 1, 2]",
        ),
        "stages": Field("strs", ()),
    },
}


def _seeds_problem(v):
    """[run] seeds (the runner's entry): an integer >= 0 or a non-empty list of distinct ones."""

    def ok(s):
        return isinstance(s, int) and not isinstance(s, bool) and s >= 0

    seeds = [v] if ok(v) else v
    if not isinstance(seeds, list) or not seeds or not all(ok(s) for s in seeds):
        return f"expected an integer >= 0 or a non-empty list of them, got {v!r}"
    if len(set(seeds)) != len(seeds):
        return "repeated seed"
    return None


def _values_problem(v, depth=0):
    """[expect] values: a table of numbers, or (one level down) of tables of numbers."""
    if not isinstance(v, dict):
        return "expected a table of numbers, e.g. { G_final = 0.47 }"
    for name, x in v.items():
        if isinstance(x, dict) and depth == 0:
            problem = _values_problem(x, 1)
            if problem:
                return f"{name}: {problem}"
        elif not (isinstance(x, (int, float)) and not isinstance(x, bool)):
            return f"{name}: expected a number, got {x!r}"
    return None


def _compare_options_problem(v):
    """[optimizer] compare_options: a table of option tables keyed by optimiser name."""
    if not isinstance(v, dict):
        return "expected a table { method = { option = value } }"
    for m, o in v.items():
        if m not in _COMPARE:
            return f"'{m}' is not one of {', '.join(_COMPARE)}"
        if not isinstance(o, dict):
            return f"options of '{m}' must be a table"
    return None


def _classes_problem(v):
    """[model] classes: a list of model class names (an ambiguous spelling says so)."""
    if not isinstance(v, list) or not all(isinstance(s, str) for s in v):
        return "expected a list of model class names"
    bad = [s for s in v if s not in MODEL_CLASSES]
    if bad:
        why = registry.ambiguous_class(bad[0])
        return why or f"'{bad[0]}' is not one of {', '.join(MODEL_CLASSES)}"
    return None
