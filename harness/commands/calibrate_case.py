"""The case ``springbench calibrate`` runs: its vocabularies (methods, models, masses, units),
the prior weight, and the in-memory Case built from the settings and the user's mesh (as a
case table; TOML text only for ``--save-case``)."""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from harness import registry
from harness.commands.calibrate_engine import candidates as engine_candidates
from harness.errors import CaseError, SpringbenchError
from harness.models.stiffness_rules import RULES as STIFFNESS_RULES

METHODS = {
    "rule": "none",
    "sa": "sa",
    "lbfgs": "lbfgs",
    "gauss-newton": "gauss-newton",
    "equilibrium-gap": "equilibrium-gap",
}
INITS = ("none", "equilibrium-gap")
MODELS = registry.CALIBRATE_CLASSES  # --model: the classes of harness/registry.py it fits
RULES = STIFFNESS_RULES  # every rule the harness has (harness/models/stiffness_rules.py)
# the prior weight of lbfgs fits that validation does not choose (a --model with a term)
PRIOR_WEIGHT = 10.0
MASSES = ("lumped", "moments-nonneg", "moments")
UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
CELLS = {"triangle": "tri", "quad": "quad", "tetra": "tet", "hexahedron": "hex"}
REGION_HINT = "--clamp / --load-region take a face group, nodes:FILE, box: or sphere: instead"
# --clamp / --load-region's help: what a region may be (harness.case.selectors)
REGION_FORMS = (
    "a face group of the mesh (gmsh physical group, cell or node set); "
    + "; ".join(registry.REGION_SELECTORS.about.values())
    + " (in the mesh's coordinates): the boundary facets all of whose nodes it holds"
)


def positive(name: str, unit: str):
    """An argparse type: a positive number, else one line '--FLAG: NAME must be positive'
    (with :func:`signed_numbers`, '-5e3' reaches it)."""

    def number(text: str) -> float:
        value = float(text) if NUMBER.fullmatch(text.strip()) else None
        if value is None or not value > 0:
            raise argparse.ArgumentTypeError(f"{name} must be positive ({unit}), got '{text}'")
        return value

    number.__name__ = name
    return number


NUMBER = re.compile(r"[-+]?((\d+\.?\d*|\.\d+)([eE][-+]?\d+)?|inf|nan)", re.I)


def signed_numbers(p) -> None:
    """Let parser ``p`` read '-5e3' and '-inf' as values, not as options: argparse before
    Python 3.13 takes only '-5' and '-.5' for negative numbers, and '--E -5e3' was 'expected
    one argument' instead of the check that names E."""
    p._negative_number_matcher = re.compile(r"^-((\d+\.?\d*|\.\d+)([eE][-+]?\d+)?|inf|nan)$", re.I)


def model_name(text: str) -> str:
    """--model's value; an ambiguous spelling is refused naming both classes it could mean."""
    why = registry.ambiguous_class(text)
    if why:
        raise argparse.ArgumentTypeError(why)
    return text


def magnitude(s) -> float:
    """The fitted loads' stress: --magnitude, else 1e-3 E."""
    return s.magnitude if s.magnitude is not None else 1e-3 * s.E


def prior_weight(s) -> float:
    """The lbfgs prior weight: --prior-weight, else the default."""
    return float(PRIOR_WEIGHT if s.prior_weight is None else s.prior_weight)


def selects(s) -> bool:
    """Whether the fit's capacity is chosen by validation (harness/stages/sms_select.py):
    the default lbfgs fit of springs, unless --prior-weight fixes it."""
    return METHODS[s.method] == "lbfgs" and s.prior_weight is None and s.model == "springs"


def validates(s) -> bool:
    """Whether the case holds validation loads (harness/stages/sms_accept.py): a class of one
    fitted material (p1-global) is exported only when it beats the plain P1 on them. The
    springs' validated fit is not judged on them: on the README lug and a gmsh ellipsoid
    they ranked the rules unlike the held-out loads and refused a fit 0.62x the best rule
    (docs/calibrate.md, "Validation loads")."""
    return s.model not in registry.SPRINGS_CLASSES


