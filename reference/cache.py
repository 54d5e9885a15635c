"""On-disk cache of reference solutions, keyed by a hash of everything that determines
them: the case's body (mesh file contents, not its path), material, loads and
[reference] settings, plus the source code of the reference and the harness modules it
uses. Name, description, tags and stage sections do not enter the key. Files are npz
under $SPRINGBENCH_CACHE or ~/.cache/springbench (never results/), not compressed:
floating-point fields shrink only 1.8x and take 30x as long to write (the README lug's
49 MB: 1.9 s compressed, 0.06 s not)."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from pathlib import Path
from types import MappingProxyType

import numpy as np

from harness.sources import digest, tree_shas

# what a reference solution can depend on: the reference and the layers before it (the case,
# its load sets, mesh files, the sparse solvers); the registry only names the load sets,
# and the loads they make enter the key themselves (case_key)
CODE = ("reference", "harness/case", "harness/io", "harness/linalg")


def cache_dir() -> Path:
    root = os.environ.get("SPRINGBENCH_CACHE") or Path.home() / ".cache" / "springbench"
    return Path(root) / "reference"


def code_version() -> str:
    """Digest of the source files whose change could change a reference solution."""
    return digest(tree_shas(CODE))


def _canon(x):
    if dataclasses.is_dataclass(x):
        return {f.name: _canon(getattr(x, f.name)) for f in dataclasses.fields(x)}
    if isinstance(x, (dict, MappingProxyType)):
        return {str(k): _canon(v) for k, v in sorted(x.items())}
    if isinstance(x, (list, tuple)):
        return [_canon(v) for v in x]
    if isinstance(x, Path):
        return hashlib.sha256(x.read_bytes()).hexdigest() if x.exists() else str(x)
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    return x


def case_key(case) -> str:
    """Hex digest identifying the reference solution of ``case``."""
    payload = {
        "dim": case.dim,
        "body": _canon(case.body),
        "material": _canon(case.material),
        "loads": _canon(case.loads),
        "reference": _canon(case.reference),
        # the loads the adaptive levels drive to tol (reference/adaptive/adapt.py scored_loads)
        "scored": [list(case.heldout), list(case.validation)],
        "code": code_version(),
    }
    text = json.dumps(payload, sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def load(name: str) -> dict | None:
    path = cache_dir() / f"{name}.npz"
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as f:
            return {k: f[k] for k in f.files}
    except (OSError, ValueError, EOFError):
        return None  # a damaged file is recomputed


def save(name: str, **arrays) -> Path:
    d = cache_dir()
    d.mkdir(parents=True, exist_ok=True)
    path = d / f"{name}.npz"
    tmp = d / f".{name}.{os.getpid()}.tmp.npz"
    np.savez(tmp, **arrays)
    os.replace(tmp, path)
    return path
