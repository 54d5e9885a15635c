"""Rewrites the generated parts of the front-door documents (harness/report/docs_gen.py):
README.md's results table from results/bench/heldout.csv, docs/calibrate.md's scale table
from results/bench/calibrate.csv, docs/commands.md's reference
of every command and flag from the command line's parser and docs/columns.md's table of
every summary.csv column from harness/report/columns.py.

    python docs/generate.py

tests/docs/ fail until this has been run after a change to either.
"""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from harness.cli import build_parser  # noqa: E402
from harness.report.docs_gen import (  # noqa: E402
    BEGIN,
    CMD_BEGIN,
    CMD_END,
    COL_BEGIN,
    COL_END,
    END,
    SCALE_BEGIN,
    SCALE_END,
    columns_reference,
    commands_reference,
    heldout_table,
    scale_table,
    update,
)

if __name__ == "__main__":
    for path, content, markers in (
        (ROOT / "README.md", heldout_table(ROOT / "results"), (BEGIN, END)),
        (ROOT / "docs" / "calibrate.md", scale_table(ROOT / "results"), (SCALE_BEGIN, SCALE_END)),
        (ROOT / "docs" / "commands.md", commands_reference(build_parser()), (CMD_BEGIN, CMD_END)),
        (ROOT / "docs" / "columns.md", columns_reference(), (COL_BEGIN, COL_END)),
    ):
        changed = update(path, content, *markers)
        print(f"{path.relative_to(ROOT)}: " + ("rewritten" if changed else "unchanged"))
