"""Where the harness finds cases and writes results: the checkout's own folders for an
editable install (cases/ beside the package), else the current folder's."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
HOME = ROOT if (ROOT / "cases").is_dir() else Path.cwd()
DEFAULT_CASES = HOME / "cases"
DEFAULT_RESULTS = HOME / "results"  # the published tables: the --full run, committed
DEFAULT_RUNS = HOME / "runs"  # where a user's runs go by default (git-ignored)
