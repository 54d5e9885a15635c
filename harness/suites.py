"""The suites under cases/ and their quick tier: what ``springbench run`` runs when given no
case, so a newcomer's first command shows every capability in minutes.

A suite is a folder of case files (cases/<suite>/). Its quick tier is one case per
capability the suite shows, the cheapest that shows it, run at the case's quick budget;
``springbench run --full`` (or a folder, ``springbench run cases/``) runs every case.
:data:`QUICK_SECONDS` is the tier's CPU time as measured (``springbench bench run``
measures it again): what README's first command promises.
"""

from __future__ import annotations

from pathlib import Path

from harness.paths import DEFAULT_CASES

# (suite, case file stem, the capability it shows, its recorded seconds in one default
# run on a shared 2-core machine: the progress line's time left weighs the cases by them),
# in run order: the longest first, so the others run beside it
QUICK = (
    ("engines", "beam-coarse_nu0.30", "engines' own bodies and an export run in Newton", 182),
    ("nu_sweep", "box_nu0.30", "every model class and the validated fit, held-out loads", 66),
    ("bourguignon2000", "fem_cube333_tetra", "B&C's element model fitted to the FEM", 38),
    ("deussen1995", "fig08_grid25_grouped", "Deussen 1995: simulated annealing of a plate", 18),
    ("verification", "box_basic3d", "the FEM reference's own error estimate, 3-D", 13),
    ("verification", "cantilever_2d", "the FEM's first frequency against Euler-Bernoulli", 5.5),
    ("verification", "plate_strain_quad", "the FEM reference meets a closed-form solution", 0.7),
    ("bourguignon2000", "volume_cube343", "Bourguignon & Cani 2000: volume under gravity", 0.2),
    ("bourguignon2000", "pull_cube353", "Bourguignon & Cani 2000: pulls in every direction", 0.2),
    ("bourguignon2000", "fibres_cube353", "Bourguignon & Cani 2000: fibre directions", 0.3),
)
# CPU seconds (user + system) of the quick tier as one `springbench run` from an empty
# reference cache: the larger of two measurements (134 s and 169 s)
QUICK_SECONDS = 170.0


def suites(root: Path = DEFAULT_CASES) -> list[str]:
    """The suite folders of ``root``: those holding case files (``_*.toml`` excluded)."""
    return sorted(
        d.name
        for d in Path(root).iterdir()
        if d.is_dir() and any(not f.name.startswith("_") for f in d.rglob("*.toml"))
    )


def quick_cases(root: Path = DEFAULT_CASES) -> list[Path]:
    """The case files of the quick tier, in run order."""
    return [Path(root) / suite / f"{stem}.toml" for suite, stem, *_ in QUICK]


def quick_seconds() -> dict[tuple[str, str], float]:
    """(suite, case) -> the recorded seconds of each case of the quick tier."""
    return {(suite, stem): float(seconds) for suite, stem, _, seconds in QUICK}
