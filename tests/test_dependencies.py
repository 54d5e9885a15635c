"""Every third-party module harness/ or reference/ imports is declared in pyproject.toml,
as a dependency or in an extra, under its distribution's name (the import names that
differ are mapped in [tool.deptry.package_module_name_map], checked here against the
installed distributions where they are installed)."""

import ast
import importlib.metadata
import re
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def imported_modules() -> set[str]:
    mods = set()
    for folder in ("harness", "reference"):
        for f in (ROOT / folder).rglob("*.py"):
            for n in ast.walk(ast.parse(f.read_text(encoding="utf-8"))):
                if isinstance(n, ast.Import):
                    mods |= {a.name.split(".")[0] for a in n.names}
                elif isinstance(n, ast.ImportFrom) and n.level == 0 and n.module:
                    mods.add(n.module.split(".")[0])
    return {
        m for m in mods if m not in sys.stdlib_module_names and m not in ("harness", "reference")
    }


def declared() -> tuple[set[str], dict[str, str]]:
    """(normalised distribution names of every dependency and extra, {distribution: module})."""
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    reqs = list(meta["project"]["dependencies"])
    for extra in meta["project"].get("optional-dependencies", {}).values():
        reqs += extra
    norm = {re.split(r"[\[<>=!~; ]", r, maxsplit=1)[0].lower().replace("_", "-") for r in reqs}
    return norm, meta["tool"]["deptry"]["package_module_name_map"]


def test_every_imported_module_is_declared():
    names, module_of = declared()
    provided = {module_of.get(d, d.replace("-", "_")) for d in names}
    missing = sorted(imported_modules() - provided)
    assert not missing, f"imported but not declared in pyproject.toml: {missing}"


def test_the_import_name_map_matches_the_installed_distributions():
    names, module_of = declared()
    assert set(module_of) <= names  # the map names declared distributions only
    installed = importlib.metadata.packages_distributions()
    for dist, module in module_of.items():
        if module in installed:
            assert dist in [d.lower() for d in installed[module]], (dist, module, installed[module])
