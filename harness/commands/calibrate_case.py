"""The case ``springbench calibrate`` runs: its vocabularies (methods, models, masses, units),
the prior weight, and the in-memory TOML case built from the arguments and the user's mesh."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from harness.case.default_loads import PEAK_STRAIN
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
MODELS = (
    "springs",
    "springs+volume",
    "springs+volume-shared",
    "springs+kn",
    "springs+kn-node",
    "springs+node-volume",
    "springs+node-volume-shared",
)
VOLUME = {
    "springs": "none",
    "springs+volume": "element",
    "springs+volume-shared": "shared",  # [model] volume
    "springs+node-volume": "node",
    "springs+node-volume-shared": "node-shared",
}
KN = {"springs+kn": "shared", "springs+kn-node": "node"}  # [model] kn
RULES = STIFFNESS_RULES  # every rule the harness has (harness/models/stiffness_rules.py)
# the prior weight of lbfgs fits that validation does not choose (--model springs+volume, +kn)
PRIOR_WEIGHT = 10.0
MASSES = ("lumped", "moments-nonneg", "moments")
UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
CELLS = {"triangle": "tri", "quad": "quad", "tetra": "tet", "hexahedron": "hex"}


def magnitude(args) -> float:
    return args.magnitude if args.magnitude is not None else 1e-3 * args.E


def prior_weight(args) -> float:
    """The lbfgs prior weight: --prior-weight, else the default."""
    w = getattr(args, "prior_weight", None)
    return float(PRIOR_WEIGHT if w is None else w)


def selects(args) -> bool:
    """Whether the fit's capacity is chosen by validation (harness/stages/sms_select.py):
    the default lbfgs fit of springs, unless --prior-weight fixes it."""
    return (
        METHODS[args.method] == "lbfgs"
        and getattr(args, "prior_weight", None) is None
        and getattr(args, "model", "springs") == "springs"
    )


def case_text(
    args, dim: int, cell_types=(), mesh_file: Path | None = None, rules=None, ends=None
) -> str:
    """The in-memory case that calibrate runs: the mesh body, the material, the fitted
    load set and the held-out end loads, an SMS on the mesh's nodes and edges."""
    mesh = json.dumps(str(Path(mesh_file or args.mesh).resolve()))
    fmt = f"format = {json.dumps(args.format)}\n" if args.format and mesh_file is None else ""
    s = magnitude(args)
    if rules is None:
        first = args.rule if args.rule != "best" else "lloyd"
        rules = [first] + [r for r in RULES if r != first]
    method = METHODS[args.method]
    cell = "".join(f'cell = "{CELLS[c]}"\n' for c in list(cell_types)[:1] if c in CELLS)
    init = (
        f', init = "{args.init}"'
        if method in ("lbfgs", "gauss-newton") and args.init != "none"
        else ""
    )
    # one solve
    budget = "" if method == "equilibrium-gap" else f"max_seconds = {float(args.budget)!r}"
    chosen = selects(args)
    if method == "lbfgs" and not chosen:
        init += f", prior = {prior_weight(args)!r}"
    opt = "" if method == "none" else f"options = {{{budget}{init}}}\n"
    # no rule is first: the stage ranks them (and solves only the ones that can win)
    if args.rule == "best":
        opt += 'start = "best"\n'
    if chosen:
        opt += "[optimizer.select]\n"
    parts, cases, held = ("", "", "")
    if ends is not None:
        parts, cases = ends.toml(
            ends.magnitudes(
                args.E, args.nu, args.density, getattr(args, "peak_strain", PEAK_STRAIN)
            )
        )
        parts = "[body.parts]\n" + parts
        held = f"heldout = {json.dumps(list(ends.names))}\n"
    return (
        f'name = "calibrate"\ndim = {dim}\n'
        f'[body]\nshape = "mesh"\nfile = {mesh}\n{fmt}{parts}'
        f"[material]\nE = {float(args.E)!r}\nnu = {float(args.nu)!r}\ndensity = "
        f"{float(args.density)!r}\n"
        f'plane = "{args.plane}"\n'
        f'[loads]\nset = "{args.loads}{dim}d"\nmagnitude = {float(s)!r}\n{held}{cases}'
        f"[reference]\nmodes = 0\ntol = {float(args.tol)!r}\nmax_refine = {int(args.max_refine)}\n"
        f'solver = "{args.solver}"\n{cell}'
        f'[model]\nkind = "sms"\nplacement = "mesh"\nmasses = "{args.masses}"\nstiffness = '
        f"{json.dumps(rules)}\n"
        f'volume = "{VOLUME.get(getattr(args, "model", "springs"), "none")}"\n'
        f'kn = "{KN.get(getattr(args, "model", "springs"), "none")}"\n'
        f'[optimizer]\nmethod = "{method}"\n{opt}'
    )


def mesh_case(args, mesh, tmp: Path):
    """The in-memory case of ``args`` for the read ``mesh`` (its file written to tmp when
    it must be scaled to m), printing the clamp and load faces it chose."""
    from harness.case.default_loads import end_loads
    from harness.case.reader import load_case
    from harness.io.mesh_groups import require_group, scaled_copy

    for flag, group in (("--clamp", args.clamp), ("--load-region", args.load_region)):
        if group is not None and args.heldout == "none":
            raise SpringbenchError(
                "--heldout none has no held-out loads", field=flag, fix="drop it, or --heldout ends"
            )
        if group is not None:
            require_group(mesh, group, file=str(args.mesh), field=flag)
    mesh_file = None
    if args.length_unit != "m" or args.format == "bc2000":  # hand the body over in metres
        import meshio

        mesh_file = tmp / "mesh.vtu"
        if args.clamp or args.load_region:  # the file itself, scaled: its groups stay
            mesh_file = scaled_copy(args.mesh, args.format, UNITS[args.length_unit], tmp)
        else:
            meshio.write(
                mesh_file,
                meshio.Mesh(
                    mesh.points * UNITS[args.length_unit], [(c, a) for c, a in mesh.cells.items()]
                ),
            )
        print(
            f"  mesh coordinates in {args.length_unit}: scaled by {UNITS[args.length_unit]:g} to m",
            file=sys.stderr,
        )
    pts = mesh.points * UNITS[args.length_unit]
    ends = (
        end_loads(pts, mesh.cells, args.clamp, args.load_region, mesh.groups)
        if args.heldout == "ends"
        else None
    )
    if ends is not None:  # on stdout, before the work: a wrong clamp is seen at once
        print(
            f"{ends.describe()}; --clamp GROUP clamps a named face group of the mesh instead",
            flush=True,
        )
    (tmp / "calibrate.toml").write_text(
        case_text(args, mesh.dim, mesh.cells, mesh_file, None, ends)
    )
    try:
        case = load_case(tmp / "calibrate.toml")
    except CaseError as exc:
        raise SpringbenchError(
            exc.message, file=str(args.mesh), field=exc.field, fix=exc.fix
        ) from None
    return case
