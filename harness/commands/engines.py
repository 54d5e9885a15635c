"""springbench engines run ENGINE DIR [--model MODEL.json] --out U.npz | engines list:
drive a physics engine to static equilibrium on every load of a benchmark pack and write
its displacements (one (n, dim) array per load, NaN where it found none) for
``springbench score --displacements U.npz DIR`` (harness/engines/)."""

from __future__ import annotations

import math
import sys
from pathlib import Path

from harness.engines.settle import CHECK, FORCE_TOL, KE_TOL, RES_TOL, RTOL, STALL, UNSUPPORTED
from harness.errors import SpringbenchError

HELP = (
    "run a physics engine (NVIDIA Newton, MuJoCo) to equilibrium on a benchmark pack; "
    "list the engines"
)
EPILOG = f"""stopping rule (harness/engines/settle.py): every {CHECK} steps, settled when the
displacement's estimated distance still to go is at most {RTOL:g} of its largest value, the
residual (the net force's work on the FEM's displacement over the external force's) is at
most {RES_TOL:g} (or what one float32 spacing per coordinate could leave), the body moved
along its load, and the net force is at most {FORCE_TOL:g} of the external force or has
stopped falling over {STALL} checks while the kinetic energy is at most {KE_TOL:g} of the
load's work (float32 trembling); a residual above its bound is never settled. Velocities are
damped each step by exp(-2 omega_1 dt), omega_1 the lowest mode under the load's own holds.
The table gives per load the status (settled / not-settled / diverged / unsupported /
unsupported-load), steps,
simulated and wall time, final kinetic energy and relative residual;
--log writes it as CSV. U.npz is written again as each load finishes (Ctrl-C keeps the
finished loads) and holds the pack's digest, which score checks, and with --model which
model ran (its path, SHA-256 and E_effective, nu_effective), which score prints."""


def add_arguments(p):
    sub = p.add_subparsers(dest="action", metavar="ACTION", parser_class=type(p))
    sub.required = True
    ls = sub.add_parser("list", help="the engines and what each runs")
    ls.set_defaults(action="list")
    r = sub.add_parser("run", help="run ENGINE on every load of the pack DIR")
    from harness.engines import names

    r.add_argument("engine", metavar="ENGINE", help=f"one of {', '.join(names())}")
    r.add_argument("pack", type=Path, metavar="DIR", help="a benchmark pack (springbench pack)")
    r.add_argument(
        "--model",
        type=Path,
        default=None,
        metavar="MODEL.json",
        help="the calibrated model to run, from springbench calibrate on the pack's mesh: "
        "newton-springs, mujoco-springs: a springs export; newton-tets: a p1 or p1-global "
        "export (tet_k_mu, tet_k_lambda per tetrahedron); mujoco-flex: a p1-global export "
        "(E_effective, nu_effective as the flex's young, poisson); masses stay each "
        "engine's own (newton-tets, mujoco-flex: the pack's lumped rho V / 4)",
    )
    r.add_argument("--loads", default=None, metavar="A,B", help="run only these loads")
    r.add_argument(
        "--out", type=Path, required=True, metavar="U.npz", help="the displacements (npz)"
    )
    r.add_argument(
        "--log", type=Path, default=None, metavar="CSV", help="also write the table as CSV"
    )


def _only(pack, loads: str | None):
    """The pack with only the loads named by --loads (all when None)."""
    from harness.export.pack import Pack, named_loads

    if loads is None:
        return pack
    want = named_loads(loads, [ld.name for ld in pack.loads])
    kept = tuple(ld for ld in pack.loads if ld.name in want)
    return Pack(pack.points, pack.cells, pack.E, pack.nu, pack.density, kept, pack.plane, pack.meta)


def with_displacement(answers: dict) -> dict:
    """The answers that have a displacement to score: every one but an unsupported load's
    or a diverged run's (NaN); `score` names the others as missing."""
    import numpy as np

    return {name: a for name, a in answers.items() if np.all(np.isfinite(a.u))}


