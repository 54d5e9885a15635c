"""The house rules the layout promises: no import circles among the modules of harness/
and reference/ (imports inside functions count), read from the source with ``ast``; every
folder imports only from folders before it in the pipeline (LAYERS); and no hand-written
module over 500 lines (generated ones say so on their first line)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("harness", "reference")


def modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for f in (ROOT / pkg).rglob("*.py"):
            parts = f.relative_to(ROOT).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = f
    return out


def imported(name: str, path: Path, known) -> set[str]:
    """The project modules ``name`` imports anywhere in its source. ``from pkg import
    mod`` counts as importing pkg.mod, not pkg (Python runs pkg/__init__ either way, as
    for any import of one of its modules)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in _runtime_nodes(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(up + ([node.module] if node.module else []))
            subs = [f"{base}.{a.name}" for a in node.names if f"{base}.{a.name}" in known]
            found.update(subs or [base])
            found.update(base for a in node.names if f"{base}.{a.name}" not in known)
    out = set()
    for target in found:
        while target and target not in known:
            target = target.rpartition(".")[0]
        if target and target != name:
            out.add(target)
    return out


def _runtime_nodes(tree):
    """Every node of the module but those under ``if TYPE_CHECKING:`` (annotations only:
    such an import never runs)."""
    stack = [tree]
    while stack:
        node = stack.pop()
        yield node
        for child in ast.iter_child_nodes(node):
            test = getattr(child, "test", None) if isinstance(child, ast.If) else None
            if test is not None and "TYPE_CHECKING" in ast.unparse(test):
                stack.extend(child.orelse)
                continue
            stack.append(child)


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index, low, stack, on, comps, counter = {}, {}, [], set(), [], [0]
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        comps.append(sorted(comp))
    return comps


def graph() -> dict[str, set[str]]:
    known = modules()
    return {name: imported(name, path, known) for name, path in known.items()}


def test_the_checker_finds_a_circle():
    g = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert cycles(g) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_the_checker_reads_function_level_and_relative_imports(tmp_path):
    known = {"harness.x": None, "harness.y": None, "harness.z": None, "harness": None}
    src = tmp_path / "x.py"
    src.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from harness import q\n"
                   "def f():\n    from harness.y import thing\n    from . import z\n")
    assert imported("harness.x", src, known) == {"harness.y", "harness.z"}


def test_no_import_circles():
    assert cycles(graph()) == []


# The pipeline, first to last: a module may import its own layer and the layers before it.
# The base (the registry of names, errors, paths, atomic outputs, sparse linear algebra, provenance, progress bars) is
# below everything; the report reads stored results and never imports the runner, which calls it.
LAYERS = ("harness harness.registry harness.sources harness.errors harness.paths harness.outputs harness.linalg harness.provenance harness.progress",
          "harness.io", "harness.case", "reference", "harness.geometry", "harness.models",
          "harness.mechanics", "harness.optimize", "harness.scoring", "harness.export", "harness.engines",
          "harness.stages", "harness.report", "harness.run", "harness.bench", "harness.commands",
          "harness.cli harness.__main__")


def layer_of(module: str, layers=LAYERS) -> tuple[int, str] | None:
    """(rank, prefix) of the longest layer prefix naming ``module`` (None if none)."""
    hits = [(len(p), i, p) for i, ps in enumerate(layers) for p in ps.split()
            if module == p or module.startswith(p + ".")]
    return (max(hits)[1], max(hits)[2]) if hits else None


def backward_imports(g: dict[str, set[str]], layers=LAYERS) -> list[str]:
    """Imports from a later layer (and modules in no layer), as "a (layer) -> b (layer)"."""
    out = []
    for name, targets in sorted(g.items()):
        here = layer_of(name, layers)
        if here is None:
            out.append(f"{name}: in no layer")
            continue
        for t in sorted(targets):
            there = layer_of(t, layers)
            if there is None or there[0] > here[0]:
                out.append(f"{name} ({here[1]}) -> {t} ({there and there[1]})")
    return out


def test_the_layer_checker_finds_a_backward_import():
    layers = ("base", "case", "models")
    g = {"case.a": {"base.x", "case.b"}, "case.b": set(), "models.m": {"case.a"}, "base.x": set()}
    assert backward_imports(g, layers) == []
    g["case.b"] = {"models.m"}
    assert backward_imports(g, layers) == ["case.b (case) -> models.m (models)"]
    assert backward_imports({"stray": set()}, layers) == ["stray: in no layer"]


def test_folders_import_only_earlier_folders():
    assert backward_imports(graph()) == []


MAX_LINES = 500


def test_no_hand_written_module_over_500_lines():
    long = {name: n for name, path in modules().items()
            if (n := len(path.read_text().splitlines())) > MAX_LINES
            and not path.read_text().lstrip('"').startswith("GENERATED")}
    assert long == {}
