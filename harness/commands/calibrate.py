"""springbench calibrate MESH --E .. --nu .. [--density ..] [--method rule|sa|lbfgs|gauss-newton|equilibrium-gap]
[--init none|equilibrium-gap] --out MODEL.vtu

Turns a user's own tri/quad/tet/hex mesh (any meshio format, or the bc2000 format) into
a calibrated spring/mass model: springs on the mesh edges (hexahedra add their body
diagonals), masses by moment matching, initial constants by a named rule, then (``sa``,
``lbfgs``, ``gauss-newton`` or ``equilibrium-gap``; ``--init equilibrium-gap`` starts the
gradient fits from the equilibrium-gap estimate) spring constants fitted so the network's
static response to the standard basic loads of the mesh's bounding box (DESIGN.md:
``basic2d`` / ``basic3d``) matches a FEM reference of the same body and material. A fit
never ends worse than the rule's constants (it keeps the best point seen; the
equilibrium-gap estimate falls back to the rule when it is worse, as on coarse meshes
against FEM, where equation error and output error differ). Prints the before/after table (G per rule
and after fitting) and writes:

- ``MODEL.vtu`` — ParaView-ready network (points in m, ``line`` cells = springs, point
  data ``mass`` in kg, cell data ``stiffness`` = linear k in N/m with f = k (l - l0)).
- ``MODEL.json`` — arrays for other engines, SI units: ``particle_q`` (n, 3) m,
  ``particle_mass`` (n) kg, ``spring_indices`` (e, 2), ``spring_rest_length`` (e) m,
  ``spring_stiffness`` (e) N/m — NVIDIA Warp's ``ModelBuilder.add_spring(i, j, ke, kd,
  control)`` ``ke`` and Taichi-style ``ke`` arrays (f = ke (l - l0)) —, and
  ``spring_stiffness_times_length`` (e) N = k l0, the per-length convention (SOFA's
  MeshSpringForceField divides its stiffness by the rest length; strain-based engines
  use f = k l0 (l - l0) / l0); SOFA's SpringForceField takes k itself (``springs="i j
  k kd l0"``). 2-D models have unit thickness (k per unit thickness, N/m per m).
- ``MODEL.csv`` — the table printed (with the ``seed`` and the optimiser's ``opt_stop``).
"""

from __future__ import annotations

import json
import math
import sys
import tempfile
import time
from pathlib import Path

from harness.errors import CaseError, SpringbenchError

HELP = "calibrate spring constants for your own mesh against FEM and export them (VTU, JSON for Warp/Taichi/SOFA)"
METHODS = {"rule": "none", "sa": "sa", "lbfgs": "lbfgs", "gauss-newton": "gauss-newton",
           "equilibrium-gap": "equilibrium-gap"}
INITS = ("none", "equilibrium-gap")
RULES = ("deussen", "vangelder", "lloyd", "uniform")


def add_arguments(p):
    p.add_argument("mesh", type=Path, metavar="MESH", help="tri/quad/tet/hex mesh (any meshio format or bc2000)")
    p.add_argument("--E", dest="E", type=float, required=True, help="Young's modulus (Pa)")
    p.add_argument("--nu", type=float, required=True, help="Poisson ratio in (-1, 0.5)")
    p.add_argument("--density", type=float, default=1000.0, help="density (kg/m^3; default 1000)")
    p.add_argument("--method", choices=tuple(METHODS), default="lbfgs",
                   help="rule: initial constants only; sa: simulated annealing; lbfgs: adjoint gradient "
                        "(default); gauss-newton; equilibrium-gap: one linear least-squares solve")
    p.add_argument("--init", choices=INITS, default="none",
                   help="start of lbfgs / gauss-newton: the rule's constants (none, default) or the "
                        "equilibrium-gap estimate (much faster on large meshes)")
    p.add_argument("--rule", choices=RULES, default="lloyd",
                   help="stiffness rule of the initial constants (default lloyd)")
    p.add_argument("--plane", choices=("stress", "strain"), default="stress", help="2-D meshes: plane stress/strain")
    p.add_argument("--magnitude", type=float, default=None,
                   help="traction of the basic loads (Pa; default 1e-3 E: small strains)")
    p.add_argument("--tol", type=float, default=1e-3,
                   help="reference (FEM) error tolerance relative to the displacement scale (default 1e-3)")
    p.add_argument("--max-refine", dest="max_refine", type=int, default=1,
                   help="reference refinements at most (default 1; each multiplies the dofs by 4-8)")
    p.add_argument("--budget", type=float, default=60.0, help="optimiser wall-time budget in seconds (default 60)")
    p.add_argument("--format", default=None, help="mesh format if the file name does not tell (meshio name or bc2000)")
    p.add_argument("--seed", type=int, default=0, help="seed of the optimiser (sa)")
    p.add_argument("--out", type=Path, required=True, metavar="MODEL.vtu", help="output network (VTU)")


