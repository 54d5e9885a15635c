"""[loads] rank_by: the fitted loads the rules are ranked by first (harness/stages/
sms_measures.py ``rank``). It names fitted loads only (a held-out load never chooses),
a name listed n times counts n times, calibrate's case ranks by each held-out load's
end-swapped twin, and rank() orders rows by G_rank_score, then G_fit_score, then the
pooled G."""

import math
import textwrap

import pytest

from harness.case.reader import load_case
from harness.errors import CaseError
from harness.stages.sms_measures import rank


def box_case(tmp_path, rank_by: str):
    p = tmp_path / "c.toml"
    p.write_text(
        textwrap.dedent(f"""
        name = "c"
        dim = 3
        [body]
        shape = "box"
        size = [1.0, 0.5, 0.5]
        [material]
        E = 1.0
        nu = 0.3
        [loads]
        set = "basic3d"
        heldout = ["stretch-x"]
        rank_by = {rank_by}
        [model]
        kind = "sms"
        placement = "grid"
        grid = [3, 2, 2]
        """)
    )
    return p


def test_rank_by_names_fitted_loads_as_listed(tmp_path):
    case = load_case(box_case(tmp_path, '["shear-xz", "stretch-y", "shear-xz"]'))
    assert case.rank_by == ("shear-xz", "stretch-y", "shear-xz")  # repeats kept: weights
    assert set(case.rank_by) <= set(case.fit_loads)


def test_the_rank_score_counts_a_name_as_often_as_it_is_listed(tmp_path):
    """G_rank_score is the mean over the list: shear-xz listed twice weighs 2/3."""
    from types import SimpleNamespace

    from harness.stages.sms_measures import fit_score

    case = load_case(box_case(tmp_path, '["shear-xz", "stretch-y", "shear-xz"]'))
    per = {n: 0.0 for n in case.fit_loads}
    per.update({"shear-xz": 0.3, "stretch-y": 0.6})
    score = fit_score(case, SimpleNamespace(per_load_norm=per))["G_rank_score"]
    assert score == pytest.approx((0.3 + 0.6 + 0.3) / 3)  # 0.4, not (0.3 + 0.6) / 2


def test_a_held_out_load_cannot_rank(tmp_path):
    with pytest.raises(CaseError) as err:
        load_case(box_case(tmp_path, '["stretch-x"]'))
    assert err.value.field == "loads.rank_by" and "held-out ones never choose" in err.value.fix


def test_rank_orders_by_the_rank_score_first():
    rows = [
        dict(G_rank_score=0.20, G_fit_score=0.10, G_norm_final=0.1),
        dict(G_rank_score=0.15, G_fit_score=0.30, G_norm_final=0.3),
        dict(G_rank_score=math.nan, G_fit_score=0.05, G_norm_final=0.0),
    ]
    assert min(rows, key=rank) is rows[1]
    plain = [dict(r, G_rank_score=math.nan) for r in rows]  # no rank_by: G_fit_score
    assert min(plain, key=rank) is plain[2]


def test_calibrate_ranks_by_the_end_swapped_twins():
    """calibrate's case table on a box of tets: rank_by is each held-out load's end-swapped
    twin (sag, tip, bridge: train-tip; tip2: train-tip2; torsion: train-torsion)."""
    import numpy as np
    import skfem

    from harness.case.default_loads import end_loads
    from harness.cli import build_parser
    from harness.commands.calibrate_case import case_table
    from harness.commands.calibrate_settings import Settings

    box = skfem.MeshTet.init_tensor(
        *(np.linspace(0, s, n) for s, n in ((1, 6), (0.3, 3), (0.2, 3)))
    )
    ends = end_loads(box.p.T, {"tetra": box.t.T})
    args = ["calibrate", "box.vtu", "--E", "1e5", "--nu", "0.3", "--out", "m.vtu"]
    s = Settings.of(build_parser().parse_args(args))
    table = case_table(s, 3, ("tetra",), ends=ends)
    assert table["loads"]["heldout"] == ["sag", "tip", "tip2", "torsion", "bridge"]
    twins = ["train-tip", "train-tip", "train-tip2", "train-torsion", "train-tip"]
    assert table["loads"]["rank_by"] == twins
    assert set(table["loads"]["rank_by"]) <= {c["name"] for c in table["loads"]["case"]}
