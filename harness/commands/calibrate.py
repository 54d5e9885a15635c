"""springbench calibrate MESH --E .. --nu .. [--density ..] [--method ..] --out MODEL.vtu
(--method rule|sa|lbfgs|gauss-newton|equilibrium-gap)

Turns a user's own tri/quad/tet/hex mesh (any meshio format, or the bc2000 format) into
a calibrated spring/mass model an explicit engine can run: springs on the mesh edges
(hexahedra add their body diagonals), lumped element masses (never negative; ``--masses``),
initial constants by a stiffness rule (``--rule``; by default the best of them on the fitted
loads, which the fit then starts from), then spring
constants fitted (``--method``) so the network's statics match a FEM reference of the
same body and material on the fitted loads, and scored on held-out loads it never saw.

Fit (``--method lbfgs``, the default): the training states' relative misfits (the clamped
states together weigh as much as the free-traction states together) + a mean_e
log(k_e/k_rule,e)^2 are minimised by L-BFGS-B with an adjoint gradient. Which capacity
(per-spring constants with a = 1 or 0.1, or with one volume term per element as well) is
chosen by leave-one-family-out validation on the training states
(harness/optimize/select.py: constant, bending, torsion, shear-gradient, gravity, and the
clamped training states together); the held-out loads never choose. A candidate must beat
the rule on the validation score (the geometric mean of its free-traction and clamped errors
relative to the rule's); when none does, the rule's constants are exported (JSON ``choice``
= "rule"). The chosen fit starts from the rule (``[optimizer.select] starts`` adds its best
global scale and perturbed starts, ``G_heldout_mean_spread`` the spread of their held-out
error). ``--prior-weight a`` fixes a per-spring fit with weight a instead (no validation).
``--engine ENGINE`` (harness/commands/calibrate_engine.py; an export engine: newton-springs,
mujoco-springs) exports only what that engine runs natively (harness/registry.py
EXPORT_TERMS): the validation chooses among the candidates whose volume term it runs
(mujoco-springs: springs only), a ``--model`` with a term it cannot run is refused, and the
first line printed says what was restricted.

Loads (docs/design.md, "Load sets"). Fitted (``--loads linear``, the default): the equilibrated
linear
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
printed when chosen); ``--clamp`` and ``--load-region`` name a mesh group, a node file, a
box or a sphere to clamp and to load instead (harness/case/selectors.py; the torsion then
turns about the load region's mean outward normal). Fitted loads have stress
``--magnitude`` (default 1e-3 E), held-out loads a peak strain of about ``--peak-strain``
(default 1e-3): small strains.

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
  ``engine`` (``--engine``, or null) and ``candidates`` (the names the validation chose
  among, or null without a validated fit),
  ``loads_fitted``, ``loads_heldout``, ``loads_validation``, ``G_val_mean`` and
  ``G_val_loads`` (the validation loads of ``--model p1-global`` / ``p1`` and the export's errors
  there), ``validation_accepted``, ``training_dropped`` (training states the FEM cannot
  resolve, left out of the fit), ``prior_weight`` (lbfgs: ``--prior-weight``),
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
  energy; the JSON's ``units`` the forces): a volume term per element
  (``--model springs+volume-element``, ``springs+volume-shared``; harness/models/volume.py)
  ``volume_*``, run in Newton as tetrahedra with k_mu = 0, k_lambda = kv; one per node
  (``--model springs+node-volume-node``, ``springs+node-volume-shared``, or a
  ``+node-volume`` choice of the validation)
  ``node_volume_*``, run in Newton by harness/engines/newton_volume.py; Kot & Nagahashi's
  term (``--model springs+kn``, ``springs+kn-node``; harness/models/kn.py) ``kn_*``.
  ``--model p1-global`` (linear tetrahedra with one fitted pair E', nu' for engines with one
  material per body; harness/stages/classes/p1_global.py) writes ``E_effective``,
  ``nu_effective`` and per tetrahedron ``tet_indices``, ``tet_E``, ``tet_nu``, ``tet_k_mu`` and
  ``tet_k_lambda`` (Newton's inputs: 4/3 mu, lambda + 5/6 mu) instead of springs;
  ``--model p1`` (a fitted E, nu per tetrahedron with a prior toward ``--E``, ``--nu``;
  harness/stages/classes/p1_element.py) the same keys, ``tet_*`` per tetrahedron and
  ``E_effective``, ``nu_effective`` null unless every tetrahedron shares one pair.
  ``dt_stable`` includes the term.
  Newton traps: ``add_particle(pos, vel, mass, radius)`` radius only matters for contacts
  (give a small one, or the particles collide with each other); ``add_spring`` recomputes
  the rest length from the particle positions, so add the particles at ``particle_q``.
- ``MODEL-heldout.vtu`` and ``MODEL-heldout.png`` (with held-out loads) — the picture of the
  fit (calibrate_picture.py): per held-out load the FEM's and the model's displacement, the
  error per node and the held and loaded nodes; the worst load drawn.
- ``MODEL.csv`` — the table printed (with the ``seed`` and the optimiser's ``opt_stop``).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from harness.commands import calibrate_options as options
from harness.commands.calibrate_case import (
    PRIOR_WEIGHT,
)
from harness.errors import SpringbenchError

HELP = (
    "calibrate spring constants for your own mesh against FEM and export them "
    "(VTU, JSON for Newton/Warp/Taichi/SOFA: k, damping, masses, stable step)"
)
EPILOG = """outputs (SI units; lengths in m whatever --length-unit):
  MODEL.vtu   network for ParaView: points (m), line cells = springs, point data mass (kg), cell
              data stiffness (N/m, f = k (l - l0))
  MODEL.json  particle_q (m), particle_mass (kg), spring_indices, spring_rest_length (m),
              spring_stiffness (N/m), spring_damping (N s/m), spring_stiffness_times_length (N),
              damping_ratio, dt_stable and dt_stable_float32 (s), omega_max (rad/s), E (Pa), nu,
              density (kg/m^3), loads_fitted, loads_heldout, loads_validation (never fitted nor
              held out; --model p1-global, p1: its fit is exported only when it beats the plain
              P1 there), G_val_mean and G_val_loads (the export's errors on them),
              validation_accepted (whether they let the fit be exported; null: not judged on
              them), training_dropped (training states
              left out: the FEM's error on them above a third of the best rule's), G_norm and
              G_norm_heldout (RMS
              displacement error / RMS FEM displacement), G_heldout_mean (mean over the held-out
              loads of each one's own G_norm), G_heldout_loads ({load: G_norm}), choice (rule, the
              validated capacity, or fit), validation (the table that chose: each model's score per
              left-out family), validation_skipped (always null: the validation always runs),
              engine (--engine, or null), candidates (the names the validation chose among:
              --engine keeps those whose volume term it runs, a large mesh fewer: fit_counts;
              null without a validated fit), fit_counts ({level, candidates, folds, maxiter,
              starts, final_maxiter, work_gflop, budget_gflop}: the fits the validated fit
              ran, fewer on a large mesh, chosen before it from flop counts; null without a
              validated fit),
              G_heldout_mean_spread (over the final fit's starts),
              reference_error (FEM's own, relative; the worst of reference_error_fitted and
              reference_error_heldout), status (the exported row's reference status: ok, or
              ref-coarse: the FEM's own error is above a tenth of the model's or missed its tol),
              verdict (held-out loads: better, tie or fit-worse-than-rule for a fit, rule when a
              rule is exported, null without held-out loads), flags (the row's flags as
              springbench run gives them: ref-coarse, memorised, fit-worse-than-rule),
              best_rule_heldout ({rule, G_heldout_mean}: the best rule on the held-out loads),
              G_heldout_mean_tets (the plain linear tetrahedra with --E, --nu on the mesh: your
              engine's own body, never a candidate; null without held-out loads, with --model
              p1-global / p1 or on a mesh not all tetrahedra / triangles),
              opt_stop and opt_stops (the
              optimiser's whole stop message: the exported start's, and every start's),
              mass_residual, masses, prior_weight (lbfgs), units; --model springs+volume-* adds
              volume_indices, volume_rest (m^3; 2-D m^2), volume_stiffness (kv, Pa; 2-D N/m),
              volume_shared; a volume term per node (--model springs+node-volume-*, a +node-volume
              choice) adds node_volume_nodes, node_volume_rest (m^3; 2-D m^2), node_volume_stiffness
              (kv, Pa; 2-D N/m), node_volume_shared, node_volume_elements, node_volume_element_rest
              (m^3; 2-D m^2); --model springs+kn adds kn_nodes, kn_node_volume (m^3; 2-D m^2),
              kn_spring_count, kn_stiffness (kn, Pa; 2-D N/m), kn_shared; --model p1-global
              (linear tetrahedra, one fitted E', nu') adds E_effective (Pa), nu_effective and per
              tetrahedron tet_indices, tet_E (Pa), tet_nu, tet_k_mu and tet_k_lambda (Newton's
              inputs, Pa); --model p1 (a fitted E, nu per tetrahedron) the same keys, E_effective
              and nu_effective null unless every tetrahedron shares one pair; for engines: dt_safe
              (s: the step to use, 0.8 dt_stable, measured in NVIDIA Newton in float32),
              settle_damping ({c, omega_1, load, velocity_factor}: after every step v *=
              velocity_factor, mass damping c = 2 omega_1 about critical for the lowest mode), and
              per load clamped_nodes ({nodes, components}: the held node ids and components),
              loaded_nodes and forces (N, one row per loaded node) and gravity (m/s^2, already
              inside forces; null without a body force)
  MODEL.csv   the printed table: model, stiffness (rule), optimizer, exported (the row written;
              the row tets[E, nu], stiffness p1, optimizer not-a-candidate: the plain linear
              tetrahedra with --E, --nu, never exported nor ranked),
              n_nodes, n_springs, G_initial and G_final (weighted G, m), G_norm_initial and
              G_norm_final (fitted loads, pooled), G_rank_score (the mean G_norm of the
              held-out loads' end-swapped twins; ranks the rules first), G_fit_score (fitted
              loads: the mean of each family's and of the clamped states' own G_norm; ranks
              them next), G_heldout,
              G_heldout_mean, G_heldout_mean_spread, G_val_mean, val_fit, val_best_rule and
              val_accepted (the validation loads: each row's error, the fit's, the rule they rank
              first, whether the fit is exported), choice, ref_error_max and ref_error_heldout
              (the FEM's own error), status (ok / ref-coarse), k_ratio (max/median k, with
              --k-ratio), dt_stable (s, the JSON's), dt_safe (s), seconds, seed, opt_stop, opt_stops
              (every start's, " | " between), training_dropped (as the JSON's), ref_note (why the
              FEM missed its tol: the loads above it and how its levels ended)
  MODEL-heldout.vtu  with held-out loads: per load u_fem/LOAD and u_model/LOAD (m), error/LOAD
              (|u_model - u_fem| per node, m), held/LOAD and loaded/LOAD (0/1 per node)
  MODEL-heldout.png  the worst held-out load: the deformed shape coloured by the error, the
              held and loaded nodes marked
2-D meshes: unit thickness (k and masses per unit thickness).
the fit (lbfgs) minimises the training states' relative misfits + a mean(log(k/k_rule)^2); by
default its capacity (the prior weight a, a volume term per node or none) is chosen by
leave-one-family-out validation on the training states (the lowest geometric mean of its
free-traction and clamped errors relative to the rule's, below 0.99), and the rule is exported
when no candidate beats it there (JSON choice, validation); --prior-weight a fixes a per-spring
fit instead; MODEL.csv's opt_prior is a."""


def add_arguments(p):
    """calibrate's options (harness/commands/calibrate_options.py), in --help's order."""
    options.inputs(p)
    options.model(p)
    options.loads(p)
    options.body(p)
    options.reference(p)
    options.outputs(p)


def main(args) -> int:
    from harness.commands.calibrate_check import check
    from harness.commands.calibrate_progress import split
    from harness.commands.calibrate_run import run
    from harness.commands.calibrate_settings import Settings
    from harness.commands.calibrate_write import write
    from harness.progress import configure

    s = Settings.of(args)
    check(s, PRIOR_WEIGHT)
    configure(s.quiet)
    from harness.commands.calibrate_case import selects
    from harness.commands.calibrate_engine import engine_line

    if s.engine is not None:  # first: what the engine restricts, before the work
        print(engine_line(s, selects(s)), flush=True)
    from harness.case.mesh_checks import check_mesh
    from harness.commands.calibrate_check import unit_warnings
    from harness.io.meshfile import read_mesh

    mesh = read_mesh(s.mesh, s.format)
    check_mesh(mesh, str(s.mesh))  # the mesh's mistakes first, before anything is built on it
    for line in unit_warnings(s, mesh):  # before the work: minutes on a wrong unit are lost
        print(line, file=sys.stderr, flush=True)
    t0, spent = time.monotonic(), {}
    with tempfile.TemporaryDirectory(prefix="springbench-calibrate-") as tmp:
        tmp = Path(tmp)
        try:
            rows, net, case = run(s, mesh, tmp, spent)
            write(s, rows, net, case)
        except SpringbenchError as exc:  # name the user's mesh and flags, never our temporary files
            field = "--budget" if exc.field == "optimizer.options.max_seconds" else exc.field
            if exc.file is None or str(tmp) in str(exc.file) or field != exc.field:
                raise type(exc)(exc.message, file=str(s.mesh), field=field, fix=exc.fix) from None
            raise
    if not s.quiet:  # where the time went (reported, never used for a choice)
        print(split(spent, time.monotonic() - t0), file=sys.stderr, flush=True)
    return 0
