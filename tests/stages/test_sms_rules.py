"""The stiffness rules of a large mesh (harness/stages/sms_rules.py): only the rules
that can rank first are solved under the clamps. On a small cylinder with the threshold
lowered, against the same calibration with every rule solved: the solved rules' rows are
the same, every skipped rule's bound is below its true G_fit_score and above the best, so
the rule 'best' picks and exports is the same."""

import pandas as pd
import pytest

from harness import cli
from harness.stages import sms_rules
from tests import meshes

pytest.importorskip("gmsh")


def rows(mesh, out, *argv):
    args = ["calibrate", str(mesh), "--E", "1e5", "--nu", "0.45", "--method", "rule"]
    assert cli.main([*args, "--max-refine", "0", "--out", str(out), *argv]) == 0
    table = pd.read_csv(out.with_suffix(".csv")).set_index("stiffness")
    rules = table[table.optimizer == "none"]  # not the plain tets row calibrate adds
    return rules, out.with_suffix(".json").read_text()


def full_and_part(tmp_path, monkeypatch):
    """(every rule solved: rows, JSON; the same with the large-mesh path forced: rows, JSON;
    the (networks, loads) of every rule solve the latter made)."""
    from harness.commands import calibrate_write
    from harness.mechanics import statics

    mesh = meshes.cylinder(tmp_path)
    full, full_json = rows(mesh, tmp_path / "full.vtu")
    solved = []
    solve_all = statics.solve_all

    def counting(nets, case, loads=None):
        solved.append((len(list(nets)), None if loads is None else len(loads)))
        return solve_all(nets, case, loads)

    monkeypatch.setattr(statics, "solve_all", counting)
    # the export's solve, not a rule's
    monkeypatch.setattr(calibrate_write, "settle_recipe", lambda net, case: None)
    monkeypatch.setattr(sms_rules, "ALL_RULES_DOFS", 0)
    part, part_json = rows(mesh, tmp_path / "part.vtu")
    # each rule's solves (the plain tets row's solve of every load is not a rule's)
    return full, full_json, part, part_json, [x for x in solved if x[1] is not None]


@pytest.mark.slow
def test_rules_that_cannot_rank_first_are_not_solved_under_the_clamps(tmp_path, monkeypatch):
    """Without [loads] rank_by (calibrate's taken away): the free-traction bound."""
    import json

    from harness.case import reader

    monkeypatch.setattr(reader, "parse_rank_by", lambda *args: ())
    full, full_json, part, part_json, solved = full_and_part(tmp_path, monkeypatch)
    skipped = part.index[part.G_fit_score.isna()]
    assert len(skipped) >= 1
    # free states, then each rule
    assert solved[0] == (len(part), 24) and len(solved) - 1 == len(part) - len(skipped)
    best = full.G_fit_score.min()
    for r in skipped:
        assert best < part.loc[r, "G_fit_score_bound"] <= full.loc[r, "G_fit_score"] + 1e-12, r
    for r in part.index.difference(skipped):
        for col in ("G_fit_score", "G_norm_final", "G_heldout_mean"):
            assert part.loc[r, col] == pytest.approx(full.loc[r, col], rel=1e-9), (r, col)
    assert json.loads(part_json)["spring_stiffness"] == pytest.approx(
        json.loads(full_json)["spring_stiffness"]
    )
    assert part.index[part.exported][0] == full.index[full.exported][0]


@pytest.mark.slow
def test_ranked_rules_a_large_mesh_solves_the_best_ranked_one_under_the_clamps(
    tmp_path, monkeypatch
):
    """calibrate's case ranks by [loads] rank_by (the end-swapped states): a large mesh
    solves every rule on the free and those states (24 + 3 loads), then only the rule of
    the lowest G_rank_score under the other clamps; it is the one the full solve ranks
    first, its row and the export are the same, every other rule's bound is below its
    true G_fit_score."""
    import json

    full, full_json, part, part_json, solved = full_and_part(tmp_path, monkeypatch)
    data = json.loads(full_json)
    n_loads = len(data["loads_fitted"]) + len(data["loads_heldout"])
    assert solved == [(len(part), 27), (1, n_loads - 27)]
    best = full.G_rank_score.idxmin()
    assert part.G_fit_score.notna().sum() == 1 and part.G_fit_score.notna()[best]
    for col in ("G_rank_score", "G_fit_score", "G_norm_final", "G_heldout_mean"):
        assert part.loc[best, col] == pytest.approx(full.loc[best, col], rel=1e-9), col
    for r in part.index.difference([best]):
        assert part.loc[r, "G_fit_score_bound"] <= full.loc[r, "G_fit_score"] + 1e-12, r
    assert part.index[part.exported][0] == best == full.index[full.exported][0]
    assert json.loads(part_json)["spring_stiffness"] == pytest.approx(
        json.loads(full_json)["spring_stiffness"]
    )
