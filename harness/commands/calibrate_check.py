"""calibrate's flag checks: every bad value is one line naming the flag, before any work."""

from __future__ import annotations

import math

from harness.case.default_loads import PEAK_STRAIN
from harness.errors import SpringbenchError

# closer to 0.5, lambda / mu > 5e4: the displacement FEM's stiffness is singular to rounding
NU_MAX = 0.49999


def check(args, prior_weight: float) -> None:
    """Raise a one-line SpringbenchError naming the flag of the first bad value (before any
    work)."""

    def bad(flag, msg, fix):
        raise SpringbenchError(msg, field=flag, fix=fix)

    if not (math.isfinite(args.E) and args.E > 0):
        bad("--E", f"{args.E} is not a positive number", "Young's modulus in Pa, e.g. --E 2e5")
    if not (-1 < args.nu < 0.5):
        bad("--nu", f"{args.nu} is out of range", "a Poisson ratio in (-1, 0.5), e.g. --nu 0.3")
    if args.nu > NU_MAX:
        bad(
            "--nu",
            f"{args.nu} is incompressible to rounding: the FEM reference's stiffness would "
            "be singular",
            f"--nu {NU_MAX:g} at most",
        )
    if not (math.isfinite(args.density) and args.density > 0):
        bad("--density", f"{args.density} is not a positive number", "kg/m^3, e.g. --density 1000")
    if args.magnitude is not None and not (math.isfinite(args.magnitude) and args.magnitude > 0):
        bad("--magnitude", f"{args.magnitude} is not a positive number", "a traction in Pa")
    peak = getattr(args, "peak_strain", PEAK_STRAIN)
    if not (math.isfinite(peak) and 0 < peak <= 0.1):
        bad(
            "--peak-strain",
            f"{peak} is not in (0, 0.1]",
            f"a small strain, e.g. --peak-strain {PEAK_STRAIN:g}",
        )
    if not (math.isfinite(args.damping_ratio) and 0 <= args.damping_ratio < 1):
        bad(
            "--damping-ratio", f"{args.damping_ratio} is not in [0, 1)", "e.g. --damping-ratio 0.05"
        )
    if args.prior_weight is not None and not (
        math.isfinite(args.prior_weight) and args.prior_weight >= 0
    ):
        bad(
            "--prior-weight",
            f"{args.prior_weight} is not a number >= 0",
            f"e.g. --prior-weight {prior_weight:g}, or 0 for none",
        )
    if args.prior_weight is not None and args.method != "lbfgs":
        bad(
            "--prior-weight",
            f"--method {args.method} has no prior",
            "use --prior-weight with --method lbfgs",
        )
    if args.init != "none" and args.method not in ("lbfgs", "gauss-newton"):
        bad(
            "--init",
            f"--method {args.method} has no start point to set",
            "use --init with --method lbfgs or gauss-newton",
        )
    if not (math.isfinite(args.budget) and args.budget > 0):
        bad("--budget", f"{args.budget} is not a positive number of seconds", "e.g. --budget 60")
    if not (math.isfinite(args.tol) and 1e-12 <= args.tol < 1):
        bad(
            "--tol",
            f"{args.tol} is not a relative error in [1e-12, 1) (below it, rounding)",
            "e.g. --tol 1e-3",
        )
    if args.max_refine < 0:
        bad(
            "--max-refine",
            f"{args.max_refine} is negative",
            "e.g. --max-refine 1, or 0 for no error estimate",
        )
    if args.k_ratio is not None and not (math.isfinite(args.k_ratio) and args.k_ratio >= 1):
        bad("--k-ratio", f"{args.k_ratio} is not a ratio >= 1", "e.g. --k-ratio 100")
    if args.seed < 0:
        bad("--seed", f"{args.seed} is negative", "a seed >= 0, e.g. --seed 0")
    from harness.case.schema import LARGEST, SMALLEST  # what the case-file numbers may be

    # E's lower end leaves room for the default traction, 1e-3 E
    for flag, v, lo in (
        ("--E", args.E, 1e3 * SMALLEST),
        ("--density", args.density, SMALLEST),
        ("--magnitude", args.magnitude, SMALLEST),
    ):
        if v is not None and not lo <= v <= LARGEST:
            bad(
                flag,
                f"{v:g} is too {'large' if v > LARGEST else 'small'} to compute with",
                f"a value between {lo:g} and {LARGEST:g}: change the units",
            )
    if args.out.suffix.lower() != ".vtu":
        bad("--out", f"'{args.out}' does not end in .vtu", "e.g. --out model.vtu")
    from harness.outputs import check_out_file

    for out in (args.out, args.out.with_suffix(".json"), args.out.with_suffix(".csv")):
        if out.resolve() == args.mesh.resolve():
            bad(
                "--out",
                f"{out} is the mesh itself: calibrate would overwrite it",
                "e.g. --out model.vtu",
            )
        check_out_file(out, "--out")  # before the work, not after it
    if not args.mesh.is_file():
        raise SpringbenchError(
            "is a folder, not a mesh file" if args.mesh.is_dir() else "no such mesh file",
            file=str(args.mesh),
            fix="check the path",
        )