def _optimizer(s) -> dict:
    """The case's [optimizer] table."""
    method = METHODS[s.method]
    out: dict = {"method": method}
    options: dict = {}
    if method != "equilibrium-gap" and s.budget is not None:  # one solve: no budget
        options["max_seconds"] = float(s.budget)  # a cap that aborts, never a stop
    if method in ("lbfgs", "gauss-newton") and s.init != "none":
        options["init"] = s.init
    if method == "lbfgs" and not selects(s):  # a fixed capacity: its own fit, by count
        from harness.stages.sms_select import FINAL_MAXITER  # the stage's, loaded when run

        options.update(prior=prior_weight(s), maxiter=FINAL_MAXITER)
    if method != "none":
        out["options"] = options
    # no rule is first: the stage ranks them (and solves only the ones that can win)
    if s.rule == "best":
        out["start"] = "best"
    if selects(s):  # --engine: only the candidates whose volume term it runs
        out["select"] = {} if s.engine is None else {"candidates": engine_candidates(s.engine)}
    return out


def case_table(s, dim: int, cell_types=(), mesh_file: Path | None = None, ends=None) -> dict:
    """The case calibrate runs, as a case table (docs/case-files.md): the mesh body, the
    material, the fitted load set and the held-out end loads, an SMS on the mesh's nodes
    and edges."""
    body: dict = {"shape": "mesh", "file": str(Path(mesh_file or s.mesh).resolve())}
    if s.format and mesh_file is None:
        body["format"] = s.format
    first = s.rule if s.rule != "best" else "lloyd"
    loads: dict = {"set": f"{s.loads}{dim}d", "magnitude": float(magnitude(s))}
    if ends is not None:
        magnitudes = ends.magnitudes(s.E, s.nu, s.density, s.peak_strain)
        parts, cases = ends.tables(magnitudes, validation=validates(s))
        body["parts"] = parts
        loads.update(heldout=list(ends.names), case=cases, rank_by=list(ends.twins))
        if validates(s):
            loads["validation"] = list(ends.validation)
    reference = {"modes": 0, "tol": float(s.tol), "max_refine": int(s.max_refine)}
    reference["solver"] = s.solver
    reference.update({"cell": CELLS[c] for c in list(cell_types)[:1] if c in CELLS})
    return {
        "name": "calibrate",
        "dim": dim,
        "body": body,
        "material": {
            "E": float(s.E),
            "nu": float(s.nu),
            "density": float(s.density),
            "plane": s.plane,
        },
        "loads": loads,
        "reference": reference,
        "model": {
            "kind": "sms",
            "placement": "mesh",
            "masses": s.masses,
            "stiffness": [first] + [r for r in RULES if r != first],
            **_model_keys(s.model),
        },
        "optimizer": _optimizer(s),
    }


def _model_keys(name: str) -> dict:
    """The [model] keys of --model ``name``: a springs class's volume and kn keys, any other
    class named in ``classes``."""
    if name not in registry.SPRINGS_CLASSES:
        return {"classes": [name]}
    model = registry.MODEL_CLASSES.load(name)
    return {"volume": model.volume, "kn": model.kn}


def case_text(s, dim: int, cell_types=(), mesh_file: Path | None = None, ends=None) -> str:
    """:func:`case_table` as a TOML case file (``--save-case``; ``springbench run`` runs it)."""
    from harness.io.toml_text import dumps

    return dumps(case_table(s, dim, cell_types, mesh_file, ends))


