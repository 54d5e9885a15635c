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
    src.write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from harness import q\n"
        "def f():\n    from harness.y import thing\n    from . import z\n"
    )
    assert imported("harness.x", src, known) == {"harness.y", "harness.z"}


def test_no_import_circles():
    assert cycles(graph()) == []


# The reference's own floors, first to last: the lattice, the mirror planes, meshes, the
# locator and the cache; assembly; the solvers; the problem on one mesh; the graded levels;
# the adaptive refinement (which reads the graded extrapolation); the methods; the solution
# and the package's ``solve`` on top.
REFERENCE_FLOORS = (
    "reference.lattice reference.mirror reference.mesh reference.locate reference.cache "
    "reference.analytic",
    "reference.fem",
    "reference.solvers",
    "reference.problem",
    "reference.graded",
    "reference.adaptive",
    "reference.methods",
    "reference.solution reference",
)

# The pipeline, first to last: a module may import its own layer and the layers before it.
# The base (the registry of names, errors, paths, atomic outputs, sparse linear algebra,
# provenance, progress bars) is
# below everything; the report reads stored results and never imports the runner, which calls it.
LAYERS = (
    "harness harness.registry harness.sources harness.errors harness.paths harness.outputs "
    "harness.linalg harness.provenance harness.progress harness.forkpool",
    "harness.io",
    "harness.case",
    *REFERENCE_FLOORS,
    "harness.geometry",
    "harness.models",
    "harness.mechanics",
    "harness.optimize",
    "harness.scoring",
    "harness.export",
    "harness.engines",
    "harness.stages",
    "harness.report",
    "harness.run",
    "harness.bench",
    "harness.commands",
    "harness.cli harness.__main__",
)


def layer_of(module: str, layers=LAYERS) -> tuple[int, str] | None:
    """(rank, prefix) of the longest layer prefix naming ``module`` (None if none)."""
    hits = [
        (len(p), i, p)
        for i, ps in enumerate(layers)
        for p in ps.split()
        if module == p or module.startswith(p + ".")
    ]
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


def test_every_module_of_the_reference_is_on_a_named_floor():
    """``reference`` on the top floor names the package alone: a new module gets a floor."""
    stray = [m for m in modules() if m.startswith("reference.") and layer_of(m)[1] == "reference"]
    assert stray == [], "add these to REFERENCE_FLOORS"


MAX_LINES = 500


def test_no_hand_written_module_over_500_lines():
    """Source and test modules alike (generated ones say so on their first line)."""
    paths = [*modules().values(), *(ROOT / "tests").rglob("*.py")]
    long = {
        str(path.relative_to(ROOT)): n
        for path in paths
        if (n := len(path.read_text().splitlines())) > MAX_LINES
        and not path.read_text().lstrip('"').startswith("GENERATED")
    }
    assert long == {}


# An import stays inside a function only in the command modules (``springbench --help``
# imports every one), for an optional dependency (inside ``try``), or when its module is
# slow to import and only some paths need it. These are the slow ones: each costs more than
# 100 ms beyond numpy and scipy (``python -X importtime``; scikit-fem behind the reference
# modules 0.3-0.5 s, numba behind the element kernels 0.2-0.25 s, pandas behind the stage
# helpers 0.15-0.3 s); hoisting them made ``springbench validate cases/`` 15-25 % slower.
LAZY = frozenset(
    {
        "harness.engines.newton_volume",
        "harness.geometry",
        "harness.geometry.bodies",
        "harness.models.bc2000.kernels",
        "harness.models.bc2000.parallel",
        "harness.models.masses",
        "harness.optimize.gradient",
        "harness.optimize.gauss_newton",
        "harness.stages.bc2000_linear",
        "harness.stages.sms_fit",
        "harness.stages.sms_measures",
        "harness.stages.sms_select",
        "reference",
        "reference.analytic",
        "reference.graded.meshes",
        "reference.graded.symmetry",
        "reference.mesh",
        "reference.problem",
        "reference.solvers.sparse",
        "reference.solvers.twolevel",
    }
)
EAGER_EXEMPT = ("harness/commands/", "harness/cli.py", "harness/__main__.py")


def lazy_project_imports(path: Path, known) -> list[tuple[int, str]]:
    """(line, module) of the imports of project modules inside functions (not in ``try``)."""
    out = []

    def walk(node, in_func, in_try):
        for c in ast.iter_child_nodes(node):
            if (
                in_func
                and not in_try
                and isinstance(c, (ast.Import, ast.ImportFrom))
                and not getattr(c, "level", 0)
            ):
                names = (
                    [
                        f"{c.module}.{a.name}" if f"{c.module}.{a.name}" in known else c.module
                        for a in c.names
                    ]
                    if isinstance(c, ast.ImportFrom)
                    else [a.name for a in c.names]
                )
                out.extend((c.lineno, n) for n in names if n and n.split(".")[0] in PACKAGES)
            walk(
                c,
                in_func or isinstance(c, (ast.FunctionDef, ast.AsyncFunctionDef)),
                in_try or isinstance(c, ast.Try),
            )

    walk(ast.parse(path.read_text(), str(path)), False, False)
    return out


def test_the_lazy_import_checker_reads_functions_and_skips_try(tmp_path):
    src = tmp_path / "m.py"
    src.write_text(
        "import harness.errors\ndef f():\n    from harness.stages import sms_fit\n    "
        "import reference\n"
        "    try:\n        from harness import scoring\n    except ImportError:\n        pass\n"
    )
    known = {"harness.stages.sms_fit", "harness.stages", "reference", "harness.scoring"}
    assert lazy_project_imports(src, known) == [(3, "harness.stages.sms_fit"), (4, "reference")]


def test_imports_are_at_module_top_unless_slow():
    known = modules()
    eager = [
        f"{path.relative_to(ROOT)}:{line} {mod}"
        for name, path in known.items()
        if not path.relative_to(ROOT).as_posix().startswith(EAGER_EXEMPT)
        for line, mod in lazy_project_imports(path, known)
        if mod not in LAZY
    ]
    assert eager == [], "import these at the module's top (or measure and add the module to LAZY)"
