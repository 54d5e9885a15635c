"""springbench pack CASE|MESH [--E .. --nu ..] --out DIR: a benchmark problem any engine can
read (harness/export/pack.py: mesh.vtu, loads/<name>.npz, problem.json; SI units).

For a case file (a mesh body): every load of the case, its held-out ones marked. For a
mesh: calibrate's load set for that mesh (the equilibrated linear stress states and the
clamped training states as "fitted", sag, tip, tip2, torsion and bridge with an end face
clamped as "heldout"; --clamp and --load-region take a mesh group, nodes:FILE, box: or
sphere: instead, as calibrate's do, and problem.json records them), held-out loads sized for
a peak strain of about --peak-strain. A mesh's pack holds by default only the loads that
judge an engine (--loads judged: held out, FEM error estimate <= 1 % or not estimated; each
one left out is named); --loads all keeps every load. problem.json's load_set says which."""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
from pathlib import Path

from harness.errors import SpringbenchError

HELP = (
    "write a benchmark problem for any engine: the mesh, per load the held nodes, nodal "
    "forces (N) and the "
    "FEM displacement with its error estimate at every node, and problem.json (SI units)"
)


LOAD_SETS = ("judged", "all")


def add_load_set(p):
    """--loads: which of the case's loads the pack holds (mesh packs judge engines by default)."""
    p.add_argument(
        "--loads",
        dest="load_set",
        choices=LOAD_SETS,
        default=None,
        help="judged: the held-out loads whose FEM error estimate is <= 1 %% (kept when not "
        "estimated), what judges an engine; all: every load, the fitted ones too (default: "
        "judged for a mesh, all for a case file)",
    )


def add_arguments(p):
    from harness.case.default_loads import PEAK_STRAIN
    from harness.commands.calibrate_case import REGION_FORMS, UNITS, positive, signed_numbers

    signed_numbers(p)
    p.add_argument(
        "source",
        type=Path,
        metavar="CASE|MESH",
        help="a case file (TOML, mesh body) or a mesh file",
    )
    p.add_argument(
        "--E",
        dest="E",
        type=positive("E", "Pa"),
        default=None,
        help="Young's modulus (Pa; meshes only)",
    )
    p.add_argument("--nu", type=float, default=None, help="Poisson ratio (meshes only)")
    p.add_argument(
        "--density",
        type=positive("density", "kg/m^3"),
        default=1000.0,
        help="density (kg/m^3; meshes only; default 1000)",
    )
    p.add_argument(
        "--length-unit",
        dest="length_unit",
        choices=tuple(UNITS),
        default="m",
        help="unit of the mesh's coordinates (meshes only; the pack is in m)",
    )
    p.add_argument(
        "--peak-strain",
        dest="peak_strain",
        type=float,
        default=PEAK_STRAIN,
        help="the held-out loads' size: a peak strain of about this (meshes only; default "
        f"{PEAK_STRAIN:g})",
    )
    p.add_argument(
        "--clamp",
        metavar="REGION",
        default=None,
        help=f"the region to clamp (meshes only; default: an end face): {REGION_FORMS}",
    )
    p.add_argument(
        "--load-region",
        dest="load_region",
        metavar="REGION",
        default=None,
        help="the region the tip loads and torsion act on (meshes only; default: the other end "
        "face; the torsion turns about its mean outward normal): as --clamp",
    )
    add_load_set(p)
    p.add_argument("--format", default=None, help="mesh format if the file name does not tell")
    p.add_argument(
        "--max-refine",
        dest="max_refine",
        type=int,
        default=100,
        help="reference refinements at most (meshes only; default 100, as calibrate: until "
        "1 %% on every held-out load or the dof cap)",
    )
    p.add_argument(
        "--full",
        dest="mode",
        action="store_const",
        const="full",
        default="quick",
        help="case files: use the case's [full] table",
    )
    p.add_argument(
        "--out", type=Path, required=True, metavar="DIR", help="the pack's folder (made if missing)"
    )


