"""One run per results folder, and no scratch left behind.

``run_lock(folder)``: a lock file ``.springbench.lock`` holding the owner's pid, created
atomically; a second run into the same folder while the owner lives is refused with one
line (a lock whose process is gone, e.g. a killed run, is taken over). Scratch folders
are named ``springbench-<pid>-*`` in the temporary directory; ``clean_stale_scratch``
removes those whose process is gone (a killed run's), at the start of every run.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path

from harness.errors import SpringbenchError
from harness.outputs import os_error

LOCK = ".springbench.lock"
SCRATCH = "springbench-"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _owner(path: Path) -> int | None:
    try:
        return int(path.read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return None


@contextmanager
def run_lock(folder: Path):
    """Hold the folder's lock for the duration of the block."""
    path = Path(folder) / LOCK
    for _ in range(2):
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            break
        except FileExistsError:
            pid = _owner(path)
            if pid is not None and pid != os.getpid() and _alive(pid):
                raise SpringbenchError(
                    f"another springbench run (pid {pid}) is writing here",
                    file=str(folder),
                    field="--results",
                    fix="wait for it to finish or give another --results folder",
                )
            path.unlink(missing_ok=True)  # stale: its run was killed
        except OSError as exc:  # read-only folder, ...
            raise os_error(exc, folder, "--results") from None
    else:
        raise SpringbenchError(
            "cannot take the results folder's lock", file=str(path), fix="remove the file"
        )
    try:
        try:
            os.write(fd, f"{os.getpid()}\n".encode())
        finally:
            os.close(fd)
    except OSError as exc:  # disk full: no lock, no empty lock file left
        path.unlink(missing_ok=True)
        raise os_error(exc, folder, "--results") from None
    try:
        yield
    finally:
        if _owner(path) == os.getpid():
            path.unlink(missing_ok=True)


def scratch_dir() -> Path:
    """A new scratch folder tagged with this process's pid."""
    return Path(tempfile.mkdtemp(prefix=f"{SCRATCH}{os.getpid()}-"))


def clean_stale_scratch(root: Path | None = None) -> int:
    """Remove scratch folders of processes that no longer exist; returns how many."""
    root = Path(root or tempfile.gettempdir())
    n = 0
    for d in root.glob(f"{SCRATCH}*-*"):
        try:
            pid = int(d.name[len(SCRATCH) :].split("-")[0])
        except ValueError:
            continue  # not ours (an old untagged name)
        if d.is_dir() and not _alive(pid):
            shutil.rmtree(d, ignore_errors=True)
            n += 1
    return n
