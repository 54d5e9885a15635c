"""springbench calibrate MESH --E .. --nu .. [--density ..] [--method rule|sa|lbfgs|gauss-newton|equilibrium-gap]
--out MODEL.vtu

Turns a user's own tri/quad/tet/hex mesh (any meshio format, or the bc2000 format) into
a calibrated spring/mass model an explicit engine can run: springs on the mesh edges
(hexahedra add their body diagonals), lumped element masses (never negative; ``--masses``),
initial constants by a stiffness rule (``--rule``; by default the best of them on the fitted
loads, which the fit then starts from), then spring
constants fitted (``--method``) so the network's statics match a FEM reference of the
same body and material on the fitted loads, and scored on held-out loads it never saw.

Fit (``--method lbfgs``, the default): the training states' relative misfits (each state
counts alike) + a mean_e log(k_e/k_rule,e)^2 are minimised by L-BFGS-B with an adjoint
gradient. Which capacity (per-spring constants with a = 1 or 0.1, or with one volume term
per element as well) is chosen by leave-one-family-out validation on the training states
(harness/optimize/select.py: constant, bending, torsion, shear-gradient, gravity, and the
clamped training states together); the held-out loads never choose. A candidate must beat
the rule on the validation score and be no worse on the clamped states; when none does,
the rule's constants are exported (JSON ``choice`` = "rule"). The chosen fit starts from
the rule, its best global scale and a perturbed start (``G_heldout_mean_spread``: the
spread of their held-out error). ``--prior-weight a`` fixes a per-spring fit with weight
a instead (no validation).

Loads (docs/design.md, "Load sets"). Fitted (``--loads linear``, the default): the equilibrated linear
stress states (harness/case/linear_states.py: the six constant ones, bending, torsion,
shear gradient and gravity, 24 in 3-D, 9 in 2-D) as tractions sigma(x) . n on the whole
surface with minimal constraints, exact for any shape (their FEM answer is the closed
form), and the clamped training states train-tip, train-tip2 and train-torsion (the high
end face held, the low one loaded) and train-<b>-<c> (per other axis b: its low end face
held, its high one sheared along c), so the clamps validation sees are at several places;
``--loads homogeneous`` keeps only the constant
states; ``--loads basic`` uses the basic loads of the bounding box (boxes only).
Held out (``--heldout ends``, the default; ``none`` turns them off): ``sag`` (a body
force), ``tip`` and ``tip2`` (end tractions across the axis, 3-D: both directions),
``torsion`` (3-D: a twist of the same end) with the end face at the low end of the
longest axis clamped, and ``bridge`` (the sag with both end faces clamped); end faces are
boundary facets, the same for the FEM and the springs (harness/case/default_loads.py;
printed when chosen); ``--clamp`` and ``--load-region`` name mesh groups to clamp and to
load instead. Fitted loads have stress ``--magnitude`` (default 1e-3 E), held-out loads
a peak strain of about ``--peak-strain`` (default 1e-3): small strains.

Units: lengths are the mesh's times ``--length-unit`` (m, cm or mm; exported in m), E in
Pa, density in kg/m^3; so k is in N/m, masses in kg, damping in N s/m, time in s.

Prints where the held-out loads clamp the body (before the work), then the table and the
verdict: the held-out error against the best rule's on the same loads, the fitted error, the
reference's status and, for a validated fit, what the validation chose. Writes:

- ``MODEL.vtu`` — ParaView-ready network (points in m, ``line`` cells = springs, point
  data ``mass`` in kg, cell data ``stiffness`` = linear k in N/m with f = k (l - l0)).
- ``MODEL.json`` — for engines, SI units: ``particle_q`` (n, 3) m, ``particle_mass`` (n) kg,
  ``spring_indices`` (e, 2), ``spring_rest_length`` (e) m, ``spring_stiffness`` (e) N/m
  (f = ke (l - l0): NVIDIA Newton's ``ModelBuilder.add_spring(i, j, ke, kd, control)`` ``ke``,
  Taichi-style ``ke``), ``spring_damping`` (e) N s/m (``kd``: ``--damping-ratio`` of each
  spring's critical damping, harness/export/engine.py), ``spring_stiffness_times_length``
  (e) N = k l0 (SOFA's MeshSpringForceField divides its stiffness by the rest length;
  SOFA's SpringForceField takes k itself, ``springs="i j k kd l0"``), ``dt_stable`` and
  ``dt_stable_float32`` (s: explicit symplectic Euler limit with that damping, and with a
  float32 margin), ``dt_safe`` and ``settle_damping`` (the step and the damping an engine
  settles with), ``clamped_nodes``, ``loaded_nodes``, ``forces`` and ``gravity`` per load
  (harness/export/engine_loads.py), ``omega_max`` (rad/s), ``E`` (Pa), ``nu``, ``density`` (kg/m^3),
  ``loads_fitted``, ``loads_heldout``, ``prior_weight`` (lbfgs: ``--prior-weight``),
  ``G_norm`` and ``G_norm_heldout`` (RMS displacement
  error relative to the FEM's, fitted / held-out loads), ``G_heldout_mean`` (the mean over
  the held-out loads of each one's own relative error) and ``G_heldout_loads`` ({load: its
  relative error}), ``status`` (the exported row's reference status, ``ok`` or ``ref-coarse``),
  ``verdict`` and ``best_rule_heldout`` (the exported constants against the best rule on the
  held-out loads, harness/report/findings.py), ``opt_stop`` and ``opt_stops`` (the optimiser's
  whole stop messages), ``reference_error`` (the FEM's
  own estimated error, relative: the worst of ``reference_error_fitted`` and
  ``reference_error_heldout``), ``mass_residual`` and ``units``. 2-D models have unit
  thickness (k, masses per unit thickness).
  A model with an extra term adds its keys (docs/calibrate.md, "What it writes", gives each
  energy; the JSON's ``units`` the forces): a volume term per element (``--model springs+volume``,
  ``springs+volume-shared``; harness/models/volume.py) ``volume_*``, run in Newton as
  tetrahedra with k_mu = 0, k_lambda = kv; one per node (``--model springs+node-volume``,
  ``springs+node-volume-shared``, or a ``+node-volume`` choice of the validation)
  ``node_volume_*``, run in Newton by harness/engines/newton_volume.py; Kot & Nagahashi's
  term (``--model springs+kn``, ``springs+kn-node``; harness/models/kn.py) ``kn_*``.
  ``dt_stable`` includes the term.
  Newton traps: ``add_particle(pos, vel, mass, radius)`` radius only matters for contacts
  (give a small one, or the particles collide with each other); ``add_spring`` recomputes
  the rest length from the particle positions, so add the particles at ``particle_q``.
- ``MODEL.csv`` — the table printed (with the ``seed`` and the optimiser's ``opt_stop``).
"""

