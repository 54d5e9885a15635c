"""File-system faults for the bad-output tests (no tests here), real where the machine allows:

- ``read_only(folder)``: the folder bind-mounted read-only on itself, its files still
  there (root with mount rights); else ``chmod 0o555`` (a user that is not root cannot write
  there); else (root without
  mount rights: chmod does not stop root) a simulation: opening for writing, creating,
  replacing and mkdir under the folder raise EROFS, and statvfs/access report read-only.
- ``disk_full(folder)``: a 1 MiB tmpfs mounted on the folder; ``.fill(free_pages)`` fills
  it up to that many free 4 KiB pages; else a simulation that accounts like tmpfs: after
  ``.fill``, every file written under the folder takes whole pages, and a write past the
  last free page writes what fits and raises ENOSPC (what was written before stays, as on
  a real disk).

``simulate=True`` forces the simulation, so the fallback that CI may run is tested here
too. Each yields a handle: ``.method`` ("bind-mount", "tmpfs", "chmod" or "simulated")
and, for ``disk_full``, ``.fill(free_pages)`` and ``.free_up()`` (delete the filler / lift
the limit)."""

from __future__ import annotations

import builtins
import errno
import io
import math
import os
import subprocess
from contextlib import contextmanager
from pathlib import Path

import pytest

PAGE = 4096


class Handle:
    def __init__(self, method, fill=None, free_up=None):
        self.method, self.fill, self.free_up = method, fill, free_up


def _under(path, folder: Path) -> bool:
    try:
        return Path(os.path.abspath(os.fsdecode(path))).is_relative_to(folder)
    except (TypeError, ValueError):
        return False  # a file descriptor, not a path


def _mount(*argv) -> bool:
    if os.geteuid() != 0:
        return False
    try:
        return (
            subprocess.run(["mount", *map(str, argv)], capture_output=True, timeout=60).returncode
            == 0
        )
    except (OSError, subprocess.TimeoutExpired):  # no mount(8) here
        return False


def _umount(folder: Path):
    if subprocess.run(["umount", str(folder)], capture_output=True).returncode != 0:
        subprocess.run(["umount", "-l", str(folder)], capture_output=True)


def _writes(mode: str) -> bool:
    return any(c in mode for c in "wax+")


@contextmanager
def read_only(folder: Path, simulate: bool = False):
    folder = Path(folder).resolve()
    folder.mkdir(parents=True, exist_ok=True)
    if not simulate and _mount("--bind", folder, folder):
        try:
            if _mount("-o", "remount,bind,ro", folder):
                yield Handle("bind-mount")
                return
        finally:
            _umount(folder)
    if not simulate and os.geteuid() != 0:
        folder.chmod(0o555)
        try:
            yield Handle("chmod")
        finally:
            folder.chmod(0o755)
        return
    real = {
        "open": builtins.open,
        "os_open": os.open,
        "mkdir": os.mkdir,
        "replace": os.replace,
        "access": os.access,
        "statvfs": os.statvfs,
    }

    def refuse(path):
        raise OSError(errno.EROFS, "Read-only file system", os.fsdecode(path))

    def fake_open(file, mode="r", *a, **kw):
        if _writes(mode) and _under(file, folder):
            refuse(file)
        return real["open"](file, mode, *a, **kw)

    def fake_os_open(path, flags, *a, **kw):
        if flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT) and _under(path, folder):
            refuse(path)
        return real["os_open"](path, flags, *a, **kw)

    def fake_mkdir(path, *a, **kw):
        if _under(path, folder) and not Path(path).exists():
            refuse(path)
        return real["mkdir"](path, *a, **kw)

    def fake_replace(src, dst, *a, **kw):
        if _under(dst, folder):
            refuse(dst)
        return real["replace"](src, dst, *a, **kw)

    def fake_access(path, how, *a, **kw):
        return (
            False if how & os.W_OK and _under(path, folder) else real["access"](path, how, *a, **kw)
        )

    def fake_statvfs(path):
        st = real["statvfs"](path)
        if _under(path, folder):
            st = os.statvfs_result(tuple(st[:8]) + (st.f_flag | os.ST_RDONLY, st.f_namemax))
        return st

    with pytest.MonkeyPatch.context() as mp:
        for mod, name, fn in (
            (builtins, "open", fake_open),
            (io, "open", fake_open),
            (os, "open", fake_os_open),
            (os, "mkdir", fake_mkdir),
            (os, "replace", fake_replace),
            (os, "access", fake_access),
            (os, "statvfs", fake_statvfs),
        ):
            mp.setattr(mod, name, fn)
        yield Handle("simulated")


