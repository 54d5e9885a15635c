"""The model-class protocol stays small and in one place: docs/design.md states it in at
most ten lines and names every method of ``ModelClass``, and every registered class is an
object of one module of harness/stages/classes/ derived from it."""

import re

from harness import registry
from harness.paths import ROOT
from harness.stages.classes.base import ModelClass


def _protocol_lines() -> list[str]:
    text = (ROOT / "docs" / "design.md").read_text()
    start = text.index("A model class of the sms stage is one module")
    return text[start:].split("\n\n", 2)[:2]


def test_the_protocol_is_stated_in_ten_lines_and_names_every_method():
    intro, items = _protocol_lines()
    assert len((intro + "\n" + items).splitlines()) <= 10
    named = set(re.findall(r"`(\w+)\(", items))
    methods = {n for n, v in vars(ModelClass).items() if callable(v) and not n.startswith("_")}
    assert named == methods, named ^ methods


def test_every_class_is_one_module_of_the_classes_package():
    for name in registry.MODEL_CLASSES:
        module = registry.MODEL_CLASSES.module(name)
        assert re.fullmatch(r"harness\.stages\.classes\.\w+", module), (name, module)
        assert isinstance(registry.MODEL_CLASSES.load(name), ModelClass), name
