"""Case files with one mistake in each section and kind of value: wrong types,
nan/inf, out of range, numbers too large or small to compute with (1e200, E = 1e308, size =
[1e-300, 1e-300]), a zero load, unknown keys ("did you mean"), and mistakes only a stage's
check sees. Each is a small edit of a valid case; ``springbench validate`` gives exit 2 and
one line naming the file, the field and the fix; ``springbench run`` gives the same line
for those the loader sees (the stage-only ones fail when their stage runs), and three
mistakes give three lines."""

from __future__ import annotations

import copy
import re

import pytest

from harness import cli
from tests.run.test_robustness import names_a_fix

BASE = {
    "": {"name": '"s"', "dim": "2"},
    "body": {"shape": '"rectangle"', "size": "[2.0, 1.0]"},
    "material": {"E": "1000.0", "nu": "0.3"},
    "loads": {"set": '"basic2d"'},
    "reference": {"cell": '"tri"', "divisions": "2"},
    "model": {
        "kind": '"sms"',
        "placement": '"grid"',
        "grid": "[3, 3]",
        "structure": '"edges+diagonal"',
    },
    "optimizer": {"method": '"none"'},
}
STAGE = "stage"  # only the stage's check (validate) or its run sees it
# (id, edits "section.key=TOML value; ..." (DEL removes the key), the field the line names[, STAGE])
CASES = [
    ("size_tiny", "body.size=[1e-300, 1e-300]", "body.size"),
    ("size_huge", "body.size=[1e200, 1.0]", "body.size"),
    ("origin_huge", "body.origin=[1e200, 0.0]", "body.origin"),
    ("origin_far", "body.origin=[1e9, 0.0]", "body.origin"),
    ("size_key_typo", "body.sise=[2.0, 1.0]", "body.sise"),
    ("origin_nan", "body.origin=[nan, 0.0]", "body.origin"),
    (
        "polygon_vertex_nan",
        'body.shape="polygon";body.size=DEL;body.vertices=[[0.0,0.0],[1.0,0.0],[1.0,1.0],[nan,1.0]];reference.divisions=DEL',
        "body.vertices",
    ),
    (
        "polygon_vertex_inf",
        'body.shape="polygon";body.size=DEL;body.vertices=[[0.0,0.0],[1.0,0.0],[1.0,inf],[0.0,1.0]];reference.divisions=DEL',
        "body.vertices",
    ),
    (
        "polygon_huge",
        'body.shape="polygon";body.size=DEL;body.vertices=[[0.0,0.0],[1e200,0.0],[1.0,1.0]];reference.divisions=DEL',
        "body.vertices",
    ),
    (
        "polygon_far",
        'body.shape="polygon";body.size=DEL;body.vertices=[[1e8,0.0],[1.00000000001e8,0.0],[1e8,1e-4]];reference.divisions=DEL',
        "body.vertices",
    ),
    ("part_box_nan", "body.parts={a = {box = [[nan, 0.0], [1.0, 1.0]]}}", "body.parts.a.box"),
    ("E_huge", "material.E=1e308", "material.E"),
    ("E_tiny", "material.E=1e-40", "material.E"),
    ("E_inf", "material.E=inf", "material.E"),
    ("nu_nan", "material.nu=nan", "material.nu"),
    ("density_huge", "material.density=1e40", "material.density"),
    ("density_typo", "material.densty=1000.0", "material.densty"),
    ("plane_not_a_choice", 'material.plane="strain2"', "material.plane"),
    (
        "region_box_huge",
        "material.regions=[{box = [[0.0, 0.0], [1e200, 1.0]], E = 5.0}]",
        "material.regions",
    ),
    (
        "region_nu_half",
        "material.regions=[{box = [[0.0, 0.0], [1.0, 1.0]], E = 5.0, nu = 0.5}]",
        "material.regions[0].nu",
    ),
    (
        "fibre_E_zero",
        "material.fibre={E_fibre = 0.0, E_cross = 1.0, direction = [1.0, 0.0]}",
        "material.fibre.E_fibre",
    ),
    ("magnitude_zero", "loads.magnitude=0.0", "loads.magnitude"),
    ("magnitude_huge", "loads.magnitude=1e308", "loads.magnitude"),
    ("magnitude_nan", "loads.magnitude=nan", "loads.magnitude"),
    ("heldout_unknown", 'loads.heldout=["sag"]', "loads.heldout"),
    ("fit_unknown", 'loads.fit=["stretch-q"]', "loads.fit"),
    ("fit_and_heldout_overlap", 'loads.fit=["stretch-x"];loads.heldout=["stretch-x"]', "loads"),
    (
        "load_gravity_nan",
        'loads.case=[{name = "g", constraint = [{part = "x0"}], gravity = [0.0, nan]}]',
        "loads.case[0].gravity",
    ),
    (
        "load_traction_huge",
        'loads.case=[{name = "t", constraint = [{part = "x0"}], '
        'traction = [{part = "x1", vector = [1e200, 0.0]}]}]',
        "vector",
    ),
    (
        "load_component_w",
        'loads.case=[{name = "t", constraint = [{part = "x0", components = ["w"]}], '
        'traction = [{part = "x1", vector = [1.0, 0.0]}]}]',
        "components",
    ),
    (
        "load_no_name",
        'loads.case=[{constraint = [{part = "x0"}], '
        'traction = [{part = "x1", vector = [1.0, 0.0]}]}]',
        "name",
    ),
    (
        "load_zero_traction",
        'loads.set=DEL;loads.case=[{name = "t", constraint = [{part = "x0"}], '
        'traction = [{part = "x1", vector = [0.0, 0.0]}]}]',
        "loads",
    ),
    ("divisions_zero", "reference.divisions=0", "reference.divisions"),
    ("tol_nan", "reference.tol=nan", "reference.tol"),
    ("tol_zero", "reference.tol=0.0", "reference.tol"),
    ("max_refine_negative", "reference.max_refine=-1", "reference.max_refine"),
    ("solver_lu", 'reference.solver="lu"', "reference.solver"),
    ("modes_negative", "reference.modes=-1", "reference.modes"),
    (
        "graded_polygon",
        'body.shape="polygon";body.size=DEL;body.vertices=[[0.0,0.0],[1.0,0.0],[1.0,1.0]];reference.method="graded";reference.cell=DEL;reference.divisions=DEL',
        "reference.method",
    ),
    ("reference_key_typo", "reference.tolerance=1e-3", "reference.tolerance"),
    ("model_kind_missing", "model.kind=DEL", "model.kind"),
    ("placement_unknown", 'model.placement="hexgrid"', "model.placement"),
    ("grid_ones", "model.grid=[1, 1]", "model.grid"),
    ("grid_string", 'model.grid="5x5"', "model.grid"),
    ("n_points_two", 'model.placement="random";model.grid=DEL;model.n_points=2', "model.n_points"),
    ("lloyd_negative", "model.lloyd_iterations=-1", "model.lloyd_iterations"),
    ("masses_unknown", 'model.masses="heavy"', "model.masses"),
    ("stiffness_unknown", 'model.stiffness=["springy"]', "model.stiffness"),
    ("model_seed_float", "model.seed=1.5", "model.seed"),
    ("model_key_typo", "model.grdi=[3, 3]", "model.grdi"),
    ("structure_unknown", 'model.structure="hexagons"', "model.structure", STAGE),
    ("optimizer_unknown", 'optimizer.method="annealing"', "optimizer.method"),
    (
        "optimizer_options_not_table",
        'optimizer.method="sa";optimizer.options=5',
        "optimizer.options",
        STAGE,
    ),
    (
        "optimizer_options_unknown",
        'optimizer.method="sa";optimizer.options={temprature = 1.0}',
        "optimizer.options",
        STAGE,
    ),
    (
        "optimizer_compare_repeat",
        'optimizer.method="sa";optimizer.compare=["sa"]',
        "optimizer.compare",
        STAGE,
    ),
    (
        "optimizer_compare_options_stray",
        'optimizer.method="sa";optimizer.compare_options={lbfgs = {maxiter = 5}}',
        "optimizer.compare_options",
        STAGE,
    ),
    ("optimizer_start_middle", 'optimizer.start="middle"', "optimizer.start"),
    (
        "optimizer_frequency_modes_zero",
        "optimizer.frequency={modes = 0}",
        "optimizer.frequency.modes",
    ),
    ("optimizer_options_with_none", "optimizer.options={maxiter = 5}", "optimizer.options", STAGE),
    (
        "optimizer_budget_nan",
        'optimizer.method="lbfgs";optimizer.options={max_seconds = nan}',
        "optimizer.options",
        STAGE,
    ),
    ("score_weights_nan", "score.weights=[nan, 1.0, 1.0]", "score.weights"),
    ("score_weights_zero", "score.weights=[0.0, 0.0, 0.0]", "score.weights"),
    ("dynamics_dt_zero", "dynamics.dt=0.0", "dynamics.dt"),
    ("dynamics_dt_nan", "dynamics.dt=nan", "dynamics.dt"),
    ("dynamics_steps_negative", "dynamics.steps=-1", "dynamics.steps"),
    ("dynamics_experiment_unknown", 'dynamics.experiment="fly"', "dynamics.experiment"),
    ("dynamics_integrator_rk4", 'dynamics.integrator="rk4"', "dynamics.integrator"),
    ("dynamics_gravity_two", "dynamics.gravity=[0.0, -9.8]", "dynamics.gravity"),
    ("dynamics_duration_negative", "dynamics.duration=-1.0", "dynamics.duration"),
    ("dynamics_repeats_zero", "dynamics.repeats=0", "dynamics.repeats"),
    ("dynamics_key_typo", "dynamics.tdt=0.01", "dynamics.tdt"),
    ("run_seeds_empty", "run.seeds=[]", "run.seeds"),
    ("run_seeds_string", 'run.seeds="a"', "run.seeds"),
    ("run_seeds_bool", "run.seeds=true", "run.seeds"),
    ("section_typo", "materail.E=1.0", "materail"),
    ("model_seed_negative", "model.seed=-1", "model.seed"),
    (
        "fibre_seed_negative",
        "material.fibre={E_fibre = 2.0, E_cross = 1.0, direction = [1.0, 0.0], seed = -3}",
        "material.fibre.seed",
    ),
    ("dim_float", "dim=2.5", "dim"),
    ("name_number", "name=42", "name"),
    ("description_number", "description=5", "description"),
]