from __future__ import annotations

import json
import math
import sys
import tempfile
from pathlib import Path

from harness.case.default_loads import PEAK_STRAIN
from harness.errors import CaseError, SpringbenchError
from harness.models.stiffness_rules import RULES as STIFFNESS_RULES

HELP = ("calibrate spring constants for your own mesh against FEM and export them "
        "(VTU, JSON for Newton/Warp/Taichi/SOFA: k, damping, masses, stable step)")
EPILOG = """outputs (SI units; lengths in m whatever --length-unit):
  MODEL.vtu   network for ParaView: points (m), line cells = springs, point data mass (kg),
              cell data stiffness (N/m, f = k (l - l0))
  MODEL.json  particle_q (m), particle_mass (kg), spring_indices, spring_rest_length (m),
              spring_stiffness (N/m), spring_damping (N s/m), spring_stiffness_times_length (N),
              damping_ratio, dt_stable and dt_stable_float32 (s), omega_max (rad/s), E (Pa), nu,
              density (kg/m^3), loads_fitted, loads_heldout, G_norm and G_norm_heldout (RMS
              displacement error / RMS FEM displacement), G_heldout_mean (mean over the held-out loads
              of each one's own G_norm), G_heldout_loads ({load: G_norm}), choice (rule, the validated
              capacity, or fit), validation (the table that chose: each model's score per left-out
              family), validation_skipped (null when the validation ran, else the --budget in s
              that lets it run), G_heldout_mean_spread (over the final fit's starts), reference_error (FEM's own, relative; the worst of
              reference_error_fitted and reference_error_heldout),
              status (the exported row's reference status: ok, or ref-coarse: the FEM's own error is above
              a tenth of the model's or missed its tol), verdict (held-out loads: better, tie or
              fit-worse-than-rule for a fit, rule when a rule is exported, null without held-out loads),
              best_rule_heldout ({rule, G_heldout_mean}: the best rule on the held-out loads), opt_stop and
              opt_stops (the optimiser's whole stop message: the exported start's, and every start's),
              mass_residual, masses, prior_weight (lbfgs), units; --model springs+volume adds volume_indices,
              volume_rest (m^3; 2-D m^2), volume_stiffness (kv, Pa; 2-D N/m), volume_shared; a volume
              term per node (--model springs+node-volume, or a +node-volume choice) adds
              node_volume_nodes, node_volume_rest (m^3; 2-D m^2), node_volume_stiffness (kv, Pa; 2-D N/m),
              node_volume_shared, node_volume_elements, node_volume_element_rest (m^3; 2-D m^2);
              --model springs+kn adds kn_nodes, kn_node_volume (m^3; 2-D m^2), kn_spring_count,
              kn_stiffness (kn, Pa; 2-D N/m), kn_shared; for engines: dt_safe (s: the step to use,
              0.8 dt_stable, measured in NVIDIA Newton in float32), settle_damping ({c, omega_1, load,
              velocity_factor}: after every step v *= velocity_factor, mass damping c = 2 omega_1 about
              critical for the lowest mode), and per load clamped_nodes ({nodes, components}: the held
              node ids and components), loaded_nodes and forces (N, one row per loaded node) and
              gravity (m/s^2, already inside forces; null without a body force)
  MODEL.csv   the printed table: model, stiffness (rule), optimizer, exported (the row written),
              n_nodes, n_springs, G_initial and G_final (weighted G, m), G_norm_initial and
              G_norm_final (fitted loads, pooled), G_fit_score (fitted loads: the mean of each family's
              and of the clamped states' own G_norm; ranks the rules), G_heldout, G_heldout_mean,
              G_heldout_mean_spread, choice, ref_error_max and ref_error_heldout (the FEM's own error),
              status (ok / ref-coarse), k_ratio (max/median k, with --k-ratio), dt_stable (s, the JSON's),
              dt_safe (s), seconds, seed, opt_stop, opt_stops (every start's, " | " between)
2-D meshes: unit thickness (k and masses per unit thickness).
the fit (lbfgs) minimises the training states' relative misfits + a mean(log(k/k_rule)^2); by default
its capacity (the prior weight a, a volume term per node or none) is chosen by leave-one-family-out
validation on the training states (the lowest geometric mean of its free-traction and clamped errors
relative to the rule's, below 0.99), and the rule is exported when no candidate beats it there (JSON
choice, validation); --prior-weight a fixes a per-spring fit instead; MODEL.csv's opt_prior is a."""
METHODS = {"rule": "none", "sa": "sa", "lbfgs": "lbfgs", "gauss-newton": "gauss-newton",
           "equilibrium-gap": "equilibrium-gap"}