def _write_answer(out: Path, answers: dict, digest: str, record: dict | None = None) -> None:
    """The displacements so far, one array per load that has one, the pack's digest and
    the record of the model run, if any (atomically)."""
    import io
    import json

    import numpy as np

    from harness.engines.tet_material import MODEL_KEY
    from harness.export.pack import DIGEST_KEY
    from harness.outputs import atomic_write

    buf = io.BytesIO()
    fields = {name: a.u for name, a in with_displacement(answers).items()}
    extra = {} if record is None else {MODEL_KEY: json.dumps(record)}
    np.savez_compressed(buf, **fields, **{DIGEST_KEY: digest}, **extra)
    atomic_write(out, buf.getvalue(), "--out")


def _record(args) -> dict | None:
    """Which model ``--model`` runs and whose masses (module EPILOG), or None."""
    from harness.engines.tet_material import model_record
    from harness.registry import EXPORT_ENGINES

    if args.model is None:
        return None
    masses = (
        "the export's particle_mass"
        if args.engine in EXPORT_ENGINES
        else "the pack's density, lumped rho V / 4 (as without --model)"
    )
    return {**model_record(args.model), "masses": masses}


def _check_model(args) -> None:
    """One line when ``--model`` goes to an engine that takes none."""
    from harness.engines.settle import no_model
    from harness.registry import ENGINES, EXPORT_ENGINES, MATERIAL_ENGINES

    if args.engine in ENGINES and args.engine not in EXPORT_ENGINES + MATERIAL_ENGINES:
        no_model({"model": args.model}, args.engine)


def run_loads(run, pack, options: dict, out: Path, digest: str, record=None) -> dict:
    """Run the engine one load at a time, rewriting ``out`` as each finishes; on Ctrl-C
    say how many loads ``out`` keeps and exit 130."""
    import dataclasses

    answers: dict = {}
    written: dict = {}  # what ``out`` holds
    try:
        for ld in pack.loads:
            answers.update(run(dataclasses.replace(pack, loads=(ld,)), options))
            _write_answer(out, answers, digest, record)
            written = with_displacement(answers)
    except KeyboardInterrupt:
        n = len(pack.loads)
        kept = (
            f"{len(written)} of {n} loads kept in {out} "
            f"({sum(a.status == 'settled' for a in written.values())} settled): "
            f"{', '.join(written)}"
            if written
            else f"none of the {n} loads had finished; nothing written to {out}"
        )
        print(f"springbench: interrupted; {kept}", file=sys.stderr)
        raise SystemExit(130) from None
    return answers


def main(args) -> int:
    import pandas as pd

    from harness.engines import ENGINES, adapter
    from harness.outputs import atomic_write, check_out_file

    if args.action == "list":
        for name, (package, what) in ENGINES.about.items():
            print(f"{name:18s} {what} (needs {package})")
        return 0
    if args.out.suffix.lower() != ".npz":
        raise SpringbenchError(
            f"'{args.out}' does not end in .npz", field="--out", fix="e.g. --out u.npz"
        )
    for flag, out in (("--out", args.out), ("--log", args.log)):
        if out is not None:
            check_out_file(out, flag)
    if args.model is not None:
        _check_model(args)
    from harness.engines.tet_material import describe
    from harness.export.pack import pack_digest, read_pack

    full = read_pack(args.pack)
    run = adapter(args.engine)
    record = _record(args)
    pack, digest = _only(full, args.loads), pack_digest(full)
    answers = run_loads(run, pack, {"model": args.model}, args.out, digest, record)
    rows = [
        {
            "load": name,
            "status": a.status,
            "steps": a.steps,
            "sim_time_s": a.sim_time,
            "wall_s": a.wall,
            "kinetic_J": a.kinetic,
            "residual": a.residual,
            "note": a.note,
        }
        for name, a in answers.items()
    ]
    df = pd.DataFrame(rows)
    print(f"{args.engine} on {args.pack} ({pack.n_nodes} nodes, {len(pack.loads)} loads)")
    if record is not None:
        print(f"{describe(record)}; masses: {record['masses']}")
    print(
        df.to_string(index=False, float_format=lambda x: f"{x:.3g}" if math.isfinite(x) else "nan")
    )
    if args.log is not None:
        log = (
            df if record is None else df.assign(model=record["file"], model_sha256=record["sha256"])
        )
        atomic_write(args.log, log.to_csv(index=False).encode(), "--log")
    print(f"-> {args.out} (pack digest {digest})")
    return 0 if all(a.status in ("settled", *UNSUPPORTED) for a in answers.values()) else 1
