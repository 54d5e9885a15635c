"""The registries (harness/registry.py): every entry imports and is what its kind needs, the
case schema's vocabularies are the registries' names, an unknown name is an error naming
the known ones, and a module that fails to import raises instead of being skipped."""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import inspect
import itertools

import numpy as np
import pytest

from harness import registry
from harness.case import sections
from harness.registry import Registry


def _parts(reg: Registry):
    """The entries whose modules can be imported here (an engine adapter needs its engine)."""
    for name in reg:
        if reg is registry.ENGINES and importlib.util.find_spec(reg.about[name][0]) is None:
            continue
        yield name, reg.load(name)


@pytest.mark.parametrize("reg", registry.ALL, ids=[r.kind for r in registry.ALL])
def test_every_entry_loads(reg):
    assert len(reg) and len(set(reg.names())) == len(reg)
    for name, part in _parts(reg):
        assert part is not None, name


def test_each_kind_has_its_interface():
    for name, mod in registry.COMMANDS.items():
        assert isinstance(mod.HELP, str) and callable(mod.add_arguments) and callable(mod.main), (
            name
        )
    for name, mod in registry.STAGES.items():
        assert mod.NAME == name and callable(mod.applies) and callable(mod.run)
        # the runner asks hasattr(stage, "check"): an imported function of that name is not one
        for attr in ("applies", "run", "check"):
            assert getattr(getattr(mod, attr, None), "__module__", mod.__name__) == mod.__name__, (
                name,
                attr,
            )
    for name, mod in registry.BENCHES.items():
        # quick, then work (where a long benchmark keeps its finished units), which is optional
        params = list(inspect.signature(mod.run).parameters.values())
        assert params[0].name == "quick", name
        assert [p.name for p in params[1:]] in ([], ["work"]), name
        assert all(p.default is not inspect.Parameter.empty for p in params[1:]), name
    for reg in (
        registry.OPTIMIZERS,
        registry.STIFFNESS_RULES,
        registry.LOAD_SETS,
        registry.EXPERIMENTS,
    ):
        for name, fn in reg.items():
            assert callable(fn), name
    for name, fn in registry.OPTIMIZERS.items():
        # the interface's four, then only parameters a caller may leave out (lbfgs's deadline)
        params = list(inspect.signature(fn).parameters.values())
        assert [p.name for p in params[:4]] == ["problem", "options", "seed", "status"], name
        assert all(p.default is not inspect.Parameter.empty for p in params[4:]), name
    from harness.stages.classes.base import ModelClass

    for name, cls in registry.MODEL_CLASSES.items():
        assert isinstance(cls, ModelClass) and cls.name == name


def test_load_sets_are_of_the_dimension_they_declare():
    from harness.case.loadsets import Frame

    for name, make in registry.LOAD_SETS.items():
        dim = registry.LOAD_SETS.about[name]
        anchors = np.eye(dim)  # the body's anchor points (unused by the box sets)
        loads = make(1.0, None if name.startswith("basic") else anchors, Frame((0.5,) * dim, 1.0))
        assert loads, name
        for ld in loads:
            assert all(len(t.vector) == dim for t in ld.tractions), name
            assert ld.stress is None or len(ld.stress) == dim * (dim + 1) // 2, name


def test_the_case_schema_reads_its_vocabularies_from_the_registries():
    assert sections.OPTIMIZER_METHODS == registry.OPTIMIZERS.names()
    assert sections.MODEL_CLASSES == registry.MODEL_CLASSES.names()
    assert sections.STIFFNESS_RULES == registry.STIFFNESS_RULES.names()
    assert sections.ENGINE_NAMES == registry.ENGINES.names()
    assert sections.DYNAMICS["experiment"].choices == registry.EXPERIMENTS.names()
    from harness.case.fields import LOADS

    assert LOADS["set"].choices == registry.LOAD_SETS.names()


def test_the_export_engines_terms_are_the_classes_and_candidates_terms():
    """EXPORT_TERMS names each export engine's terms as the validated fit's candidates
    (Candidate.volume) and the springs classes (CLASS_TERMS: their volume / kn keys) do, and
    every export engine runs springs alone (calibrate --engine always has candidates)."""
    from harness.optimize.select import CANDIDATES

    engines = tuple(registry.EXPORT_TERMS)
    assert engines == registry.EXPORT_ENGINES == tuple(registry.EXPORT_TERMS_WHY)
    assert all("" in terms for terms in registry.EXPORT_TERMS.values())
    used = {t for terms in registry.EXPORT_TERMS.values() for t in terms}
    assert used | {c.volume for c in CANDIDATES} | set(registry.CLASS_TERMS.values()) <= set(
        registry.TERMS
    )
    assert tuple(registry.CLASS_TERMS) == registry.SPRINGS_CLASSES
    own = {"none": "", "shared": "element", "element": "element"}
    own.update({"node-shared": "node", "node": "node"})
    for name, cls in registry.MODEL_CLASSES.items():
        if name in registry.CLASS_TERMS:
            assert registry.CLASS_TERMS[name] == ("kn" if cls.kn != "none" else own[cls.volume])


def test_the_solver_names_are_one_list():
    """``[reference] solver``, ``calibrate --solver`` and the planner take registry.SOLVERS;
    every step a plan can name is one the sparse solve knows how to try."""
    from harness.case.fields import REFERENCE
    from harness.commands import calibrate
    from reference.solvers import plan, sparse

    names = tuple(registry.SOLVERS)
    assert REFERENCE["solver"].choices == names
    p = argparse.ArgumentParser()
    calibrate.add_arguments(p)
    assert next(a for a in p._actions if "--solver" in a.option_strings).choices == names
    for chain in plan._CHAINS.values():
        assert set(chain) <= set(sparse.STEPS)
    estimate = {"gflop": 1.0, "gbytes": 0.1}
    for name, n, coords, aid in itertools.product(names, (10, 10**6), *[(True, False)] * 2):
        s = plan.System(n, 3, name, coords=coords, coarse=aid, tensor=aid, nnz=10**6)
        steps = plan.choose_plan(dataclasses.replace(s, estimate=estimate)).steps
        assert steps and set(steps) <= set(sparse.STEPS), s
    with pytest.raises(ValueError, match="unknown solver 'lu'"):
        plan.choose_plan(plan.System(10, 3, "lu"))


def test_unknown_names_and_broken_modules_are_errors(tmp_path, monkeypatch):
    reg = Registry(
        "widget", {"good": "json:dumps", "broken": "no_such_module_here:f", "mod": "json"}
    )
    assert reg.load("good")([1]) == "[1]" and reg.load("mod").__name__ == "json"
    with pytest.raises(KeyError, match="unknown widget 'bad' .one of good, broken, mod."):
        reg.load("bad")
    with pytest.raises(ModuleNotFoundError):
        reg.load("broken")
    with pytest.raises(ModuleNotFoundError):
        reg.items()  # nothing is skipped silently
    (tmp_path / "raises_on_import.py").write_text("raise RuntimeError('boom')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(RuntimeError, match="boom"):
        Registry("widget", {"x": "raises_on_import:f"}).load("x")
    assert reg.with_entries({"good": "json:dumps"}).names() == ("good",)


def test_a_stage_module_that_fails_to_import_stops_the_run(tmp_path, monkeypatch):
    from harness.stages import load_stages

    (tmp_path / "stage_raises.py").write_text("raise ImportError('a missing dependency')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(registry, "STAGES", registry.STAGES.with_entries({"x": "stage_raises"}))
    with pytest.raises(ImportError, match="a missing dependency"):
        load_stages()