INITS = ("none", "equilibrium-gap")
MODELS = ("springs", "springs+volume", "springs+volume-shared", "springs+kn", "springs+kn-node",
          "springs+node-volume", "springs+node-volume-shared")
VOLUME = {"springs": "none", "springs+volume": "element", "springs+volume-shared": "shared",   # [model] volume
          "springs+node-volume": "node", "springs+node-volume-shared": "node-shared"}
KN = {"springs+kn": "shared", "springs+kn-node": "node"}                                     # [model] kn
RULES = STIFFNESS_RULES     # every rule the harness has (harness/models/stiffness_rules.py)
PRIOR_WEIGHT = 10.0     # the prior weight of lbfgs fits that validation does not choose (--model springs+volume, +kn)
MASSES = ("lumped", "moments-nonneg", "moments")
UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}


def add_arguments(p):
    p.add_argument("mesh", type=Path, metavar="MESH", help="tri/quad/tet/hex mesh (any meshio format or bc2000)")
    p.add_argument("--E", dest="E", type=float, required=True, help="Young's modulus (Pa)")
    p.add_argument("--nu", type=float, required=True, help="Poisson ratio in (-1, 0.5)")
    p.add_argument("--density", type=float, default=1000.0, help="density (kg/m^3; default 1000)")
    p.add_argument("--method", choices=tuple(METHODS), default="lbfgs",
                   help="rule: initial constants only; sa: simulated annealing; lbfgs: adjoint gradient "
                        "(default); gauss-newton; equilibrium-gap: one linear least-squares solve")
    p.add_argument("--model", choices=MODELS, default="springs",
                   help="springs (default); springs+volume: plus a volume energy per tetrahedron (2-D: triangle) "
                        "with its own fitted constant kv; springs+volume-shared: one kv for the whole body; "
                        "springs+kn: plus the adjustable-Poisson term of Kot & Nagahashi 2015, one constant kn "
                        "for the body (springs+kn-node: one per node); springs+node-volume: plus a volume "
                        "energy per node, on its share of its elements' volume change (no locking under "
                        "clamps), kv per node (springs+node-volume-shared: one kv)")
    p.add_argument("--prior-weight", dest="prior_weight", type=float, default=None,
                   help="lbfgs: fit every spring with this weight a of the pull towards the start rule's constants, "
                        "Phi = G^2/G0^2 + a mean(log(k/k_rule)^2), instead of the capacity chosen by validation "
                        "(default: chosen; 0: no pull)")
    p.add_argument("--init", choices=INITS, default="none",
                   help="start of lbfgs / gauss-newton: the rule's constants (none, default) or the "
                        "equilibrium-gap estimate (much faster on large meshes)")
    p.add_argument("--rule", choices=RULES + ("best",), default="best",
                   help="stiffness rule of the initial constants: best (default: the rule with the lowest "
                        "G_fit_score on the fitted loads, which the fit then starts from) or one of them")
    p.add_argument("--loads", choices=("linear", "homogeneous", "basic"), default="linear",
                   help="fitted loads: the equilibrated linear stress states (constant, bending, torsion, shear "
                        "gradient, gravity) on the whole surface, exact for any shape (default); homogeneous: their "
                        "constant part only; basic: the basic loads of the bounding box (boxes); with --heldout ends "
                        "also clamped training states (the ends swapped, and each side face held)")
    p.add_argument("--heldout", choices=("ends", "none"), default="ends",
                   help="held-out loads (default ends): sag, tip load, (3-D) a second tip load across and torsion "
                        "with one end face clamped, and the sag with both end faces clamped (bridge); or none")
    p.add_argument("--clamp", metavar="GROUP", default=None,
                   help="clamp of the held-out loads: a named group of the mesh (gmsh physical group, cell or "
                        "node set; default: the end face at the low end of the longest axis)")
    p.add_argument("--load-region", dest="load_region", metavar="GROUP", default=None,
                   help="where the held-out tip loads and torsion act: a named group of the mesh (default: the "
                        "end face at the high end of the longest axis)")
    p.add_argument("--masses", choices=MASSES, default="lumped",
                   help="lumped element masses (default, never negative), moments-nonneg, or moments "
                        "(Deussen's moment matching: may be negative, which explicit engines cannot run)")
    p.add_argument("--damping-ratio", dest="damping_ratio", type=float, default=0.05,
                   help="spring damping as a fraction of each spring's critical damping (default 0.05)")
    p.add_argument("--k-ratio", dest="k_ratio", type=float, default=None,
                   help="cap the fitted constants at this multiple of their median (max/median): a larger "
                        "stable step for some G; the table shows both")
    p.add_argument("--length-unit", dest="length_unit", choices=tuple(UNITS), default="m",
                   help="unit of the mesh's coordinates (default m; exports are in m)")
    p.add_argument("--plane", choices=("stress", "strain"), default="stress", help="2-D meshes: plane stress/strain")
    p.add_argument("--magnitude", type=float, default=None,
                   help="stress of the fitted loads (Pa; default 1e-3 E: small strains)")
    p.add_argument("--peak-strain", dest="peak_strain", type=float, default=PEAK_STRAIN,
                   help=f"the held-out loads' size: a peak strain of about this by beam theory on the body's "
                        f"section (default {PEAK_STRAIN:g}: the linear answer is the physical one)")
    p.add_argument("--tol", type=float, default=1e-3,
                   help="reference (FEM) error tolerance relative to the displacement scale (default 1e-3)")
    p.add_argument("--max-refine", dest="max_refine", type=int, default=1,
                   help="reference refinements at most (default 1; tri/tet meshes: 2-3 adaptive bisection "
                        "steps each, up to 200k dofs in 3-D, a mesh too large for that estimated from coarser meshes "
                        "of its body; quad/hex: uniform, x4-8 dofs; 0: no estimate)")
    p.add_argument("--solver", choices=("auto", "direct", "amg", "cg", "two-level"), default="auto",
                   help="FEM linear solver (default auto: sparse Cholesky, or for large P2 systems CG with a "
                        "two-level P1 preconditioner (two-level); AMG and Cholesky as fallbacks)")
    p.add_argument("--budget", type=float, default=60.0, help="optimiser wall-time budget in seconds (default 60): the fit's starts share it; the "
                   "validation fits stop at their iteration limit or their share of twice it (large meshes)")
    p.add_argument("--format", default=None, help="mesh format if the file name does not tell (meshio name or bc2000)")
    p.add_argument("--seed", type=int, default=0, help="seed of the optimiser (sa; >= 0)")
    p.add_argument("--out", type=Path, required=True, metavar="MODEL.vtu", help="output network (VTU)")
    p.add_argument("--quiet", action="store_true",
                   help="no progress line (phase, elapsed time, ETA; never drawn when stderr is not a terminal)")


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
    return (METHODS[args.method] == "lbfgs" and getattr(args, "prior_weight", None) is None
            and getattr(args, "model", "springs") == "springs")


