"""Which source files a result depends on, and their hashes: the one scheme behind the
reference cache's key (the folders a reference solution can depend on) and the runner's
record of the code each result came from (the modules the job loaded).

A file's identity is its path relative to the checkout and the SHA-256 of its bytes; a
set of files is identified by :func:`digest` of those pairs, so moving or renaming a
module changes the digest as changing it does."""

from __future__ import annotations

import hashlib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_SHA_CACHE: dict[tuple, str] = {}


def file_sha(path: Path) -> str | None:
    """SHA-256 of a file (cached by path, size and mtime); None if it is gone."""
    try:
        st = path.stat()
    except OSError:
        return None
    key = (str(path), st.st_size, st.st_mtime_ns)
    if key not in _SHA_CACHE:
        _SHA_CACHE[key] = hashlib.sha256(path.read_bytes()).hexdigest()
    return _SHA_CACHE[key]


def relative(path: Path) -> str:
    """The file's key: its path relative to the checkout (absolute when outside it)."""
    p = Path(path).resolve()
    return p.relative_to(ROOT).as_posix() if p.is_relative_to(ROOT) else str(p)


def tree_shas(paths) -> dict[str, str]:
    """{file key: sha} of every .py file under the folders (or the files) ``paths``,
    relative to the checkout."""
    out = {}
    for given in paths:
        p = ROOT / given
        for f in sorted(p.rglob("*.py")) if p.is_dir() else [p]:
            sha = file_sha(f)
            if sha:
                out[relative(f)] = sha
    return dict(sorted(out.items()))


def digest(shas: dict[str, str]) -> str:
    """One hex digest (16 characters) of {file key: sha}."""
    h = hashlib.sha256()
    for key, sha in sorted(shas.items()):
        h.update(f"{key} {sha}\n".encode())
    return h.hexdigest()[:16]