def _mesh_case(args, tmp: Path):
    """calibrate's in-memory case for the mesh (its loads, no optimiser)."""
    from harness.case.mesh_checks import check_mesh
    from harness.commands import calibrate as cal
    from harness.commands import calibrate_case
    from harness.commands.calibrate_check import check as check_flags
    from harness.commands.calibrate_check import unit_warnings
    from harness.io.meshfile import read_mesh

    if args.E is None or args.nu is None:
        raise SpringbenchError(
            "a mesh needs its material",
            field="--E" if args.E is None else "--nu",
            fix="e.g. --E 1e5 --nu 0.45 (Pa)",
        )
    p = argparse.ArgumentParser(add_help=False)
    cal.add_arguments(p)
    cargs = p.parse_args(
        [str(args.source), "--E", repr(args.E), "--nu", repr(args.nu), "--out", str(tmp / "x.vtu")]
        + ["--method", "rule", "--density", repr(args.density), "--length-unit", args.length_unit]
        + ["--peak-strain", repr(args.peak_strain), "--max-refine", str(args.max_refine)]
    )
    cargs.clamp, cargs.load_region, cargs.format = args.clamp, args.load_region, args.format
    check_flags(cargs, calibrate_case.prior_weight(cargs))
    mesh = read_mesh(args.source, args.format)
    check_mesh(mesh, str(args.source))
    for line in unit_warnings(cargs, mesh):
        print(line, file=sys.stderr, flush=True)
    return calibrate_case.mesh_case(cargs, mesh, tmp)


def main(args) -> int:
    from harness import __version__
    from harness.export.pack import write_pack
    from harness.export.pack_make import judged, make_pack
    from harness.outputs import check_out_dir

    if not args.source.is_file():
        raise SpringbenchError(
            "no such file", file=str(args.source), fix="a case file (.toml) or a mesh file"
        )
    check_out_dir(args.out, "--out")
    is_case = args.source.suffix.lower() == ".toml"
    if is_case:
        for flag, v in (
            ("--E", args.E),
            ("--nu", args.nu),
            ("--clamp", args.clamp),
            ("--load-region", args.load_region),
        ):
            if v is not None:
                raise SpringbenchError(
                    f"{flag} is for a mesh; the case file sets it",
                    field=flag,
                    fix="drop it, or change the case file",
                )
    with tempfile.TemporaryDirectory(prefix="springbench-pack-") as tmp:
        tmp = Path(tmp)
        if is_case:
            from harness.case.reader import load_case

            case = load_case(args.source, args.mode)
        else:
            try:
                case = _mesh_case(args, tmp)
            except SpringbenchError as exc:  # name the user's mesh, never our temporary files
                if exc.file is None or str(tmp) in str(exc.file):
                    raise type(exc)(
                        exc.message, file=str(args.source), field=exc.field, fix=exc.fix
                    ) from None
                raise
        load_set = args.load_set or ("all" if is_case else "judged")
        meta = {"source": str(args.source), "springbench": __version__, "load_set": load_set}
        if not is_case:
            meta["peak_strain"] = args.peak_strain
            meta.update(regions(case))
        if load_set == "judged":
            case = heldout_case(case)
        pack = make_pack(case, meta=meta)
        if load_set == "judged":
            pack, notes = judged(pack)
            for line in notes:
                print(f"{args.source}: {line}", file=sys.stderr, flush=True)
    path = write_pack(pack, args.out)
    held = sum(ld.role == "heldout" for ld in pack.loads)
    print(
        f"{args.source}: {pack.n_nodes} nodes, {sum(len(c) for c in pack.cells.values())} cells, "
        f"{len(pack.loads)} loads ({held} held out), E {pack.E:g} Pa, nu {pack.nu:g}"
    )
    for ld in pack.loads:
        err = ld.u_fem_error
        print(
            f"  {ld.name:16s} {ld.role:8s} {ld.kind:16s} held {len(ld.held_nodes):5d} nodes, "
            f"|u_fem| max {float((ld.u_fem**2).sum(axis=1).max()) ** 0.5:.3g} m"
            + (
                f", FEM error <= {float(max(err)):.2g} m"
                if len(err) and all(e == e for e in err)
                else ""
            )
        )
    print(f"-> {path}")
    return 0


def heldout_case(case):
    """The case with only its held-out loads (the fitted ones judge no engine: no FEM solve
    for them); an error naming --loads if it holds none out."""
    kept = tuple(ld for ld in case.loads if ld.name in case.heldout)
    if not kept:
        raise SpringbenchError(
            "the case holds no load out: no load judges an engine",
            file=str(case.path) if case.path else None,
            field="--loads",
            fix="--loads all",
        )
    return dataclasses.replace(case, loads=kept)


def regions(case) -> dict:
    """{"clamp", "load_region"}: how the case spells the held-out loads' regions (a group,
    a selector in m, or an end face), so a pack says where it holds and loads."""
    from harness.case.selectors import SelectorPart
    from harness.io.end_faces import EndPart
    from harness.io.mesh_groups import GroupPart

    def spelling(part):
        if isinstance(part, SelectorPart):
            return part.selector.text
        if isinstance(part, GroupPart):
            return part.group
        return f"end face {part.name}" if isinstance(part, EndPart) else None

    parts = case.body.parts or {}
    return {"clamp": spelling(parts.get("clamp")), "load_region": spelling(parts.get("tip"))}