def case_text(args, dim: int, cell_types=(), mesh_file: Path | None = None, rules=None, ends=None) -> str:
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
    init = f', init = "{args.init}"' if method in ("lbfgs", "gauss-newton") and args.init != "none" else ""
    budget = "" if method == "equilibrium-gap" else f"max_seconds = {float(args.budget)!r}"  # one solve
    chosen = selects(args)
    if method == "lbfgs" and not chosen:
        init += f", prior = {prior_weight(args)!r}"
    opt = "" if method == "none" else f"options = {{{budget}{init}}}\n"
    if args.rule == "best":      # no rule is first: the stage ranks them (and solves only the ones that can win)
        opt += 'start = "best"\n'
    if chosen:
        opt += "[optimizer.select]\n"
    parts, cases, held = ("", "", "")
    if ends is not None:
        parts, cases = ends.toml(ends.magnitudes(args.E, args.nu, args.density,
                                                 getattr(args, "peak_strain", PEAK_STRAIN)))
        parts = "[body.parts]\n" + parts
        held = f"heldout = {json.dumps(list(ends.names))}\n"
    return (f'name = "calibrate"\ndim = {dim}\n'
            f'[body]\nshape = "mesh"\nfile = {mesh}\n{fmt}{parts}'
            f"[material]\nE = {float(args.E)!r}\nnu = {float(args.nu)!r}\ndensity = {float(args.density)!r}\n"
            f'plane = "{args.plane}"\n'
            f'[loads]\nset = "{args.loads}{dim}d"\nmagnitude = {float(s)!r}\n{held}{cases}'
            f'[reference]\nmodes = 0\ntol = {float(args.tol)!r}\nmax_refine = {int(args.max_refine)}\n'
            f'solver = "{args.solver}"\n{cell}'
            f'[model]\nkind = "sms"\nplacement = "mesh"\nmasses = "{args.masses}"\nstiffness = {json.dumps(rules)}\n'
            f'volume = "{VOLUME.get(getattr(args, "model", "springs"), "none")}"\n'
            f'kn = "{KN.get(getattr(args, "model", "springs"), "none")}"\n'
            f'[optimizer]\nmethod = "{method}"\n{opt}')


