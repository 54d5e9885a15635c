"""A suite's committed ``_generate.py`` loaded as a module (the scripts are not a package)."""

import importlib.util

from harness.paths import ROOT


def generator(suite: str):
    """The module ``cases/<suite>/_generate.py``."""
    spec = importlib.util.spec_from_file_location(
        f"{suite}_generate", ROOT / "cases" / suite / "_generate.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
