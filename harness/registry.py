"""Every pluggable part of springbench, by name: one :class:`Registry` per kind.

An entry is ``"module:attribute"`` (or ``"module"`` for parts that are modules: commands,
stages, benchmarks), imported only when used, so reading a case file or ``springbench
--help`` imports none of them. The case schema takes its vocabularies (``[optimizer]
method``, ``[model] classes``, ``[loads] set``, ...) from these names, so a new optimiser,
model class, load set, stiffness rule, mesh format, engine, stage, command, benchmark or
report table is one module and one line here. A name whose module fails to import raises:
nothing is skipped silently.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Any, Iterator, Mapping


@dataclass(frozen=True)
class Registry:
    """``kind`` (for messages), ``entries`` name -> "module[:attribute]", and per name
    whatever else its users read without importing it (``about``)."""

    kind: str
    entries: Mapping[str, str]
    about: Mapping[str, Any] = field(default_factory=dict)

    def names(self) -> tuple[str, ...]:
        return tuple(self.entries)

    def __iter__(self) -> Iterator[str]:
        return iter(self.entries)

    def __contains__(self, name) -> bool:
        return name in self.entries

    def __len__(self) -> int:
        return len(self.entries)

    def target(self, name: str) -> str:
        """The "module[:attribute]" of ``name`` (KeyError naming the known ones)."""
        if name not in self.entries:
            raise KeyError(f"unknown {self.kind} '{name}' (one of {', '.join(self.entries)})")
        return self.entries[name]

    def module(self, name: str) -> str:
        return self.target(name).partition(":")[0]

    def load(self, name: str):
        """The object ``name`` registers, its module imported (an ImportError propagates)."""
        module, _, attr = self.target(name).partition(":")
        mod = importlib.import_module(module)
        return getattr(mod, attr) if attr else mod

    def items(self):
        """(name, object) for every entry, each imported."""
        return [(name, self.load(name)) for name in self.entries]

    def with_entries(self, entries: Mapping[str, str]) -> Registry:
        """A registry of the same kind holding ``entries`` (tests, restricted runs)."""
        return Registry(
            self.kind, dict(entries), {k: v for k, v in self.about.items() if k in entries}
        )


def _modules(kind: str, package: str, names: str) -> Registry:
    return Registry(kind, {n: f"{package}.{n}" for n in names.split()})


# ``springbench COMMAND``: modules with HELP, add_arguments(parser), main(args) -> int
COMMANDS = _modules(
    "command",
    "harness.commands",
    "run validate reference build score calibrate pack engines bench report rules",
)

# ``springbench run``: stage modules in pipeline order (NAME, applies, run[, check]);
# keyed by NAME, the case files' ``[run] stages``
STAGES = Registry(
    "stage",
    {
        "reference": "harness.stages.reference_check",  # FEM reference + its verification
        "sms": "harness.stages.sms",  # spring/mass build + score + optimise
        "bc2000": "harness.stages.bc2000",  # Bourguignon & Cani experiments
        "engines": "harness.stages.engines",  # engines' deformable bodies against the FEM
    },
)

# ``springbench bench NAME``: modules with run(quick) -> DataFrame
BENCHES = _modules(
    "benchmark",
    "harness.bench",
    "reference sa fit dynamics calibrate heldout tets engines shapes run",
)

# ``[optimizer] method``: function(problem, options, seed, status) -> FitResult fields
OPTIMIZERS = Registry(
    "optimiser",
    {
        "sa": "harness.optimize.annealing:sa",  # Deussen 1995 Fig. 6, incremental G
        # the same chain, every proposal re-factorised (the paper's cost; baseline)
        "sa-refactor": "harness.optimize.annealing:sa_refactor",
        "lbfgs": "harness.optimize.gradient:lbfgs",  # adjoint gradient, L-BFGS-B over log k
        "nelder-mead": "harness.optimize.gradient:nelder_mead",  # derivative-free (few groups)
        # Levenberg-Marquardt, CG on adjoint products
        "gauss-newton": "harness.optimize.gauss_newton:gauss_newton",
        # the equation error: one sparse linear least squares
        "equilibrium-gap": "harness.optimize.equilibrium:equilibrium_gap",
        "none": "harness.optimize.keep:keep",  # k0 as it is (the unoptimised row)
    },
)

# ``[model] classes`` and ``calibrate --model``: the model classes scored on the nodes of a case
# (ModelClass objects, harness/stages/classes/); ``about``: (its model, where its constants live)
MODEL_CLASSES = Registry(
    "model class",
    {
        "springs": "harness.stages.classes.springs:SPRINGS",
        "springs+volume-shared": "harness.stages.classes.springs:VOLUME_SHARED",
        "springs+volume-element": "harness.stages.classes.springs:VOLUME_ELEMENT",
        "springs+node-volume-shared": "harness.stages.classes.springs:NODE_VOLUME_SHARED",
        "springs+node-volume-node": "harness.stages.classes.springs:NODE_VOLUME_NODE",
        "springs+kn": "harness.stages.classes.springs:KN_SHARED",
        "springs+kn-node": "harness.stages.classes.springs:KN_NODE",
        "p1": "harness.stages.classes.p1_element:P1",
        "p1-global": "harness.stages.classes.p1_global:P1_GLOBAL",
        "mt": "harness.stages.classes.mt:MT",
    },
    about={
        "springs": ("springs on the model's edges", "one k per spring"),
        "springs+volume-shared": (
            "springs + a volume energy per tetrahedron (2-D: triangle) of the model's cells "
            "(harness/models/volume.py)",
            "one kv for the body",
        ),
        "springs+volume-element": (
            "springs + a volume energy per tetrahedron (2-D: triangle) of the model's cells "
            "(harness/models/volume.py)",
            "one kv per element",
        ),
        "springs+node-volume-shared": (
            "springs + a volume energy per node on its share of its elements' volume change, "
            "no locking under clamps (harness/models/volume.py)",
            "one kv for the body",
        ),
        "springs+node-volume-node": (
            "springs + a volume energy per node on its share of its elements' volume change, "
            "no locking under clamps (harness/models/volume.py)",
            "one kv per node",
        ),
        "springs+kn": (
            "springs + the adjustable-Poisson term of Kot & Nagahashi 2015 per node "
            "(harness/models/kn.py)",
            "one kn for the body",
        ),
        "springs+kn-node": (
            "springs + the adjustable-Poisson term of Kot & Nagahashi 2015 per node "
            "(harness/models/kn.py)",
            "one kn per node",
        ),
        "p1": (
            "linear finite elements on the model's cells (harness/models/p1.py), a material "
            "per element for an engine's tetrahedra (harness/stages/classes/p1_element.py)",
            "one E and one nu per element, with a prior toward the case's",
        ),
        "p1-global": (
            "linear finite elements on the model's cells with one effective isotropic material, "
            "the (E, nu) to give an engine's tetrahedra (harness/stages/classes/p1_global.py)",
            "one E and one nu fitted for the body",
        ),
        "mt": (
            "Bourguignon & Cani's element model on the model's cells, 3-D (harness/models/mt.py)",
            "three moduli fitted for the body",
        ),
    },
)
# the classes of springs with or without one extra term: the ones calibrate --model fits
SPRINGS_CLASSES = tuple(
    n for n in MODEL_CLASSES if MODEL_CLASSES.module(n) == "harness.stages.classes.springs"
)
# calibrate --model: the springs classes and the classes of a fitted material
CALIBRATE_CLASSES = SPRINGS_CLASSES + ("p1-global", "p1")
# spellings that could mean two classes: refused, naming both
AMBIGUOUS_CLASSES = {
    "springs+volume": ("springs+volume-shared", "springs+volume-element"),
    "springs+node-volume": ("springs+node-volume-shared", "springs+node-volume-node"),
}


def class_doc(name: str) -> str:
    """What model class ``name`` is: its model and where its constants live."""
    model, constants = MODEL_CLASSES.about[name]
    return f"{model}, {constants}"


def ambiguous_class(name: str) -> str | None:
    """The one-line refusal of a spelling in AMBIGUOUS_CLASSES (None for any other)."""
    if name not in AMBIGUOUS_CLASSES:
        return None
    a, b = AMBIGUOUS_CLASSES[name]
    about = MODEL_CLASSES.about
    return f"'{name}' is ambiguous: {a} ({about[a][1]}) or {b} ({about[b][1]})"


# ``[model] stiffness``: rule(points, springs, cells, material) -> k
STIFFNESS_RULES = Registry(
    "stiffness rule",
    {
        "deussen": "harness.models.stiffness_rules:deussen",
        "vangelder": "harness.models.stiffness_rules:vangelder",
        "lloyd": "harness.models.stiffness_rules:lloyd",
        "uniform": "harness.models.stiffness_rules:uniform",
        "cauchy": "harness.models.stiffness_rules:cauchy",
        "learned": "harness.models.stiffness_rules:learned",
    },
)

# ``[loads] set``: make(s, anchors, frame) -> loads; ``about``: the set's dimension
LOAD_SETS = Registry(
    "load set",
    {
        "basic2d": "harness.case.loadsets:basic2d",  # Deussen 1995 Fig. 4
        "basic3d": "harness.case.loadsets:basic3d",  # Deussen 1995 Fig. 7
        "homogeneous2d": "harness.case.loadsets:homogeneous2d",  # constant stress states
        "homogeneous3d": "harness.case.loadsets:homogeneous3d",
        "linear2d": "harness.case.linear_states:linear2d",  # + equilibrated linear stress states
        "linear3d": "harness.case.linear_states:linear3d",
    },
    about={
        "basic2d": 2,
        "basic3d": 3,
        "homogeneous2d": 2,
        "homogeneous3d": 3,
        "linear2d": 2,
        "linear3d": 3,
    },
)

# region spellings of --clamp / --load-region / [body.parts] facets (a group's name otherwise):
# test(selector, points, tol) -> mask of the nodes inside; ``about``: the right spelling
REGION_SELECTORS = Registry(
    "region selector",
    {
        "nodes": "harness.case.selectors:nodes",
        "box": "harness.case.selectors:box",
        "sphere": "harness.case.selectors:sphere",
    },
    about={
        "nodes": "nodes:FILE of node ids, 0-based, one a line or comma-separated",
        "box": "box:XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX or in 2-D box:XMIN,YMIN,XMAX,YMAX",
        "sphere": "sphere:X,Y,Z,R or in 2-D the circle sphere:X,Y,R",
    },
)

# mesh formats of our own (any other name is a meshio format): reader(path) -> Mesh
MESH_READERS = Registry(
    "mesh format",
    {"bc2000": "harness.io.meshfile:read_bc2000", "meshio": "harness.io.meshfile:read_meshio"},
)

# ``ENGINE`` / ``[model] engines``: adapter(pack, options) -> {load: Answer};
# ``about``: (the package it needs, what it runs)
ENGINES = Registry(
    "engine",
    {
        "newton-springs": "harness.engines.newton_engine:run_springs",
        "newton-tets": "harness.engines.newton_engine:run_tets",
        "mujoco-flex": "harness.engines.mujoco_flex:run",
        "pybullet-fem": "harness.engines.pybullet_fem:run",
        "drake-fem": "harness.engines.drake_fem:run",
        "mujoco-springs": "harness.engines.mujoco_springs:run",
    },
    about={
        "newton-springs": (
            "newton",
            "a springbench export (--model MODEL.json) as NVIDIA Newton particles, springs "
            "and (a volume term per element) tetrahedra",
        ),
        "newton-tets": (
            "newton",
            "NVIDIA Newton's own tetrahedral FEM (stable Neo-Hookean, k_mu / k_lambda from E "
            "and nu)",
        ),
        "mujoco-flex": ("mujoco", "MuJoCo's 3-D flex with its own elasticity (young, poisson)"),
        "pybullet-fem": (
            "pybullet",
            "Bullet's FEM soft body (Neo-Hookean, k_mu / k_lambda from E and nu; uniform node "
            "masses; gravity loads only)",
        ),
        "drake-fem": (
            "pydrake",
            "Drake's FEM deformable body (kLinear tetrahedra, E and nu; gravity loads only)",
        ),
        "mujoco-springs": (
            "mujoco",
            "a springbench export (--model MODEL.json, springs only) as MuJoCo bodies with "
            "slide joints and spatial tendons",
        ),
    },
)

# the pip name of each engine package whose import name differs (as pyproject's deptry map)
PIP_NAMES = {"pydrake": "drake", "warp": "warp-lang"}

# the engines that run a springbench export (``--model MODEL.json``), not E and nu
EXPORT_ENGINES = ("newton-springs", "mujoco-springs")
# the engines whose own tetrahedra run a calibrated material (engines run --model: a
# p1 or p1-global export; mujoco-flex one material per body)
MATERIAL_ENGINES = ("newton-tets", "mujoco-flex")


# ``[model] exports`` of an engines case: springbench's models of the mesh, each made by
# ``springbench calibrate`` with ``flags`` and run by ``engines`` (engines run ENGINE --model)
@dataclass(frozen=True)
class EngineExport:
    """calibrate's flags that make the export, the engines that run it, what it is."""

    flags: tuple
    engines: tuple
    about: str


