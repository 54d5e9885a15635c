"""calibrate's flag checks: every bad value is one line naming the flag, before any work."""

from __future__ import annotations

import math

import numpy as np

from harness.case.default_loads import PEAK_STRAIN
from harness.commands import calibrate_engine as engine
from harness.errors import SpringbenchError

# closer to 0.5, lambda / mu > 5e4: the displacement FEM's stiffness is singular to rounding
NU_MAX = 0.49999


def _bad(flag, msg, fix):
    raise SpringbenchError(msg, field=flag, fix=fix)


def check(s, prior_weight: float) -> None:
    """Raise a one-line SpringbenchError naming the flag of the first bad value (before any
    work): the material, the loads, the fit, the reference, the numbers' range, the files."""
    _material(s)
    _loads(s)
    _fit(s, prior_weight)
    engine.check(s)
    _reference(s)
    _ranges(s)
    _files(s)
    check_format(s.format)


def _material(s) -> None:
    if not (math.isfinite(s.E) and s.E > 0):
        _bad("--E", f"E must be positive, got {s.E:g}", "Young's modulus in Pa, e.g. --E 2e5")
    if not (-1 < s.nu < 0.5):
        _bad("--nu", f"{s.nu} is out of range", "a Poisson ratio in (-1, 0.5), e.g. --nu 0.3")
    if s.nu > NU_MAX:
        _bad(
            "--nu",
            f"{s.nu} is incompressible to rounding: the FEM reference's stiffness would "
            "be singular",
            f"--nu {NU_MAX:g} at most",
        )
    if not (math.isfinite(s.density) and s.density > 0):
        _bad(
            "--density",
            f"density must be positive, got {s.density:g}",
            "kg/m^3, e.g. --density 1000",
        )


def _loads(s) -> None:
    if s.magnitude is not None and not (math.isfinite(s.magnitude) and s.magnitude > 0):
        _bad("--magnitude", f"{s.magnitude} is not a positive number", "a traction in Pa")
    peak = s.peak_strain
    if not (math.isfinite(peak) and 0 < peak <= 0.1):
        _bad(
            "--peak-strain",
            f"{peak} is not in (0, 0.1]",
            f"a small strain, e.g. --peak-strain {PEAK_STRAIN:g}",
        )
    if not (math.isfinite(s.damping_ratio) and 0 <= s.damping_ratio < 1):
        _bad("--damping-ratio", f"{s.damping_ratio} is not in [0, 1)", "e.g. --damping-ratio 0.05")


def _fit(s, prior_weight: float) -> None:
    if s.prior_weight is not None and not (math.isfinite(s.prior_weight) and s.prior_weight >= 0):
        _bad(
            "--prior-weight",
            f"{s.prior_weight} is not a number >= 0",
            f"e.g. --prior-weight {prior_weight:g}, or 0 for none",
        )
    if s.prior_weight is not None and s.method != "lbfgs":
        _bad(
            "--prior-weight",
            f"--method {s.method} has no prior",
            "use --prior-weight with --method lbfgs",
        )
    if s.init != "none" and s.method not in ("lbfgs", "gauss-newton"):
        _bad(
            "--init",
            f"--method {s.method} has no start point to set",
            "use --init with --method lbfgs or gauss-newton",
        )
    if s.budget is not None and not (math.isfinite(s.budget) and s.budget > 0):
        _bad("--budget", f"{s.budget} is not a positive number of seconds", "e.g. --budget 600")
    if s.k_ratio is not None and not (math.isfinite(s.k_ratio) and s.k_ratio >= 1):
        _bad("--k-ratio", f"{s.k_ratio} is not a ratio >= 1", "e.g. --k-ratio 100")
    if s.seed < 0:
        _bad("--seed", f"{s.seed} is negative", "a seed >= 0, e.g. --seed 0")


def _reference(s) -> None:
    if not (math.isfinite(s.tol) and 1e-12 <= s.tol < 1):
        _bad(
            "--tol",
            f"{s.tol} is not a relative error in [1e-12, 1) (below it, rounding)",
            "e.g. --tol 1e-2",
        )
    if s.max_refine < 0:
        _bad(
            "--max-refine",
            f"{s.max_refine} is negative",
            "e.g. --max-refine 100 (until --tol), or 0 for no error estimate",
        )


