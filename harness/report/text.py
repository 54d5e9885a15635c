"""The words of the results page: what each suite reproduces, short case labels, figure
captions, the glossary of columns. Text only (no numbers: those come from the stored
results), so the page builder (:mod:`harness.report.page`) stays about layout."""

from __future__ import annotations

import re

UNITS = (
    "Units: our G is G_{a:b:c} in the case's length unit (metres); the normalised G divides it by "
    "the reference's own weighted norm, so 0.05 is a 5 % RMS displacement error. The "
    "papers' G is in "
    "units they do not state: compare improvement factors and trends, never the absolute values."
)

SUITES = {
    "deussen1995": (
        "Deussen, Kobbelt & Tücke 1995: spring/mass systems fitted by simulated annealing",
        "Deussen, Kobbelt and Tücke (1995) place springs and masses in a plate (grids, "
        "rectangular cells, an "
        "inhomogeneous plate, random points after Lloyd iterations) and a 3-D box, and tune "
        "the spring "
        "constants by simulated annealing until the network's displacements under the basic "
        "loads match "
        "linear elasticity. We reproduce Figs. 8-12 and Section 6 against a converged FEM "
        "reference, run "
        "gradient fits beside SA on the same models, and score every fit on loads it never saw.",
    ),
    "bourguignon2000": (
        "Bourguignon & Cani 2000: controlling anisotropy in mass-spring systems",
        "Bourguignon and Cani (2000) replace the mesh-edge springs by springs along three "
        "axes of interest "
        "per element (MT0) plus volume forces (MT). We run their model on the original "
        "program's meshes, "
        "reproduce the program's volume curves (Fig. 3) and timing (Table 1), and go where "
        "the paper did "
        "not: MS, MT0 and MT scored against isotropic and transversely isotropic FEM, "
        "calibrated, and "
        "tested for undesired anisotropy by pulls in 12 directions.",
    ),
    "nu_sweep": (
        "The Poisson-ratio map: which model imitates elasticity best at each nu",
        "A box lattice, a plate and a gmsh cylinder at nine Poisson ratios from 0 to 0.49: "
        "each model class "
        "(springs with a stiffness rule or fitted, springs with a volume term or Kot & "
        "Nagahashi's term, "
        "Bourguignon & Cani's element model, linear FEM on the same cells) fitted on the "
        "training states and "
        "scored on held-out loads it never saw (sag, tip, torsion, a two-end-clamped "
        "bridge). Held-out loads "
        "never choose a row; the findings below name the model with the lowest mean "
        "held-out error per body "
        "and nu, and call gaps inside a fit's spread over its starts ties.",
    ),
    "engines": (
        "Engines: how far each engine's deformable body is from linear elasticity",
        "Four gmsh bodies (a box beam, a round bar, a curved elbow, a holed tapered bar) at "
        "two resolutions and nu = 0.3, "
        "0.45 and 0.49, clamped and loaded as a benchmark pack: each engine's own model "
        "from E and nu (NVIDIA "
        "Newton's tetrahedral FEM, MuJoCo's flex elasticity) and springbench's exports of "
        "the same mesh (the "
        "best stiffness rule, the calibrated model) run in Newton, all driven to static "
        "equilibrium on the CPU "
        "and scored against the FEM on held-out loads (sag, tip, tip2, torsion, bridge).",
    ),
    "verification": (
        "Verification of the FEM reference",
        "Every score above is only as good as the reference. These cases check the "
        "scikit-fem reference "
        "against closed forms, its own error estimate and Euler-Bernoulli's cantilever "
        "frequency, on every "
        "element type and method the suites use.",
    ),
}

CASES = {
    "fig08_grid25_grouped": "Fig. 8: 5x5 grid, grouped h/v/diag",
    "fig09_grid25_separate": "Fig. 9: 5x5 grid, all separate",
    "fig10_rectangular_anisotropic": "Fig. 10: rectangular cells, orthotropic",
    "fig11_inhomogeneous": "Fig. 11: left third twice as stiff",
    "sec6_box3d": "Sec. 6: box 4x4x4, nine loads",
    "volume_cube343": "Fig. 3 volume, cube_343",
    "volume_beam336": "volume, beam_336",
}


def case_label(case: str) -> str:
    """A short label for a table row: ``fig12_lloyd05`` -> "Fig. 12: 5 Lloyd iterations"."""
    m = re.fullmatch(r"fig12_lloyd(\d+)", str(case))
    if m:
        return f"Fig. 12: 36 random points, {int(m.group(1))} Lloyd it."
    return CASES.get(str(case), str(case))