def render(edits: str) -> str:
    """BASE with the edits applied, as TOML."""
    d = copy.deepcopy(BASE)
    for edit in edits.split(";"):
        path, value = (s.strip() for s in edit.split("=", 1))
        sec, key = path.rsplit(".", 1) if "." in path else ("", path)
        if value == "DEL":
            d.setdefault(sec, {}).pop(key, None)
        else:
            d.setdefault(sec, {})[key] = value
    lines = [f"{k} = {v}" for k, v in d.pop("").items()]
    for sec, kv in d.items():
        lines += [f"[{sec}]"] + [f"{k} = {v}" for k, v in kv.items()]
    return "\n".join(lines) + "\n"


def cli_lines(argv, capsys):
    code = cli.main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    return code, [ln for ln in err.splitlines() if ln.startswith("springbench")]


def test_the_base_case_is_valid(tmp_path, capsys):
    """The control: every failure below is its edit's."""
    (tmp_path / "base.toml").write_text(render('name = "base"'))
    assert cli_lines(["validate", tmp_path / "base.toml"], capsys) == (0, [])


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_validate_names_file_field_and_fix(case, tmp_path, capsys):
    name, edits, field = case[:3]
    f = tmp_path / f"{name}.toml"
    f.write_text(render(edits))
    code, lines = cli_lines(["validate", f], capsys)
    assert code == 2 and len(lines) == 1, lines
    line = lines[0]
    assert (
        line.startswith(f"springbench: error: {f}: ") and f"{field}" in line and names_a_fix(line)
    ), line
    if name.endswith("typo"):
        assert "did you mean" in line, line


