"""The tests mirror the package's folders (tests/case/, tests/reference/, ...). Their shared
helpers (meshes.py, independent_elasticity.py, fs_faults.py, the fake runner stage) stay
here, and test modules share fixtures by module name (``from test_runner import fake``),
so this folder and every sub-folder are importable from any test (names are unique)."""

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
for folder in [HERE, *sorted(p for p in HERE.iterdir() if p.is_dir() and any(p.glob("test_*.py")))]:
    if str(folder) not in sys.path:
        sys.path.insert(0, str(folder))