def _ranges(s) -> None:
    """The numbers a case file may hold (E's lower end leaves room for the default traction,
    1e-3 E)."""
    from harness.case.schema import LARGEST, SMALLEST

    for flag, v, lo in (
        ("--E", s.E, 1e3 * SMALLEST),
        ("--density", s.density, SMALLEST),
        ("--magnitude", s.magnitude, SMALLEST),
    ):
        if v is not None and not lo <= v <= LARGEST:
            _bad(
                flag,
                f"{v:g} is too {'large' if v > LARGEST else 'small'} to compute with",
                f"a value between {lo:g} and {LARGEST:g}: change the units",
            )


def _files(s) -> None:
    """The outputs writable and not the mesh (before the work, not after it); the mesh a file."""
    from harness.outputs import check_out_file

    if s.out.suffix.lower() != ".vtu":
        _bad("--out", f"'{s.out}' does not end in .vtu", "e.g. --out model.vtu")
    if s.save_case is not None:
        check_out_file(s.save_case, "--save-case")
    for out in (s.out, s.out.with_suffix(".json"), s.out.with_suffix(".csv")):
        if out.resolve() == s.mesh.resolve():
            _bad(
                "--out",
                f"{out} is the mesh itself: calibrate would overwrite it",
                "e.g. --out model.vtu",
            )
        check_out_file(out, "--out")
    if not s.mesh.is_file():
        raise SpringbenchError(
            "is a folder, not a mesh file" if s.mesh.is_dir() else "no such mesh file",
            file=str(s.mesh),
            fix="check the path",
        )


def check_format(fmt: str | None) -> None:
    """--format names a reader of ours or a meshio format (None: told by the file name)."""
    if fmt is None:
        return
    from meshio._helpers import reader_map

    from harness.registry import MESH_READERS

    known = [*MESH_READERS, *sorted(reader_map)]
    if fmt not in known:
        raise SpringbenchError(
            f"unknown mesh format '{fmt}'",
            field="--format",
            fix=f"one of {', '.join(known)}; or drop --format to tell it by the file name",
        )


SOFTEST = 100.0  # Pa: no solid body is softer (gels and brain tissue: a few hundred Pa and up)
DENSITIES = (10.0, 30_000.0)  # kg/m^3: aerogels and foams ... osmium (22,590)
SIZES = (1e-4, 10.0)  # m: a body from a tenth of a millimetre to ten metres across


def unit_warnings(s, mesh) -> list[str]:
    """One warning line per value outside what SI bodies have (module constants), naming the
    unit it looks like and the flag that fixes it: warnings, not errors (an odd body may be
    right), printed before the work."""
    out = []
    if s.E < SOFTEST:
        gpa = f", or GPa (--E {s.E * 1e9:g})" if s.E >= 1 else ""
        out.append(
            f"warning: --E {s.E:g} Pa is softer than any solid body (under {SOFTEST:g} Pa): "
            f"looks like MPa: give Pa (--E {s.E * 1e6:g}){gpa}"
        )
    lo, hi = DENSITIES
    if s.density < lo:
        out.append(
            f"warning: --density {s.density:g} kg/m^3 is lighter than any solid body (under "
            f"{lo:g}): looks like g/cm^3: give kg/m^3 (--density {s.density * 1e3:g})"
        )
    if s.density > hi:
        out.append(
            f"warning: --density {s.density:g} kg/m^3 is denser than any material (over "
            f"{hi:,.0f}): looks like g/m^3: give kg/m^3 (--density {s.density * 1e-3:g})"
        )
    return out + size_warnings(s, mesh)


def size_warnings(s, mesh) -> list[str]:
    """The line for a body over 10 m or under 0.1 mm across, naming --length-unit."""
    from harness.commands.calibrate_case import UNITS

    scale = UNITS[s.length_unit]
    size = float(np.ptp(mesh.points, axis=0).max()) * scale
    lo, hi = SIZES
    if lo <= size <= hi:
        return []
    # the likeliest first: mm for a body too large, m for one too small
    order = sorted(UNITS.items(), key=lambda uf: uf[1] if size > hi else -uf[1])
    fits = [
        f"--length-unit {u} ({size * f / scale:.3g} m)"
        for u, f in order
        if (f < scale if size > hi else f > scale) and lo <= size * f / scale <= hi
    ]
    likely = (
        f"looks like {fits[0].split()[1]}: {' or '.join(fits)}"
        if fits
        else ("check the mesh's unit (--length-unit: m, cm or mm)")
    )
    what = "over 10 m" if size > hi else "under 0.1 mm"
    return [
        f"warning: the body is {size:.3g} m across ({what}; mesh coordinates in "
        f"{s.length_unit}): {likely}"
    ]