ENGINE_EXPORTS = {
    "rule": EngineExport(
        ("--method", "rule"),
        ("newton-springs", "mujoco-springs"),
        "the best stiffness rule (calibrate --method rule)",
    ),
    "calibrated": EngineExport((), ("newton-springs",), "calibrate's default (its validated fit)"),
    "calibrated-mujoco": EngineExport(
        ("--engine", "mujoco-springs"),
        ("mujoco-springs",),
        "the validated fit among what MuJoCo's tendons run (calibrate --engine mujoco-springs)",
    ),
    "p1-global": EngineExport(
        ("--model", "p1-global"),
        ("mujoco-flex", "newton-tets"),
        "one fitted (E', nu') for the engines' tetrahedra (calibrate --model p1-global)",
    ),
    "p1": EngineExport(
        ("--model", "p1"),
        ("newton-tets",),
        "a fitted material per tetrahedron (calibrate --model p1)",
    ),
}
# the terms each export engine runs natively, spelled as the validated fit's candidates
# spell their volume term (harness/optimize/select.py Candidate.volume): '' springs alone,
# 'element' a volume term per element, 'node' one per node ('kn': Kot & Nagahashi's term)
EXPORT_TERMS = {"newton-springs": ("", "element", "node"), "mujoco-springs": ("",)}
# why each export engine runs those terms and no others (calibrate --engine's line)
EXPORT_TERMS_WHY = {
    "newton-springs": "Newton runs a volume term per element as tetrahedra with k_mu = 0, one "
    "per node by harness/engines/newton_volume.py, no kn term",
    "mujoco-springs": "MuJoCo's tendons carry springs only",
}
# each term in words, as EXPORT_TERMS spells it
TERMS = {
    "": "springs alone",
    "element": "a volume term per element",
    "node": "a volume term per node",
    "kn": "Kot & Nagahashi's kn term",
}
# the term each springs class of calibrate --model adds, as EXPORT_TERMS spells it
CLASS_TERMS = {
    "springs": "",
    "springs+volume-shared": "element",
    "springs+volume-element": "element",
    "springs+node-volume-shared": "node",
    "springs+node-volume-node": "node",
    "springs+kn": "kn",
    "springs+kn-node": "kn",
}