# (path under the suite folder, caption): shown full width, in this order, when present
KEY_FIGURES = {
    "deussen1995": [
        (
            "fig-lloyd-bars.png",
            "Deussen Fig. 12: left, G before and after each fit per Lloyd iteration count "
            "(log axis; mean and standard deviation over 3 seeds); right, the trend "
            "G_final / G_final at 0 iterations, ours beside the paper's.",
        ),
        (
            "fig08_grid25_grouped/fig-deformed-deussen-sa.png",
            "Deussen Fig. 8: the 5x5 grid with grouped constants after SA, deformed under "
            "each load "
            "(magnified): the network (blue) against the FEM displacement of the same nodes (red).",
        ),
        (
            "fig09_grid25_separate/fig-trace.png",
            "Fig. 9: G against optimiser steps, SA and the gradient fits from the same "
            "start (log axes).",
        ),
        (
            "sec6_box3d/fig-deformed-deussen-sa.png",
            "Section 6: the 4x4x4 box after SA, every load in a 3-D view of the surface "
            "springs (magnified): "
            "network (blue) against the FEM at the same nodes (red), rest shape grey.",
        ),
        (
            "fig12_lloyd50/seed0/fig-lloyd.png",
            "Deussen Fig. 2: Lloyd iterations even out the random points (seed 0): spread "
            "of neighbour "
            "distances and of region sizes.",
        ),
        (
            "fig09_grid25_separate/fig-spectrum.png",
            "Fig. 9: natural frequencies of each model against the FEM's.",
        ),
    ],
    "nu_sweep": [
        (
            "fig-nu-sweep-families.png",
            "Held-out normalised G per load family (sag, tip, torsion, bridge) against "
            "Poisson's ratio: each class's fitted row solid, the unfitted stiffness rules "
            "dashed.",
        ),
        (
            "fig-nu-sweep.png",
            "Normalised G against Poisson's ratio per model class, fitted and held-out loads; the "
            "Cauchy ratio marked.",
        ),
    ],
    "engines": [
        (
            "fig-engines.png",
            "Mean G_norm over the held-out loads against Poisson's ratio, per body: each engine's "
            "own model and springbench's exports run in Newton; coarse mesh dashed, fine "
            "solid (Newton's and "
            "MuJoCo's tetrahedra coincide).",
        )
    ],
    "bourguignon2000": [
        (
            "volume_cube343/fig-volume.png",
            "Bourguignon & Cani Fig. 3: relative volume variation of MS, MT0 and MT on "
            "cube_343 under gravity; "
            "ours solid, the original program's recorded curves dashed; below, the difference.",
        ),
        (
            "volume_beam336/fig-volume.png",
            "beam_336, MT0: our volume curve against the program's own record vol.txt.",
        ),
        (
            "fem_cube333_tetra/fig-anisotropy.png",
            "Undesired anisotropy: effective Young's modulus of each model under a uniaxial "
            "pull along 12 "
            "directions in the x-y plane (isotropic FEM dashed: a circle).",
        ),
        (
            "fem_cube333_tetra_fibre/fig-anisotropy.png",
            "The same with a transversely isotropic material (uniform fibre): the FEM's own "
            "anisotropy dashed.",
        ),
        (
            "fibres_cube353/fig-fibres-helicoidal.png",
            "Bourguignon & Cani Fig. 6: the helicoidal fibre field of cube_353 after the pull.",
        ),
    ],
}

KINDS = [  # (file name pattern, caption of any figure of that kind)
    (r"fig-trace\.png", "G against optimiser steps (log axes)."),
    (r"fig-lloyd\.png", "Lloyd statistics against iterations (Deussen Fig. 2)."),
    (
        r"fig-lloyd-bars\.png",
        "G per Lloyd iteration count (Deussen Fig. 12), ours and the paper's trend.",
    ),
    (
        r"fig-nu-sweep\.png",
        "Normalised G against Poisson's ratio per model class (fitted and held-out loads), "
        "Cauchy ratio marked.",
    ),
    (
        r"fig-nu-sweep-families\.png",
        "Held-out normalised G per load family (sag, tip, torsion, bridge) against "
        "Poisson's ratio: each class's fitted row solid, the unfitted stiffness rules dashed.",
    ),
    (
        r"fig-(bench-)?engines\.png",
        "Each engine's mean G_norm over the held-out loads against Poisson's ratio.",
    ),
    (r"fig-volume\.png", "Relative volume variation against time (Bourguignon & Cani Fig. 3)."),
    (
        r"fig-bench-reference\.png",
        "Benchmarks: the FEM solve's time against its unknowns per element and solver "
        "(left); the reference's true error against an independent solve (right).",
    ),
    (r"fig-spectrum\.png", "Natural frequencies of the models against the FEM."),
    (r"fig-anisotropy\.png", "Effective Young's modulus against pull direction (polar)."),
    (r"fig-deformed-?(.*)\.png", "Deformed shapes, model {0} (blue) against the FEM (red)."),
    (r"fig-fibres-?(.*)\.png", "Fibre directions {0} (Bourguignon & Cani Fig. 6)."),
]


def figure_caption(name: str) -> str:
    """A generic caption from a figure's file name."""
    for pattern, text in KINDS:
        m = re.fullmatch(pattern, name)
        if m:
            return text.format(*(g or "" for g in m.groups())).replace("  ", " ").replace(" )", ")")
    return name


BENCH = {
    "sa": "incremental SA against the refactorising SA: steps per second, same chain",
    "fit": "G / G0 reached in 60 s on recoverable networks, with and without noise",
    "dynamics": "ms per simulated second against the original C++ program; spring updates "
    "per second",
    "calibrate": "a user's mesh end to end: seconds, memory, G before and after",
    "reference": "the FEM reference's true error and cost against an independent solve",
    "heldout": "calibrate against every stiffness rule on held-out gmsh bodies, loads and "
    "clamps it never saw",
    "run": "README's first command, springbench run (the quick tier): wall and CPU seconds, "
    "what it leaves in runs/",
}
