"""Writing the user's output files: refused up front when they cannot be written, written
atomically (temp file in the same folder + ``os.replace``: a reader sees the old file or the
new one, never half), and any file-system failure (disk full, read-only, a folder in the
way) is one line naming the path the user gave, never a temporary file.

``check_out_file`` / ``check_out_dir`` run before a command computes anything;
``atomic_write`` writes bytes; ``staged`` gives temp paths for writers that want a path
(meshio, pandas) and puts all of them in place together, or none.
"""

from __future__ import annotations

import errno
import os
import uuid
from contextlib import contextmanager
from pathlib import Path

from harness.errors import SpringbenchError

_WHY = {
    errno.ENOSPC: (
        "disk full (no space left on the device)",
        "free space on that disk or write somewhere else",
    ),
    errno.EDQUOT: ("disk quota exceeded", "free space on that disk or write somewhere else"),
    errno.EROFS: ("read-only file system", "give a writable folder"),
    errno.EACCES: ("permission denied", "give a folder you can write to"),
    errno.EPERM: ("permission denied", "give a folder you can write to"),
    errno.EISDIR: ("is a folder", "give a file name inside it, e.g. FOLDER/out.csv"),
    errno.ENOTDIR: ("a parent of it is a file, not a folder", "give a path inside a folder"),
    errno.EEXIST: ("a parent of it is a file, not a folder", "give a path inside a folder"),
}


def os_error(exc: OSError, path, field: str | None = None) -> SpringbenchError:
    """One line for a failed write of ``path`` (the user's name for it)."""
    msg, fix = _WHY.get(
        exc.errno, (f"cannot write it ({exc.strerror or exc})", "check the path and the disk")
    )
    return SpringbenchError(msg, file=str(path), field=field, fix=fix)


def _existing_ancestor(p: Path) -> Path:
    p = Path(os.path.abspath(p))
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def _check_writable_folder(folder: Path, path, field):
    if not folder.is_dir():
        raise SpringbenchError(
            f"{folder} is a file, not a folder",
            file=str(path),
            field=field,
            fix="give a path inside a folder",
        )
    if not os.access(folder, os.W_OK | os.X_OK):
        readonly = bool(os.statvfs(folder).f_flag & os.ST_RDONLY)
        raise os_error(OSError(errno.EROFS if readonly else errno.EACCES, ""), path, field)


def check_out_file(path, field: str | None = "--out") -> Path:
    """Refuse an output file that cannot be written, before any work: a folder in its place,
    a file where a parent folder goes, a read-only or foreign folder. Missing folders are
    fine (they are created when writing)."""
    path = Path(path)
    if path.is_dir():
        raise os_error(OSError(errno.EISDIR, ""), path, field)
    _check_writable_folder(_existing_ancestor(path.parent), path, field)
    return path


def check_out_dir(path, field: str | None = "--out") -> Path:
    """The same for an output folder (it may exist; it must be a folder)."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise SpringbenchError(
            "exists and is not a folder",
            file=str(path),
            field=field,
            fix="give a folder (or a new name)",
        )
    _check_writable_folder(_existing_ancestor(path), path, field)
    return path


def _temp(path: Path, token: str) -> Path:
    # same folder (os.replace stays on one file system), same suffix (writers pick the
    # format by it), one token per batch (MODEL.vtu's writer finds MODEL.json by suffix)
    return path.with_name(f".{path.stem}.{token}.part{path.suffix}")


def _token() -> str:
    return f"{os.getpid()}-{uuid.uuid4().hex[:8]}"


def atomic_write(path, data: bytes, field: str | None = None):
    """Write ``data`` to ``path`` so readers see the old file or the new one, never half."""
    with staged([path], field) as (tmp,):
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())


def write_changed(path, data: bytes, field: str | None = None) -> bool:
    """:func:`atomic_write` unless ``path`` already holds exactly ``data`` (then the file,
    its time stamp included, is left alone); True if it wrote."""
    path = Path(path)
    try:
        if path.is_file() and path.stat().st_size == len(data) and path.read_bytes() == data:
            return False
    except OSError:
        pass
    atomic_write(path, data, field)
    return True


@contextmanager
def staged(paths, field: str | None = None):
    """Temp paths beside ``paths``; on leaving the block every temp file replaces its
    target; on any error none does and the temps are removed (an OSError becomes one
    line naming the user's path)."""
    paths = [Path(p) for p in paths]
    token = _token()
    temps = [_temp(p, token) for p in paths]
    try:
        for p in paths:
            p.parent.mkdir(parents=True, exist_ok=True)
            if p.is_dir():
                raise OSError(errno.EISDIR, "Is a directory", str(p))
        yield temps
        for t, p in zip(temps, paths):
            os.replace(t, p)
    except OSError as exc:
        failed = next(
            (p for t, p in zip(temps, paths) if exc.filename in (str(t), str(p))), paths[0]
        )
        raise os_error(exc, failed, field) from None
    except SpringbenchError as exc:  # a nested atomic writer named our temp file: name the user's
        user = next((p for t, p in zip(temps, paths) if exc.file == str(t)), None)
        if user is None:
            raise
        raise type(exc)(
            exc.message, file=str(user), field=field or exc.field, fix=exc.fix
        ) from None
    finally:
        for t in temps:
            try:
                t.unlink()
            except OSError:
                pass
