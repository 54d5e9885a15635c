"""One vocabulary of model classes, harness/registry.py MODEL_CLASSES: ``calibrate --model``
offers its springs classes, the case schema's ``[model] classes`` takes its names, a case's
own volume and kn keys and calibrate's case table name the same class objects, and the
model lists of the docs name only registry names; the two ambiguous spellings are one-line
errors naming both classes they could mean, in a case file and on the command line."""

from __future__ import annotations

import argparse
import re

import pytest

from harness import cli, registry
from harness.case import sections
from harness.case.reader import load_case
from harness.commands import calibrate
from harness.commands.calibrate_case import case_table
from harness.errors import CaseError
from harness.paths import ROOT
from harness.stages.classes.springs import Springs, of_spec

AMBIGUOUS = tuple(registry.AMBIGUOUS_CLASSES)
CASE = """name = "v"
dim = 2
[body]
shape = "rectangle"
size = [2.0, 1.0]
[material]
E = 1000.0
nu = 0.3
[loads]
set = "basic2d"
[reference]
cell = "tri"
divisions = 2
[model]
kind = "sms"
placement = "grid"
grid = [3, 3]
classes = {classes}
[optimizer]
method = "none"
"""


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser()
    calibrate.add_arguments(p)
    return p


def _model_option():
    return next(a for a in _parser()._actions if "--model" in a.option_strings)


def test_calibrate_offers_the_registrys_springs_classes_and_p1_global():
    springs = tuple(n for n, c in registry.MODEL_CLASSES.items() if isinstance(c, Springs))
    option = _model_option()
    assert springs == registry.SPRINGS_CLASSES
    assert tuple(option.choices) == registry.CALIBRATE_CLASSES == springs + ("p1-global", "p1")
    assert all(f"{n}: {registry.class_doc(n)}" in option.help for n in option.choices)


def test_the_case_schema_takes_the_registrys_names():
    assert sections.SMS["classes"].choices == registry.MODEL_CLASSES.names()


def test_each_class_says_what_it_is_and_each_springs_class_knows_its_keys(tmp_path):
    keys = set()
    for name, cls in registry.MODEL_CLASSES.items():
        model, constants = registry.MODEL_CLASSES.about[name]
        assert model and constants and cls.name == name
        if isinstance(cls, Springs):
            keys.add((cls.volume, cls.kn))
            # a case without classes, with the class's own keys, is that class
            assert of_spec({"volume": cls.volume, "kn": cls.kn}) is cls
            s = _parser().parse_args(
                ["m.vtu", "--E", "1e5", "--nu", "0.3", "--out", "o.vtu", "--model", name]
            )
            model_table = case_table(s, 3)["model"]
            assert (model_table["volume"], model_table["kn"]) == (cls.volume, cls.kn), name
    assert len(keys) == len(registry.SPRINGS_CLASSES)  # one class per pair of keys
    # every value of [model] volume, and of kn, alone names a registered class
    volumes, kns = sections.SMS["volume"].choices, sections.SMS["kn"].choices
    assert {(v, "none") for v in volumes} | {("none", k) for k in kns} == keys


def test_every_name_loads_in_a_case(tmp_path):
    p = tmp_path / "all.toml"
    p.write_text(CASE.format(classes=str(list(registry.MODEL_CLASSES.names())).replace("'", '"')))
    assert load_case(p).section("model")["classes"] == list(registry.MODEL_CLASSES.names())


@pytest.mark.parametrize("name", AMBIGUOUS)
def test_an_ambiguous_class_in_a_case_is_one_line_naming_both(name, tmp_path, capsys):
    p = tmp_path / "c.toml"
    p.write_text(CASE.format(classes=f'["springs", "{name}"]'))
    with pytest.raises(CaseError) as exc:
        load_case(p)
    why = registry.ambiguous_class(name)
    assert exc.value.message == why and exc.value.field == "model.classes"
    assert all(n in why for n in registry.AMBIGUOUS_CLASSES[name])
    assert cli.main(["validate", str(p)]) == 2
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(lines) == 1 and why in lines[0], lines


@pytest.mark.parametrize("name", AMBIGUOUS)
def test_an_ambiguous_model_on_the_command_line_is_one_line_naming_both(name, tmp_path, capsys):
    argv = ["calibrate", str(tmp_path / "m.vtu"), "--E", "1e5", "--nu", "0.3"]
    with pytest.raises(SystemExit) as exc:
        cli.main(argv + ["--out", str(tmp_path / "o.vtu"), "--model", name])
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert exc.value.code == 2 and len(lines) == 1, lines
    assert f"--model: {registry.ambiguous_class(name)}" in lines[0]


def test_the_refusal_names_both_meanings():
    assert registry.ambiguous_class("springs+volume") == (
        "'springs+volume' is ambiguous: springs+volume-shared (one kv for the body) or "
        "springs+volume-element (one kv per element)"
    )
    assert registry.ambiguous_class("springs+node-volume") == (
        "'springs+node-volume' is ambiguous: springs+node-volume-shared (one kv for the body) "
        "or springs+node-volume-node (one kv per node)"
    )
    assert registry.ambiguous_class("springs") is None


def _named(text: str):
    """(name, its sentence) of every backticked springs+... name and --model value."""
    for sentence in re.split(r"(?<=[.;])\s", text):
        for name in re.findall(r"`(springs\+[a-z-]+)`", sentence) + re.findall(
            r"--model `?(springs[a-z+-]*)", sentence
        ):
            yield name, sentence


@pytest.mark.parametrize("page", ["case-files.md", "calibrate.md", "models.md"])
def test_the_docs_model_lists_name_registry_classes(page):
    text = (ROOT / "docs" / page).read_text(encoding="utf-8")
    named = list(_named(text))
    assert named
    for name, sentence in named:
        assert name in registry.MODEL_CLASSES or (name in AMBIGUOUS and "ambiguous" in sentence), (
            f"{page}: {name} in {sentence!r}"
        )
    listed = set(re.findall(r"`(springs(?:\+[a-z-]+)?|p1(?:-global)?|mt)`", text))
    want = registry.CALIBRATE_CLASSES if page == "calibrate.md" else registry.MODEL_CLASSES
    assert set(want) <= listed, f"{page}: {set(want) - listed} not named"