def main(args) -> int:
    from harness.commands.calibrate_check import check
    from harness.progress import configure
    check(args, PRIOR_WEIGHT)
    configure(getattr(args, "quiet", False))
    from harness.case.mesh_checks import check_mesh
    from harness.io.meshfile import read_mesh
    mesh = read_mesh(args.mesh, args.format)
    check_mesh(mesh, str(args.mesh))          # the mesh's mistakes first, before anything is built on it
    with tempfile.TemporaryDirectory(prefix="springbench-calibrate-") as tmp:
        tmp = Path(tmp)
        try:
            rows, net, case = _run(args, mesh, tmp)
            _report(args, rows, net, case)       # the case may read its mesh file (in tmp) again
        except SpringbenchError as exc:   # name the user's mesh, never our temporary files
            if exc.file is None or str(tmp) in str(exc.file):
                raise type(exc)(exc.message, file=str(args.mesh), field=exc.field, fix=exc.fix) from None
            raise
    return 0


def mesh_case(args, mesh, tmp: Path):
    """The in-memory case of ``args`` for the read ``mesh`` (its file written to tmp when
    it must be scaled to m), printing the clamp and load faces it chose."""
    from harness.case.default_loads import end_loads
    from harness.case.reader import load_case
    from harness.io.mesh_groups import require_group, scaled_copy
    for flag, group in (("--clamp", args.clamp), ("--load-region", args.load_region)):
        if group is not None and args.heldout == "none":
            raise SpringbenchError("--heldout none has no held-out loads", field=flag, fix="drop it, or --heldout ends")
        if group is not None:
            require_group(mesh, group, file=str(args.mesh), field=flag)
    mesh_file = None
    if args.length_unit != "m" or args.format == "bc2000":     # hand the body over in metres
        import meshio
        mesh_file = tmp / "mesh.vtu"
        if args.clamp or args.load_region:                     # the file itself, scaled: its groups stay
            mesh_file = scaled_copy(args.mesh, args.format, UNITS[args.length_unit], tmp)
        else:
            meshio.write(mesh_file, meshio.Mesh(mesh.points * UNITS[args.length_unit],
                                                [(c, a) for c, a in mesh.cells.items()]))
        print(f"  mesh coordinates in {args.length_unit}: scaled by {UNITS[args.length_unit]:g} to m",
              file=sys.stderr)
    pts = mesh.points * UNITS[args.length_unit]
    ends = end_loads(pts, mesh.cells, args.clamp, args.load_region, mesh.groups) if args.heldout == "ends" else None
    if ends is not None:     # on stdout, before the work: a wrong clamp is seen at once
        print(f"{ends.describe()}; --clamp GROUP clamps a named face group of the mesh instead", flush=True)
    (tmp / "calibrate.toml").write_text(case_text(args, mesh.dim, mesh.cells, mesh_file, None, ends))
    try:
        case = load_case(tmp / "calibrate.toml")
    except CaseError as exc:
        raise SpringbenchError(exc.message, file=str(args.mesh), field=exc.field, fix=exc.fix) from None
    return case


