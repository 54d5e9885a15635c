"""Fitted rows and stiffness rules' rows are built by typed helpers (harness/stages/rows.py
FitColumns, RuleColumns) whose fields are columns documented in harness/report/columns.py,
and no fit or rule row writes one of those columns itself."""

import ast
import dataclasses
import inspect
import math
from types import SimpleNamespace

from harness.report.columns import COLUMNS
from harness.stages import sms_fit, sms_rows, sms_select
from harness.stages.classes import base, mt, p1_element, p1_global
from harness.stages.rows import FIT_COLUMNS, RULE_COLUMNS, FitColumns, RuleColumns

FITS = (sms_fit, sms_select, p1_global, p1_element, mt)
# every row carries these, rule and skip rows too: only a skip row may write them itself
LABELS = {"model", "stiffness", "optimizer"}


def undocumented(cls) -> list[str]:
    """The fields of dataclass ``cls`` that are no documented column (exact name, not a
    family such as G_<load>)."""
    names = {c.name for c in COLUMNS}
    return [f.name for f in dataclasses.fields(cls) if f.name not in names]


def literal_columns(source: str, columns) -> list[str]:
    """The shared columns ``source`` writes itself: dict literal keys, ``update``
    keywords and ``row[...] =`` targets (outside a ``skip_row``, which may name LABELS;
    a trace frame's ``df["model"]`` and a run's ``dict(objective=...)`` are no rows)."""
    found = []

    def visit(node, in_skip):
        if isinstance(node, ast.FunctionDef) and node.name == "skip_row":
            in_skip = True
        names = []
        if isinstance(node, ast.Dict):
            names = [k.value for k in node.keys if isinstance(k, ast.Constant)]
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", None) == "update":
            names = [k.arg for k in node.keywords]
        elif (
            isinstance(node, ast.Subscript)
            and isinstance(node.ctx, ast.Store)
            and getattr(node.value, "id", None) == "row"
        ):
            names = [node.slice.value] if isinstance(node.slice, ast.Constant) else []
        found.extend(n for n in names if n in columns and not (in_skip and n in LABELS))
        for child in ast.iter_child_nodes(node):
            visit(child, in_skip)

    visit(ast.parse(source), False)
    return found


def test_every_field_of_the_helper_is_a_documented_column():
    assert undocumented(FitColumns) == []
    assert FIT_COLUMNS == tuple(f.name for f in dataclasses.fields(FitColumns))
    broken = dataclasses.make_dataclass(
        "Broken", [("G_norm_finale", float)], bases=(FitColumns,), frozen=True
    )
    assert undocumented(broken) == ["G_norm_finale"]


def test_every_fit_builds_its_row_through_the_helper():
    for module in FITS:
        source = inspect.getsource(module)
        assert ".fit_columns(" in source and ".row(" in source, module.__name__
        assert literal_columns(source, FIT_COLUMNS) == [], module.__name__
    # the scan sees each way a module could write a shared column itself
    snippet = (
        "def optimise():\n"
        "    row = {'G_norm_final': 1.0, 'model': 'm'}\n"
        "    row.update(objective='G')\n"
        "    row['n_params'] = 2\n"
        "    row.update({'budget': 'x'})\n"
        "def skip_row():\n"
        "    return {'model': 'm', 'G_final': 0.0}\n"
    )
    assert literal_columns(snippet, FIT_COLUMNS) == [
        "G_norm_final",
        "model",
        "objective",
        "n_params",
        "budget",
        "G_final",
    ]


def _columns(**kw) -> FitColumns:
    first = {"G_initial": 2.0, "G_norm_initial": 0.2}  # a rule row without G_s_initial
    sc = SimpleNamespace(G=1.0, G_norm=0.1, G_s=1.5)
    return FitColumns.of("sms-mesh", "lloyd", "lbfgs", first, sc, **kw)


def test_the_row_holds_the_columns_in_order_and_leaves_out_the_unset():
    c = _columns(seconds=3.0, objective="G", n_params=7, budget="maxiter=4")
    row = c.row({"case": "c", "seconds": -1.0}, scored={"G_heldout": 0.3}, chosen={"choice": "x"})
    assert list(row) == [
        "case",
        "seconds",
        "model",
        "stiffness",
        "optimizer",
        "G_initial",
        "G_norm_initial",
        "G_s_initial",
        "G_final",
        "G_norm_final",
        "G_s_final",
        "G_heldout",
        "objective",
        "choice",
        "budget",
        "n_params",
    ]
    assert row["model"] == "sms-mesh[lloyd]" and row["seconds"] == 3.0
    assert (row["G_initial"], row["G_final"], row["G_norm_final"]) == (2.0, 1.0, 0.1)
    assert math.isnan(row["G_s_initial"]) and row["G_s_final"] == 1.5
    # a score column after a field overrides its value in place, as a dict merge does
    assert c.row({}, scored={"G_final": 9.0})["G_final"] == 9.0
    assert list(c.row({}, scored={"G_final": 9.0})).index("G_final") == 7