def region_text(s, text: str, flag: str, mesh) -> str:
    """--clamp / --load-region's ``text`` as the case spells it: a group of the mesh as
    named, a selector (harness.case.selectors) with its lengths in m and its node file's
    full path; one line naming the flag when it is neither."""
    from harness.case.selectors import (
        SPELLINGS,
        check_nodes,
        facet_masks,
        parse,
        require_facets,
    )
    from harness.io.meshfile import boundary_facets

    def bad(message, fix):
        raise SpringbenchError(message, field=flag, fix=fix)

    if s.heldout == "none":
        bad("--heldout none has no held-out loads", "drop it, or --heldout ends")
    sel = parse(text, bad, mesh.dim)
    if sel is None and text not in mesh.groups:
        have = ", ".join(sorted(mesh.groups)) or "none"
        bad(
            f"mesh '{Path(s.mesh).name}' has no group '{text}' (its groups: {have})",
            f"{SPELLINGS}; coordinates in --length-unit",
        )
    if sel is None:
        return text
    check_nodes(sel, len(mesh.points), bad)
    masks = facet_masks(sel, mesh.points, boundary_facets(mesh.cells))
    require_facets(sel, masks, mesh.points, bad, text, s.length_unit)
    return sel.scaled(UNITS[s.length_unit]).text


def regions(s, mesh) -> tuple[str | None, str | None]:
    """(clamp, load region) as the case spells them (:func:`region_text`; None: the end
    faces)."""
    return tuple(
        None if text is None else region_text(s, text, flag, mesh)
        for flag, text in (("--clamp", s.clamp), ("--load-region", s.load_region))
    )


def metre_mesh(s, mesh, tmp: Path) -> Path | None:
    """The mesh file in metres, written to ``tmp`` when its coordinates are in another unit
    or its format is bc2000 (None: the user's own file is the body)."""
    import meshio

    from harness.case.selectors import kind_of
    from harness.io.mesh_groups import scaled_copy

    if s.length_unit == "m" and s.format != "bc2000":
        return None
    scale = UNITS[s.length_unit]
    groups = [t for t in (s.clamp, s.load_region) if t is not None and not kind_of(t)]
    if groups:  # the file itself, scaled: its groups stay (node ids stay in either copy)
        mesh_file = scaled_copy(s.mesh, s.format, scale, tmp)
    else:
        mesh_file = tmp / "mesh.vtu"
        meshio.write(
            mesh_file, meshio.Mesh(mesh.points * scale, [(c, a) for c, a in mesh.cells.items()])
        )
    print(f"  mesh coordinates in {s.length_unit}: scaled by {scale:g} to m", file=sys.stderr)
    return mesh_file


def mesh_case(s, mesh, tmp: Path):
    """The in-memory Case of settings ``s`` for the read ``mesh`` (its file written to tmp
    when it must be scaled to m), printing the clamp and load faces it chose."""
    from harness.case.default_loads import end_loads, near_point_warnings
    from harness.case.elasticity import isotropic
    from harness.case.reader import case_of
    from harness.io.toml_text import dumps

    clamp, tip = regions(s, mesh)
    mesh_file = metre_mesh(s, mesh, tmp)
    pts = mesh.points * UNITS[s.length_unit]
    ends = None
    if s.heldout == "ends":
        ends = end_loads(pts, mesh.cells, clamp, tip, mesh.groups)
        # on stdout, before the work: a wrong clamp is seen at once
        print(f"{ends.describe()}; {REGION_HINT}", flush=True)
        for line in near_point_warnings(ends):
            print(line, flush=True)
    table = case_table(s, mesh.dim, mesh.cells, mesh_file, ends)
    if s.save_case is not None:
        s.save_case.write_text(dumps(table))  # what ran, for the user to run again or edit
    material = isotropic(s.E, s.nu, s.density, s.plane)
    try:  # the case is named after the user's mesh: errors name it
        return case_of(table, Path(s.mesh).resolve(), material=material)
    except CaseError as exc:
        raise SpringbenchError(
            exc.message, file=str(s.mesh), field=exc.field, fix=exc.fix
        ) from None