class _Budget:
    """Free pages, spent like tmpfs: a file of n bytes holds ceil(n / PAGE) pages."""

    def __init__(self, pages):
        self.pages = pages

    def spend(self, held: int, size: int, n: int) -> int:
        """Bytes of an n-byte write at ``size`` that fit (the file holds ``held`` pages)."""
        if self.pages is None:
            return n
        room = (held + self.pages) * PAGE - size
        return max(0, min(n, room))

    def take(self, pages: int):
        if self.pages is not None:
            self.pages -= pages


class _Sized:
    def __init__(self):
        self.size = 0

    @property
    def held(self):
        return math.ceil(self.size / PAGE)


class _FullFile(_Sized):
    """A file object whose writes draw on the budget."""

    def __init__(self, fh, budget):
        super().__init__()
        self._fh, self._budget = fh, budget

    def write(self, data):
        raw = data.encode() if isinstance(data, str) else bytes(data)
        ok = self._budget.spend(self.held, self.size, len(raw))
        if ok < len(raw):
            if ok:
                self._fh.write(
                    raw[:ok].decode(errors="ignore") if isinstance(data, str) else raw[:ok]
                )
                self._fh.flush()
            self._grow(ok)
            raise OSError(errno.ENOSPC, "No space left on device")
        self._grow(len(raw))
        return self._fh.write(data)

    def _grow(self, n):
        before = self.held
        self.size += n
        self._budget.take(self.held - before)

    def __getattr__(self, name):
        return getattr(self._fh, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._fh.close()

    def __iter__(self):
        return iter(self._fh)


@contextmanager
def disk_full(folder: Path, simulate: bool = False):
    folder = Path(folder).resolve()
    folder.mkdir(parents=True, exist_ok=True)
    if not simulate and _mount("-t", "tmpfs", "-o", "size=1m", "tmpfs", folder):
        filler = folder / ".filler"

        def fill(free_pages=0):
            st = os.statvfs(folder)
            with open(filler, "ab") as fh:
                fh.write(b"\0" * ((st.f_bavail - free_pages) * st.f_frsize))

        try:
            yield Handle("tmpfs", fill, lambda: filler.unlink())
        finally:
            _umount(folder)
        return
    budget = _Budget(None)
    real = {"open": builtins.open, "os_open": os.open, "write": os.write, "close": os.close}
    fds: dict[int, _Sized] = {}

    def fake_open(file, mode="r", *a, **kw):
        fh = real["open"](file, mode, *a, **kw)
        return _FullFile(fh, budget) if _writes(mode) and _under(file, folder) else fh

    def fake_os_open(path, flags, *a, **kw):
        fd = real["os_open"](path, flags, *a, **kw)
        if flags & (os.O_WRONLY | os.O_RDWR) and _under(path, folder):
            fds[fd] = _Sized()
        return fd

    def fake_write(fd, data):
        f = fds.get(fd)
        if f is not None:
            ok = budget.spend(f.held, f.size, len(data))
            if ok < len(data):
                raise OSError(errno.ENOSPC, "No space left on device")
            before = f.held
            f.size += len(data)
            budget.take(f.held - before)
        return real["write"](fd, data)

    def fake_close(fd):
        fds.pop(fd, None)
        return real["close"](fd)

    def fill(free_pages=0):
        budget.pages = free_pages

    def free_up():
        budget.pages = None

    with pytest.MonkeyPatch.context() as mp:
        for mod, name, fn in (
            (builtins, "open", fake_open),
            (io, "open", fake_open),
            (os, "open", fake_os_open),
            (os, "write", fake_write),
            (os, "close", fake_close),
        ):
            mp.setattr(mod, name, fn)
        yield Handle("simulated", fill, free_up)
