"""The Bourguignon & Cani suite's columns (harness/stages/bc2000*.py): (name, unit,
meaning, page) rows that harness/report/columns.py turns into its entries."""

BC2000 = [
    (
        "comparison",
        "",
        "what the FEM rows compare: the model linearised at rest against linear FEM, same clamp, "
        "gravity, density, E and nu",
        False,
    ),
    (
        "mechanisms",
        "count",
        "zero-energy modes of the linearised model under the case's constraints (> 0: no "
        "static answer)",
        False,
    ),
    ("run_seconds", "s", "wall time of the simulated run", False),
    (
        "stiffness_spread",
        "",
        "(max - min) / mean of the six clamped face pulls' stiffness (0: the mesh adds no "
        "anisotropy)",
        False,
    ),
    (
        "G_norm_gravity",
        "",
        "normalised G of the gravity load, linearised model against the FEM",
        False,
    ),
    (
        "G_norm_gravity_scaled",
        "",
        "G_norm_gravity after the best single scale of the model's displacement (the "
        "shape error alone)",
        False,
    ),
    (
        "tip_<load>_ratio",
        "",
        "the model's mean tip displacement along the load / the FEM's, for a load other than "
        "gravity",
        False,
    ),
    (
        "E_bending",
        "Pa",
        "E / tip_ratio: the Young's modulus the model shows in bending under gravity",
        False,
    ),
    (
        "E_stretch",
        "Pa",
        "E / the stretch load's tip ratio: the Young's modulus the model shows in tension",
        False,
    ),
    (
        "tip_deflection_linear",
        "m",
        "mean vertical tip displacement of the model linearised at rest, under gravity",
        False,
    ),
    (
        "tip_deflection_fem",
        "m",
        "the FEM's mean vertical tip displacement under the same gravity load",
        False,
    ),
    ("tip_ratio", "", "model tip deflection / FEM tip deflection, linearised at rest", True),
    (
        "flexion_ratio",
        "",
        "tip_ratio / the stretch load's ratio (1: the model bends as stiffly as its stretching "
        "implies; > 1: too soft in bending)",
        False,
    ),
    (
        "drift_max",
        "",
        "largest |mean transverse| / mean along-pull displacement over the six face pulls",
        False,
    ),
    (
        "elongation",
        "m",
        "mean vertical displacement of the pulled nodes over the second half of the run",
        False,
    ),
    (
        "lateral_drift",
        "m",
        "norm of the pulled nodes' mean horizontal displacement over the second half of the run",
        False,
    ),
    ("drift_ratio", "", "lateral_drift / |elongation|", False),
    (
        "thinning",
        "",
        "mean distance from the vertical centre line at mid height, deformed / rest",
        False,
    ),
    (
        "twist_deg",
        "deg",
        "twist of the pulled nodes about the vertical axis through their centroid",
        False,
    ),
    (
        "fibre_field",
        "",
        "the named fibre field of the run (vertical, horizontal, diagonal, hemicircular, "
        "helicoidal, random)",
        False,
    ),
    ("peak_abs_dV_percent", "%", "largest |V - V0| / V0 over the run", True),
    ("final_dV_percent", "%", "(V - V0) / V0 at the end of the run", False),
    (
        "max_dev_vs_original_percent",
        "%",
        "largest difference between our volume curve and the original "
        "program's recorded one, in points of percent",
        False,
    ),
    ("dt", "s", "the time step of the run", False),
    ("per_sim_second_ms", "ms", "wall time per simulated second (best of the repeats)", False),
    ("model_MS_ratio_per_second", "", "the model's time per simulated second / MS's", False),
    (
        "tip_deflection",
        "m",
        "mean vertical tip displacement over the second half of the dynamic run",
        False,
    ),
    (
        "tip_swing",
        "m",
        "peak-to-peak vertical tip motion over the second half of the run (still swinging)",
        False,
    ),
    ("tip_deflection_max", "m", "the lowest mean tip displacement during the run", False),
    (
        "tip_deflection_static",
        "m",
        "the nonlinear static equilibrium's mean tip displacement under the program's load",
        False,
    ),
    (
        "tip_deflection_linear_program_load",
        "m",
        "the linearised model's mean tip displacement under the program's load",
        False,
    ),
    (
        "static_nonlinearity",
        "",
        "tip_deflection_static / tip_deflection_linear_program_load",
        False,
    ),
    (
        "static_status",
        "",
        "how the nonlinear static solve ended (converged, a limit point, inverted elements)",
        False,
    ),
    ("static_load_factor", "", "the share of the program's load the static path reached", False),
    ("static_inverted_elements", "count", "elements inverted at the static equilibrium", False),
    (
        "limit_load_factor",
        "",
        "the load factor of the static path's first limit point (fold)",
        False,
    ),
    ("limit_tip_deflection", "m", "the mean tip displacement at that limit point", False),
    ("limit_inverted_elements", "count", "elements inverted at that limit point", False),
    (
        "f1_hz",
        "Hz",
        "the FEM reference's first natural frequency under the load case's constraints (the "
        "verification stage)",
        False,
    ),
    ("f1_ratio", "", "the model's first natural frequency / the FEM's", False),
    (
        "modes_unstable",
        "count",
        "modes of the linearised model with a negative or complex eigenvalue",
        False,
    ),
    (
        "freq_error_heldout",
        "",
        "RMS relative frequency error of the modes under the held-out load's constraints",
        False,
    ),
    (
        "freq_error_heldout_initial",
        "",
        "freq_error_heldout with the scaled (unfitted) constants",
        False,
    ),
    (
        "fit_ks",
        "N/m",
        "MS's spring stiffness after the least-squares fit to the FEM on the fitted loads",
        False,
    ),
    *[
        (
            f"fit_ks{i}",
            "N/m",
            f"MT0 / MT: the axial spring stiffness of axis {i} after the least-squares fit",
            False,
        )
        for i in (1, 2, 3)
    ],
    *[
        (
            f"fit_ks{i}",
            "N",
            f"MT0 / MT: the angular spring constant of axis pair {pair} (force per unit cosine "
            "change) after the least-squares fit",
            False,
        )
        for i, pair in ((4, "1-2"), (5, "1-3"), (6, "2-3"))
    ],
    ("fit_kvs", "N/m", "MT's volume stiffness after the least-squares fit", False),
    (
        "scaled_ks",
        "N/m",
        "MS's spring stiffness times the single factor that best matches the FEM",
        False,
    ),
    *[
        (
            f"scaled_ks{i}",
            "N/m" if i <= 3 else "N",
            f"MT0 / MT: ks{i} times the single common factor that best matches the FEM",
            False,
        )
        for i in range(1, 7)
    ],
    (
        "scaled_kvs",
        "N/m",
        "MT's volume stiffness times the single common factor that best matches the FEM",
        False,
    ),
    (
        "mt_axial",
        "Pa",
        "the element model on a spring model's cells: its fitted axial modulus",
        False,
    ),
    ("mt_angular", "Pa", "its fitted angular modulus", False),
    ("mt_volume", "Pa", "its fitted volume modulus", False),
    (
        "pull_stiffness_spread",
        "",
        "max / min of the effective Young's modulus over 12 pull directions (1 = isotropic)",
        True,
    ),
    (
        "pull_stiffness_spread_<col>",
        "",
        "pull_stiffness_spread of the FEM (fem) or with the fibre turned with the "
        "pull, the mesh's share (mesh)",
        False,
    ),
    (
        "pull_stiffness_cv",
        "",
        "coefficient of variation of the effective Young's modulus over the pull directions",
        False,
    ),
    (
        "pull_stiffness_cv_mesh",
        "",
        "pull_stiffness_cv with the fibre turned with the pull (the mesh's share)",
        False,
    ),
    ("pull_stiffness_err_max", "", "largest |E_model / E_FEM - 1| over the pull directions", False),
    (
        "pull_stiffness_err_max_mesh",
        "",
        "pull_stiffness_err_max with the fibre turned with the pull",
        False,
    ),
    (
        "pull_drift_max",
        "",
        "largest transverse / along-pull displacement over the pull directions",
        False,
    ),
    (
        "pull_drift_max_<col>",
        "",
        "pull_drift_max of the FEM (fem) or with the fibre turned with the pull (mesh)",
        False,
    ),
    ("pull_ref_error_estimate", "", "the FEM's estimated error in the pulls, relative", False),
    ("u_max", "m", "the reference's largest displacement of the load", False),
]