def _run(args, mesh, tmp: Path):
    """(rows, the exported network, the case) of one calibration in the folder tmp."""
    from harness.export.vtu import read_vtu
    from harness.stages import StageContext
    from harness.stages import sms as stage
    from harness.stages.sms_measures import rank
    case = mesh_case(args, mesh, tmp)
    from harness.commands.calibrate_progress import tracker
    from harness.progress import Clock
    clock = Clock("calibrate")           # on a terminal only (and not with --quiet)
    try:
        ctx = StageContext(out_dir=tmp / "out", seed=args.seed,
                           status=tracker(clock, args.budget, selects(args)))
        rows = stage.run(case, ctx)
    finally:
        clock.close()
    if args.method == "rule":
        exported = min(rows, key=rank) if args.rule == "best" else rows[0]
    else:
        exported = rows[-1]
    tag = exported["stiffness"] if exported.get("optimizer", "none") == "none" else \
        f"{exported['stiffness']}-select" if "choice" in exported else f"{exported['stiffness']}-{exported['optimizer']}"
    net, _ = read_vtu(ctx.out_dir / f"model-{tag}.vtu")
    if (ctx.out_dir / f"volume-{tag}.npz").exists():       # springs + volume: the term beside the VTU
        from harness.models.volume import load
        net = load(ctx.out_dir / f"volume-{tag}.npz", net)
    if (ctx.out_dir / f"kn-{tag}.npz").exists():           # springs + kn (harness/models/kn.py)
        from harness.models.kn import load as load_kn
        net = load_kn(ctx.out_dir / f"kn-{tag}.npz", net)
    if args.k_ratio is not None:
        capped = _capped_row(net, case, exported, args.k_ratio, args.damping_ratio)
        rows.append(capped)
        net, exported = capped.pop("_net"), capped
    for r in rows:
        r["exported"] = r is exported
    validation = ctx.out_dir / "validation.csv"
    if validation.exists():               # the validated fit's table (harness/stages/sms_select.py)
        import pandas as pd
        exported["_validation"] = pd.read_csv(validation).to_dict("records")
    return rows, net, case