def test_the_setting_labels_its_fits():
    s = base.Setting(*[None] * 3, "p1-sms-mesh", {}, *[None] * 8)
    first = {"G_initial": 2.0, "G_norm_initial": 0.2, "G_s_initial": 2.5}
    sc = SimpleNamespace(G=1.0, G_norm=0.1, G_s=1.5)
    c = s.fit_columns(first, "p1", "l-bfgs-b", sc, seconds=1.0, objective="G", n_params=2)
    assert c.model == "p1-sms-mesh[p1]" and c.G_s_initial == 2.5 and c.grouped is None


# the rule rows as the stage writes them: the names and order written out here, not read
# from the helper
SCORED = ["G_initial", "G_final", "G_norm_initial", "G_norm_final", "G_s_initial", "G_s_final"]
LABELS_SECONDS = ["model", "stiffness", "optimizer", "seconds"]


def _scorer(sc, monkeypatch):
    """A stand-in for the stage's Scorer: ``sc`` its score of every network (None: no
    reference), one constant column, one validation column; the score columns stubbed."""
    monkeypatch.setattr(
        sms_rows.measures,
        "scored_columns",
        lambda case, sc, sh: {"G_pull": 4.0, "G_fit_score": 5.0},
    )
    written = []
    return SimpleNamespace(
        evaluate=lambda net, res: (SimpleNamespace(seconds=0.5), sc, None),
        write=lambda net, res, rule: written.append((rule, res)),
        cls=SimpleNamespace(constants=lambda net: {"E_effective": 7.0}),
        validated=lambda net, res: {"G_val_mean": 6.0},
        case=None,
        written=written,
    )


def test_every_field_of_the_rule_helper_is_a_documented_column():
    assert undocumented(RuleColumns) == []
    assert RULE_COLUMNS == tuple(f.name for f in dataclasses.fields(RuleColumns))
    assert literal_columns(inspect.getsource(sms_rows), RULE_COLUMNS) == []


def test_a_scored_rule_row_holds_the_helpers_columns_in_order(monkeypatch):
    sc = SimpleNamespace(G=1.0, G_norm=0.1, G_s=1.5)
    scorer = _scorer(sc, monkeypatch)
    common = {"case": "c", "mode": "quick"}
    row = sms_rows.rule_row(scorer, common, "sms", "lloyd", None, None, 2.0, "")
    assert list(row) == [
        "case",
        "mode",
        *LABELS_SECONDS,
        "E_effective",
        *SCORED,
        "G_pull",
        "G_fit_score",
        "G_val_mean",
    ]
    assert [k for k in row if k in RULE_COLUMNS] == [c for c in RULE_COLUMNS if c in row]
    assert (row["model"], row["stiffness"], row["optimizer"]) == ("sms[lloyd]", "lloyd", "none")
    assert [row[k] for k in SCORED] == [1.0, 1.0, 0.1, 0.1, 1.5, 1.5]
    assert row["seconds"] >= 2.5 and row["E_effective"] == 7.0 and row["G_val_mean"] == 6.0
    assert common == {"case": "c", "mode": "quick"} and scorer.written[-1][0] == "lloyd"
    # a common column the helper also fills keeps its place and takes the helper's value
    row = sms_rows.rule_row(scorer, {"seconds": -1.0}, "sms", "lloyd", None, None, 2.0, "")
    assert list(row)[:2] == ["seconds", "model"] and row["seconds"] >= 2.5


def test_an_unscored_and_an_unsolved_rule_row_hold_the_helpers_columns(monkeypatch):
    scorer = _scorer(None, monkeypatch)
    row = sms_rows.rule_row(scorer, {"case": "c"}, "sms", "cauchy", None, None, 2.0, "no FEM")
    assert list(row) == ["case", *LABELS_SECONDS, "E_effective", *SCORED[:4], "note"]
    assert all(math.isnan(row[k]) for k in SCORED[:4])
    assert row["note"] == "no reference (no FEM)"
    row = sms_rows.unsolved_row(scorer, {"case": "c"}, "sms", "uniform", None, 0.25, 3.0)
    assert row == {
        "case": "c",
        "model": "sms[uniform]",
        "stiffness": "uniform",
        "optimizer": "none",
        "seconds": 3.0,
        "G_fit_score_bound": 0.25,
        "note": sms_rows.UNSOLVED,
    }
    assert list(row)[1:] == [c for c in RULE_COLUMNS if c in row]
    assert scorer.written[-1] == ("uniform", None)
