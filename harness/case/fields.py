"""The case file's schema: the fields of the core sections (body, material, loads,
reference) and of the top level, each a :class:`harness.case.schema.Field`. The sections
that later stages own are in :mod:`harness.case.sections`; docs/case-files.md documents
every key."""

from __future__ import annotations

from harness import registry
from harness.case.fibres import NAMED_FIELDS
from harness.case.schema import Field

BODY = {
    "shape": Field(
        "str",
        choices=("rectangle", "box", "polygon", "mesh"),
        doc="rectangle (2-D), box (3-D), polygon (2-D) or mesh",
    ),
    "origin": Field("floats", None, length=(2, 3)),
    "size": Field("floats", None, length=(2, 3), min=0, min_exclusive=True, doc="positive extents"),
    "vertices": Field("matrix", None, doc="polygon vertices [[x, y], ...] in order"),
    "file": Field("str", None, doc="mesh file, relative to the case file"),
    "format": Field("str", None, doc="meshio format name or 'bc2000'; guessed if absent"),
    "parts": Field(
        "any",
        {},
        doc="named boxes: name = {box = [[lo...], [hi...]]}, mesh groups: "
        'name = {group = "physical group"}, or a mesh\'s end faces: name = '
        '{end = "x1", band = 0.05, cos = 0.5} (boundary facets within band x the '
        "extent of that end whose outward normals point along the axis, cos >= cos)",
    ),
}

FIBRE = {
    "E_fibre": Field("float", min=0, min_exclusive=True, doc="Young's modulus along the fibre"),
    "E_cross": Field("float", min=0, min_exclusive=True, doc="Young's modulus across the fibre"),
    "nu_fibre": Field(
        "float",
        None,
        min=-1,
        max=0.5,
        min_exclusive=True,
        doc="major Poisson ratio nu_LT (strain across / strain along); default nu",
    ),
    "nu_cross": Field(
        "float",
        None,
        min=-1,
        max=1,
        min_exclusive=True,
        max_exclusive=True,
        doc="Poisson ratio in the isotropic cross plane nu_TT; default nu",
    ),
    "G_fibre": Field(
        "float",
        None,
        min=0,
        min_exclusive=True,
        doc="shear modulus G_LT; default E_fibre E_cross / (E_fibre + E_cross (1 + 2 nu_fibre))",
    ),
    "direction": Field("floats", None, length=(2, 3)),
    "azimuth_deg": Field("float", None),
    "elevation_deg": Field("float", None),
    "field": Field("str", None, choices=NAMED_FIELDS),
    "seed": Field("int", 0, min=0, doc="seed of a random fibre field (>= 0)"),
}

REGION = {
    "box": Field("matrix", doc="[[lo...], [hi...]]"),
    "E": Field("float", min=0, min_exclusive=True, doc="Young's modulus > 0"),
    "nu": Field("float", None, min=-1, max=0.5, min_exclusive=True, max_exclusive=True),
    "density": Field("float", None, min=0, min_exclusive=True),
}

MATERIAL = {
    "E": Field("float", min=0, min_exclusive=True, doc="Young's modulus > 0"),
    "nu": Field(
        "float",
        min=-1,
        max=0.5,
        min_exclusive=True,
        max_exclusive=True,
        doc="Poisson ratio in (-1, 0.5)",
    ),
    "density": Field("float", 1.0, min=0, min_exclusive=True),
    "plane": Field("str", "stress", choices=("stress", "strain")),
    "fibre": Field("table", None, spec=FIBRE),
    "regions": Field("tables", (), spec=REGION),
}

COMPONENTS = ("x", "y", "z", "all")
CONSTRAINT = {"part": Field("str"), "components": Field("strs", ("all",), choices=COMPONENTS)}
TRACTION = {
    "part": Field("str"),
    "vector": Field("floats", None, length=(2, 3)),
    "twist": Field(
        "floats", None, length=3, doc="w: adds w x (x - c), c the part's centroid (torsion)"
    ),
}
USER_LOAD = {
    "name": Field("str"),
    "constraint": Field("tables", (), spec=CONSTRAINT),
    "traction": Field("tables", (), spec=TRACTION),
    "gravity": Field("floats", None, length=(2, 3), doc="acceleration, e.g. [0, -9.81]"),
    "body_force": Field("floats", None, length=(2, 3), doc="force per volume"),
}
LOADS = {
    "set": Field("str", None, choices=registry.LOAD_SETS.names()),
    "magnitude": Field(
        "float",
        1.0,
        doc="traction s of the standard set (stress units), not 0",
        check=lambda v: "a zero traction moves nothing (G would be 0/0)" if v == 0 else None,
    ),
    "case": Field("tables", (), spec=USER_LOAD),
    "fit": Field(
        "strs", None, doc="the load cases a fit may use (default: all that are not held out)"
    ),
    "heldout": Field("strs", None, doc="load cases scored only (G_heldout), never fitted"),
    "validation": Field(
        "strs",
        None,
        doc="load cases never fitted that decide whether a validated fit beats every rule "
        "(G_val_mean); never held out",
    ),
    "rank_by": Field(
        "strs",
        None,
        doc="fitted load cases the rules are ranked by first (G_rank_score: the mean of "
        "their own normalised G, a name listed n times counting n times), before G_fit_score",
    ),
}

GRADED_LEVELS = 8  # default max_refine of the graded method: n = 2..10 cells per end zone. A cube's
# shears reach 7e-5 at n = 8 (tests/reference/test_graded_vs_independent.py) and stop there (tol);
# a 10:1 box at nu = 0.49 reaches 6.6e-5 at n = 10 against the independent truth (2.5e-4 at n = 6);
# the dof budget (reference/graded/levels.py) stops earlier where a level would not fit

REFERENCE = {
    "element": Field("str", "P2", choices=("P1", "P2")),
    "cell": Field("str", None, choices=("tri", "quad", "tet", "hex")),
    "divisions": Field(
        "int", None, min=1, max=4096, doc="initial elements along the shortest side"
    ),
    "tol": Field("float", 1e-4, min=0, min_exclusive=True),
    "max_refine": Field(
        "int",
        None,
        min=0,
        doc="further refinement levels (default 3; graded 8, "
        "within a 400k-dof system in 3-D with the default solver, 64k with a factorising one)",
    ),
    "solver": Field("str", "auto", choices=tuple(registry.SOLVERS)),
    "modes": Field("int", 6, min=0, doc="natural frequencies to compute"),
    "method": Field(
        "str",
        "auto",
        choices=("auto", "graded", "refine"),
        doc="graded: Q2 hexes/quads graded towards the faces, levels extrapolated "
        "(boxes, rectangles); refine: uniform/adaptive refinement of the cell's mesh; "
        "auto: graded for a box unless cell or element say otherwise, else refine",
    ),
}

TOP = {
    "name": Field("str", doc="a short identifier"),
    "dim": Field("int", choices=(2, 3), doc="2 or 3"),
    "description": Field("str", ""),
    "tags": Field("strs", ()),
    "body": Field("table", spec=BODY),
    "material": Field("table", spec=MATERIAL),
    "loads": Field("table", {}, spec=LOADS),
    "reference": Field("table", {}, spec=REFERENCE),
}