def _capped_row(net, case, row, ratio: float, zeta: float) -> dict:
    """The exported constants capped at ratio x their median, scored like the stage does
    (fitted and held-out loads), with the stable step of both (what the cap gains)."""
    import numpy as np

    import reference
    from harness.export.engine import spring_damping, stable_step
    from harness.mechanics import statics
    from harness.scoring import case_weights, fit_and_heldout, reference_displacements
    k = np.asarray(net.k, float)
    capped = net.with_k(np.minimum(k, ratio * np.median(k)))
    ref = reference.solve(case)             # cached by the stage's solve
    res = statics.solve(capped, case)
    u_ref = reference_displacements(ref, capped.points, res.names)
    sc, sh = fit_and_heldout(u_ref, res.u, capped.classes, case_weights(case), res.names, case.fit_loads, case.heldout)
    out = {k_: v for k_, v in row.items() if k_ in ("model", "stiffness", "n_nodes", "n_springs", "seed", "G_ref",
                                                     "G_ref_heldout", "ref_error_max", "ref_error_heldout")}
    out.update(optimizer=f"{row.get('optimizer', 'none')}+k-ratio {ratio:g}", G_norm_initial=row.get("G_norm_final"),
               G_norm_final=sc.G_norm, G_heldout=sh.G_norm if sh else math.nan,
               k_ratio=float(capped.k.max() / np.median(capped.k)), _net=capped)
    if sh is not None:
        per = {f"G_heldout_{name}": float(v) for name, v in sh.per_load_norm.items()}
        out.update(G_heldout_mean=float(np.mean(list(per.values()))), **per)
    if "status" in row:     # the reference's error against the capped constants' (harness/scoring.py ref_status)
        from harness.scoring import ref_status
        out["status"] = ref_status(row.get("G_ref", math.nan), sc.G_norm, row.get("ref_met_tol"))
        if sh is not None and ref_status(row.get("G_ref_heldout", math.nan), sh.G_norm, None) != "ok":
            out["status"] = "ref-coarse"
    if np.all(net.masses > 0):
        for r, n in ((row, net), (out, capped)):
            kd = spring_damping(n.springs, n.k, n.masses, zeta)
            r["dt_stable"] = stable_step(n.points, n.springs, n.k, n.masses, kd,
                                         volume=getattr(n, "volume", None))["dt_stable"]
    row["k_ratio"] = float(k.max() / np.median(k))
    return out


def _choice(args, row) -> str:
    """The JSON's ``choice``: 'rule' (the rule's constants exported: --method rule, or no
    candidate beat the rule on validation), the validated candidate's name, or 'fit'
    (a fit whose capacity the user fixed)."""
    if row.get("optimizer", "none") == "none":
        return "rule"
    return str(row.get("choice", "fit"))


def _worst(*values) -> float:
    """The largest value, NaN if any is NaN (a load without an estimate: none overall)."""
    return math.nan if any(math.isnan(v) for v in values) else max(values)


def positive(net) -> bool:
    """Whether every mass is positive (an explicit engine can run the network)."""
    import numpy as np
    return bool(np.all(np.asarray(net.masses) > 0))