@pytest.fixture(scope="module")
def run_lines(tmp_path_factory):
    """Every case the loader sees, through one `springbench run` with the fake stage."""
    import contextlib
    import io

    from harness import registry

    d = tmp_path_factory.mktemp("cases") / "bad"
    d.mkdir()
    for name, edits, *_ in CASES:
        (d / f"{name}.toml").write_text(render(f'name = "{name}"; {edits}'))
    err = io.StringIO()
    with (
        pytest.MonkeyPatch.context() as mp,
        contextlib.redirect_stderr(err),
        contextlib.redirect_stdout(io.StringIO()),
    ):
        mp.setattr(registry, "STAGES", registry.STAGES.with_entries({"fake": "tests.fakestage"}))
        code = cli.main(
            ["run", str(d), "--results", str(d.parent / "results"), "--jobs", "1", "--no-figures"]
        )
    return code, err.getvalue().splitlines()


@pytest.mark.parametrize(
    "case", [c for c in CASES if STAGE not in c], ids=[c[0] for c in CASES if STAGE not in c]
)
def test_run_gives_the_same_line(case, run_lines):
    code, lines = run_lines
    mine = [ln for ln in lines if re.search(rf"[/ ]{re.escape(case[0])}\.toml:", ln)]
    assert code == 2 and len(mine) == 1 and case[2] in mine[0], (case, mine)


def test_every_mistake_is_a_line(tmp_path, capsys):
    """Three mistakes in three sections: validate prints three lines; run one, saying so."""
    f = tmp_path / "three.toml"
    f.write_text(
        render("material.E=-1.0; material.densty=1.0; reference.tol=nan; model.grdi=[3, 3]")
    )
    code, lines = cli_lines(["validate", f], capsys)
    assert code == 2 and len(lines) == 4, lines
    for field, line in zip(["material.densty", "material.E", "reference.tol", "model.grdi"], lines):
        assert line.startswith(f"springbench: error: {f}: {field}: "), (field, line)
    from harness.case.reader import load_case
    from harness.errors import CaseError

    with pytest.raises(CaseError, match=r"and 3 more mistakes"):
        load_case(f)


BAD_CASES = [f"case {c[0]}" for c in CASES]