def _check(args):
    def bad(flag, msg, fix):
        raise SpringbenchError(msg, field=flag, fix=fix)
    if not (math.isfinite(args.E) and args.E > 0):
        bad("--E", f"{args.E} is not a positive number", "Young's modulus in Pa, e.g. --E 2e5")
    if not (-1 < args.nu < 0.5):
        bad("--nu", f"{args.nu} is out of range", "a Poisson ratio in (-1, 0.5), e.g. --nu 0.3")
    if not (math.isfinite(args.density) and args.density > 0):
        bad("--density", f"{args.density} is not a positive number", "kg/m^3, e.g. --density 1000")
    if args.magnitude is not None and not (math.isfinite(args.magnitude) and args.magnitude > 0):
        bad("--magnitude", f"{args.magnitude} is not a positive number", "a traction in Pa")
    if args.init != "none" and args.method not in ("lbfgs", "gauss-newton"):
        bad("--init", f"--method {args.method} has no start point to set", "use --init with --method lbfgs or gauss-newton")
    if not (args.budget > 0):
        bad("--budget", f"{args.budget} is not a positive number of seconds", "e.g. --budget 60")
    if not (args.tol > 0) or args.max_refine < 0:
        bad("--tol", "needs --tol > 0 and --max-refine >= 0", "e.g. --tol 1e-3 --max-refine 1")
    if args.out.suffix.lower() != ".vtu":
        bad("--out", f"'{args.out}' does not end in .vtu", "e.g. --out model.vtu")
    if not args.mesh.is_file():
        raise SpringbenchError("no such mesh file", file=str(args.mesh), fix="check the path")


CELLS = {"triangle": "tri", "quad": "quad", "tetra": "tet", "hexahedron": "hex"}


def case_text(args, dim: int, cell_types=()) -> str:
    """The in-memory case that calibrate runs: the mesh body, the material, the basic
    loads of the bounding box, an SMS on the mesh's nodes and edges."""
    mesh = json.dumps(str(args.mesh.resolve()))
    fmt = f"format = {json.dumps(args.format)}\n" if args.format else ""
    s = args.magnitude if args.magnitude is not None else 1e-3 * args.E
    rules = [args.rule] + [r for r in ("deussen", "vangelder", "lloyd") if r != args.rule]
    method = METHODS[args.method]
    cell = "".join(f'cell = "{CELLS[c]}"\n' for c in list(cell_types)[:1] if c in CELLS)
    init = f', init = "{args.init}"' if method in ("lbfgs", "gauss-newton") and args.init != "none" else ""
    budget = "" if method == "equilibrium-gap" else f"max_seconds = {float(args.budget)!r}"  # one solve
    opt = "" if method == "none" else f"options = {{{budget}{init}}}\n"
    return (f'name = "calibrate"\ndim = {dim}\n'
            f'[body]\nshape = "mesh"\nfile = {mesh}\n{fmt}'
            f"[material]\nE = {float(args.E)!r}\nnu = {float(args.nu)!r}\ndensity = {float(args.density)!r}\n"
            f'plane = "{args.plane}"\n'
            f'[loads]\nset = "basic{dim}d"\nmagnitude = {float(s)!r}\n'
            f'[reference]\nmodes = 0\ntol = {float(args.tol)!r}\nmax_refine = {int(args.max_refine)}\n{cell}'
            f'[model]\nkind = "sms"\nplacement = "mesh"\nstiffness = {json.dumps(rules)}\n'
            f'[optimizer]\nmethod = "{method}"\n{opt}')