def _report(args, rows, net, case):
    """Write MODEL.vtu/.json/.csv and print the table and the verdict."""
    import pandas as pd

    from harness.commands import calibrate_verdict as cv
    from harness.export.model_json import export
    from harness.report.findings import heldout_error
    from harness.stages.sms_measures import rank
    exported = next(r for r in rows if r["exported"])
    from_row = dict(G_norm="G_norm_final", G_norm_heldout="G_heldout", G_heldout_mean="G_heldout_mean",
                    reference_error_fitted="ref_error_max", reference_error_heldout="ref_error_heldout",
                    validation_skipped="val_skipped", G_heldout_mean_spread="G_heldout_mean_spread",
                    mass_residual="mass_residual")       # JSON key: the exported row's column
    meta = dict(E=args.E, nu=args.nu, density=args.density, damping_ratio=args.damping_ratio,
                loads_fitted=list(case.fit_loads), loads_heldout=list(case.heldout),
                **{key: exported.get(col, math.nan) for key, col in from_row.items()},
                G_heldout_loads={n: cv.finite(exported.get(f"G_heldout_{n}")) for n in case.heldout},
                reference_error=_worst(exported.get("ref_error_max", math.nan), exported.get("ref_error_heldout", 0.0)),
                choice=_choice(args, exported), validation=cv.records(exported.pop("_validation", None)),
                masses=args.masses, prior_weight=(exported.get("opt_prior", math.nan) if "choice" in exported else
                                                  prior_weight(args) if args.method == "lbfgs" else math.nan))
    rules = [r for r in rows if r.get("optimizer", "none") == "none"]
    said, rule = cv.verdict(exported, rules) if case.heldout else (None, None)
    stops = exported.get("opt_stops") or exported.get("opt_stop")
    meta.update(status=str(exported.get("status", "ok")), verdict=said,
                best_rule_heldout=None if rule is None else {"rule": rule["stiffness"],
                                                             "G_heldout_mean": cv.finite(heldout_error(rule))},
                opt_stop=exported.get("opt_stop") if isinstance(exported.get("opt_stop"), str) else None,
                opt_stops=stops.split(" | ") if isinstance(stops, str) else [])
    from harness.export.engine_loads import load_records, settle_recipe
    meta.update(load_records(net, case), settle_damping=settle_recipe(net, case) if positive(net) else None)
    cols = [c for c in ("model", "stiffness", "optimizer", "exported", "n_nodes", "n_springs", "G_initial", "G_final",
                        "G_norm_initial", "G_norm_final", "G_fit_score", "G_fit_score_bound", "G_heldout",
                        "G_heldout_mean", "G_heldout_mean_spread",
                        "choice", "ref_error_max", "ref_error_heldout", "status",
                        "k_ratio", "dt_stable", "dt_safe", "seconds", "seed", "opt_stop", "opt_stops", "opt_prior",
                        "note")
            if any(c in r for r in rows) or c == "dt_safe"]
    from harness.outputs import staged
    out = args.out              # the three files appear together or not at all (disk full: none)
    with staged([out, out.with_suffix(".json"), out.with_suffix(".csv")], "--out") as (vtu, _, csv):
        data = export(net, vtu, meta)         # writes vtu and its .json beside it (harness/export/model_json.py)
        exported.update(dt_stable=data["dt_stable"], dt_safe=data.get("dt_safe"))   # one step, the JSON's, in the table
        df = pd.DataFrame(rows).reindex(columns=cols)
        df.to_csv(csv, index=False)
    print(df.drop(columns=["opt_stops"], errors="ignore").to_string(index=False))
    print(cv.heldout_sentence(exported, rules, case.heldout))
    print(cv.fitted_sentence(exported, min(rules, key=rank)))
    print(cv.reference_sentence(exported, meta, bool(case.heldout), args.max_refine))
    if "choice" in exported:
        print(cv.validation_sentence(exported, meta["validation"] or []))
    step = (f"dt_stable {data['dt_stable']:.3g} s (float32 {data['dt_stable_float32']:.3g} s, safe {data['dt_safe']:.3g} s)"
            if data["dt_stable"] is not None else data.get("warning", ""))
    print(f"-> {args.out} (+ .json, .csv): {net.n_nodes} nodes, {net.n_springs} springs, masses {args.masses}, "
          f"k {min(data['spring_stiffness']):.3g}..{max(data['spring_stiffness']):.3g} N/m, {step}")
