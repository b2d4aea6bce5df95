"""Run ``hapticlab`` with its write points under a folder counted, and kill -9 itself at one.

``python -m benchmarks._killpoint ARGS…`` runs ``hapticlab ARGS…``. Every write point whose
path lies under ``$HAPTICLAB_KILL_ROOT`` is counted: opening a file for writing, each
write, each fsync, each rename/replace and each mkdir. With ``$HAPTICLAB_KILL_AT = N`` the
process sends itself SIGKILL right after the N-th point (as a power cut or ``kill -9``
would find it); with ``$HAPTICLAB_KILL_TORN = 1`` the N-th point, when it is a write, writes
only half of its bytes first (a torn write). ``$HAPTICLAB_KILL_LOG`` names a file that
receives one line per point (``kind<TAB>path``) as it happens.

The SQLite crash tests work this way; nothing here is part of hapticlab itself.
"""

from __future__ import annotations

import builtins
import io
import os
import signal
import sys

ROOT = os.path.realpath(os.environ.get("HAPTICLAB_KILL_ROOT", "/nonexistent")) + os.sep
KILL_AT = int(os.environ.get("HAPTICLAB_KILL_AT", "0"))
TORN = os.environ.get("HAPTICLAB_KILL_TORN") == "1"
LOG = os.environ.get("HAPTICLAB_KILL_LOG")

_count = 0
_fds: dict[int, str] = {}  # descriptors open for writing under ROOT → path
_log = open(LOG, "a", buffering=1) if LOG else None  # noqa: SIM115 - open for the run


def _under(path) -> bool:
    try:
        return os.path.realpath(os.fspath(path)).startswith(ROOT)
    except (TypeError, ValueError):
        return False


def _point(kind: str, path: str) -> bool:
    """Count a point; True when this one is the kill point (the caller finishes, then dies)."""
    global _count
    _count += 1
    if _log is not None:
        _log.write(f"{kind}\t{path}\n")
    return _count == KILL_AT


def _die() -> None:
    os.kill(os.getpid(), signal.SIGKILL)


_os_open, _os_write, _os_fsync = os.open, os.write, os.fsync
_os_replace, _os_rename, _os_mkdir, _os_close = os.replace, os.rename, os.mkdir, os.close
_open, _fdopen = builtins.open, os.fdopen
_WRITE_FLAGS = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_APPEND | os.O_TRUNC


def _open_fd(path, flags, mode=0o777, *, dir_fd=None):
    fd = _os_open(path, flags, mode, dir_fd=dir_fd)
    if flags & _WRITE_FLAGS and _under(path):
        _fds[fd] = os.fspath(path)
        if _point("open", os.fspath(path)):
            _die()
    elif _under(path):  # a folder opened to fsync it
        _fds[fd] = os.fspath(path)
    return fd


def _write_fd(fd, data):
    path = _fds.get(fd)
    if path is None:
        return _os_write(fd, data)
    kill = _point("write", path)
    if kill and TORN and len(data) > 1:
        _os_write(fd, bytes(data)[: len(data) // 2])
        _die()
    n = _os_write(fd, data)
    if kill:
        _die()
    return n


def _fsync(fd):
    fileno = fd if isinstance(fd, int) else fd.fileno()
    _os_fsync(fd)
    path = _fds.get(fileno)
    if path is not None and _point("fsync", path):
        _die()


def _close(fd):
    _fds.pop(fd, None)
    return _os_close(fd)


def _replace(src, dst, **kw):
    _os_replace(src, dst, **kw)
    if _under(dst) and _point("rename", os.fspath(dst)):
        _die()


def _rename(src, dst, **kw):
    _os_rename(src, dst, **kw)
    if _under(dst) and _point("rename", os.fspath(dst)):
        _die()


def _mkdir(path, mode=0o777, **kw):
    _os_mkdir(path, mode, **kw)
    if _under(path) and _point("mkdir", os.fspath(path)):
        _die()


class _File(io.RawIOBase):
    """A file opened for writing under ROOT: writes go through the counted ``os.write``."""

    def __init__(self, fd: int, path: str):
        super().__init__()
        self._fd, self.name = fd, path

    def writable(self) -> bool:
        return True

    def write(self, b) -> int:
        return _write_fd(self._fd, bytes(b))

    def fileno(self) -> int:
        return self._fd

    def close(self) -> None:
        if not self.closed:
            _close(self._fd)
        super().close()


def _wrap(fd: int, path: str, mode: str, encoding=None, newline=None):
    raw = _File(fd, path)
    if "b" in mode:
        return raw  # unbuffered: every write is a point
    return io.TextIOWrapper(io.BufferedWriter(raw, buffer_size=1 << 20), encoding=encoding
                            or "utf-8", newline=newline, write_through=False)


def _builtin_open(file, mode="r", buffering=-1, encoding=None, errors=None, newline=None,
                  closefd=True, opener=None):
    if isinstance(file, int) or not any(c in mode for c in "wax+") or not _under(file):
        return _open(file, mode, buffering, encoding, errors, newline, closefd, opener)
    flags = {"w": os.O_WRONLY | os.O_CREAT | os.O_TRUNC, "a": os.O_WRONLY | os.O_CREAT
             | os.O_APPEND, "x": os.O_WRONLY | os.O_CREAT | os.O_EXCL}[mode.strip("bt+")[0]]
    fd = _open_fd(file, flags, 0o666)
    return _wrap(fd, os.fspath(file), mode, encoding, newline)


def _os_fdopen(fd, mode="r", *args, **kw):
    if fd in _fds and any(c in mode for c in "wa+"):
        return _wrap(fd, _fds[fd], mode, kw.get("encoding"), kw.get("newline"))
    return _fdopen(fd, mode, *args, **kw)


def install() -> None:
    os.open, os.write, os.fsync, os.close = _open_fd, _write_fd, _fsync, _close
    os.replace, os.rename, os.mkdir, os.fdopen = _replace, _rename, _mkdir, _os_fdopen
    builtins.open = _builtin_open


def main() -> int:
    install()
    from app.cli import main as cli

    try:
        return cli(sys.argv[1:])
    finally:
        if _log is not None:
            _log.close()


if __name__ == "__main__":
    sys.exit(main())