def main(args) -> int:
    _check(args)
    from harness.cases import load_case
    from harness.meshfile import read_mesh
    from harness.stages import StageContext
    from harness.stages import sms as stage
    import pandas as pd

    mesh = read_mesh(args.mesh, args.format)
    dim = mesh.dim
    with tempfile.TemporaryDirectory(prefix="springbench-calibrate-") as tmp:
        tmp = Path(tmp)
        (tmp / "calibrate.toml").write_text(case_text(args, dim, mesh.cells))
        try:
            case = load_case(tmp / "calibrate.toml")
        except CaseError as exc:  # name the user's mesh or flag, not our temporary case file
            raise SpringbenchError(exc.message, file=str(args.mesh), field=exc.field, fix=exc.fix)

        last = [0.0]

        def status(msg):  # at most one line a second
            now = time.monotonic()
            if now - last[0] >= 1.0:
                last[0] = now
                print(f"  {msg}", file=sys.stderr, flush=True)
        ctx = StageContext(out_dir=tmp / "out", seed=args.seed, status=status)
        rows = stage.run(case, ctx)
        best = rows[-1]
        tag = best["stiffness"] if best.get("optimizer", "none") == "none" else \
            f"{best['stiffness']}-{best['optimizer']}"
        if args.method == "rule":
            tag = args.rule
        from harness.io_vtu import read_vtu
        net, _ = read_vtu(ctx.out_dir / f"model-{tag}.vtu")
    export(net, args.out)
    cols = [c for c in ("model", "stiffness", "optimizer", "n_nodes", "n_springs", "G_initial", "G_final",
                        "G_norm_initial", "G_norm_final", "seconds", "seed", "opt_stop")  # seed: --seed, recorded
            if any(c in r for r in rows)]
    df = pd.DataFrame(rows)[cols]
    df.to_csv(args.out.with_suffix(".csv"), index=False)
    print(df.to_string(index=False))
    print(f"-> {args.out} (+ .json, .csv): {net.n_nodes} nodes, {net.n_springs} springs, "
          f"k from {tag}; G normalised {best.get('G_norm_initial', math.nan):.4g} -> {best.get('G_norm_final', math.nan):.4g}")
    return 0


def export(net, out: Path):
    """MODEL.vtu and MODEL.json (units in the module docstring)."""
    import numpy as np
    from harness.io_vtu import write_vtu
    out.parent.mkdir(parents=True, exist_ok=True)
    write_vtu(out, net)
    L = net.rest_lengths
    q = np.hstack([net.points, np.zeros((net.n_nodes, 3 - net.dim))]) if net.dim < 3 else net.points
    data = {
        "units": {"length": "m", "mass": "kg", "spring_stiffness": "N/m (f = k (l - l0))",
                  "spring_stiffness_times_length": "N (k l0; per-length convention, f = k l0 (l - l0) / l0)",
                  "note": "2-D models: unit thickness" if net.dim == 2 else ""},
        "dim": net.dim,
        "particle_q": q.tolist(),
        "particle_mass": np.asarray(net.masses, float).tolist(),
        "spring_indices": np.asarray(net.springs, int).tolist(),
        "spring_rest_length": L.tolist(),
        "spring_stiffness": np.asarray(net.k, float).tolist(),
        "spring_stiffness_times_length": (np.asarray(net.k, float) * L).tolist(),
    }
    out.with_suffix(".json").write_text(json.dumps(data))
