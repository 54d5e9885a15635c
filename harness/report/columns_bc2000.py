"""The Bourguignon & Cani suite's columns (harness/stages/bc2000*.py): (name, unit,
meaning, page) rows that harness/report/columns.py turns into its entries."""

BC2000 = [
    ("comparison", "", "what the FEM rows compare: the model linearised at rest against linear FEM, same clamp, "
                       "gravity, density, E and nu", False),
    ("mechanisms", "count", "zero-energy modes of the linearised model under the case's constraints (> 0: no "
                            "static answer)", False),
    ("run_seconds", "s", "wall time of the simulated run", False),
    ("stiffness_spread", "", "(max - min) / mean of the six clamped face pulls' stiffness (0: the mesh adds no "
                             "anisotropy)", False),
    ("G_norm_gravity", "", "normalised G of the gravity load, linearised model against the FEM", False),
    ("G_norm_gravity_scaled", "", "G_norm_gravity after the best single scale of the model's displacement (the "
                                  "shape error alone)", False),
    ("tip_<load>_ratio", "", "the model's mean tip displacement along the load / the FEM's, for a load other than "
                             "gravity", False),
]