# ``[reference] solver`` and ``calibrate --solver``: the FEM's linear solver, name -> what it
# tries first; reference/solvers/plan.py turns a name into the steps reference/solvers/sparse.py
# tries in turn (an iterative one falls back to a stronger one, at last to a direct solve)
SOLVERS = {
    "auto": "per system the cheaper of the multifrontal Cholesky and an iterative method",
    "direct": "the multifrontal Cholesky (SuperLU where the dofs' locations are unknown)",
    "cholesky": "the same as direct",
    "superlu": "SuperLU",
    "amg": "CG preconditioned by smoothed-aggregation AMG with the rigid-body modes",
    "cg": "Jacobi-preconditioned CG",
    "two-level": "P2/Q2: CG preconditioned by Gauss-Seidel and an exact P1/Q1 solve",
    "tensor": "graded boxes: CG with the fast-diagonalisation preconditioner at any size",
}

# ``[dynamics] experiment`` of the bc2000 stage: function(case, ctx, model, dyn) -> rows
EXPERIMENTS = Registry(
    "bc2000 experiment",
    {
        "run": "harness.stages.bc2000:plain",
        "volume": "harness.stages.bc2000:volume",
        "pull": "harness.stages.bc2000:pull",
        "cantilever": "harness.stages.bc2000:cantilever",
        "fibres": "harness.stages.bc2000:fibres",
        "timing": "harness.stages.bc2000:timing",
        "fem": "harness.stages.bc2000_fem:fem",
    },
)

# the results page's tables of a suite folder: function(summary DataFrame) -> tables
# (suites not named here get harness.report.headlines:generic_tables)
REPORT_TABLES = Registry(
    "report table",
    {
        "deussen1995": "harness.report.headlines:deussen_tables",
        "bourguignon2000": "harness.report.headlines_bc2000:bc2000_tables",
        "verification": "harness.report.headlines:verification_tables",
        "engines": "harness.report.engines:engines_tables",
    },
)

ALL = (
    COMMANDS,
    STAGES,
    BENCHES,
    OPTIMIZERS,
    MODEL_CLASSES,
    STIFFNESS_RULES,
    LOAD_SETS,
    REGION_SELECTORS,
    MESH_READERS,
    ENGINES,
    EXPERIMENTS,
    REPORT_TABLES,
)
