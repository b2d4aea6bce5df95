"""Checks that run before any device or window opens, so a session cannot start wrong.

Each check returns a :class:`Check` (``ok``, what it saw, and how to fix it); the session
refuses to start on the first failure, and ``hapticlab preflight`` prints them all.
"""

from __future__ import annotations

import errno
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

from .errors import DataFolderError, DiskFullError, NotAFolderError, io_error

__all__ = ["Check", "check_data_folder", "expected_session_bytes", "data_folder_ready",
           "PER_WINDOW_BYTES"]

#: bytes one tapping window's traces take on disk (compressed NumPy), by ``--traces`` mode;
#: measured on realism sessions (15 MB full, 5 MB contacts over 49 windows)
PER_WINDOW_BYTES = {"full": 320_000, "contacts": 110_000, "none": 0}
ROW_BYTES = 600  # one trials.tsv row, generously


@dataclass(frozen=True)
class Check:
    """One preflight check: its name, whether it passed, what was seen, and the fix."""

    name: str
    ok: bool
    detail: str
    fix: str = ""

    def line(self) -> str:
        mark = "ok  " if self.ok else "FAIL"
        return f"{mark} {self.name}: {self.detail}" + ("" if self.ok or not self.fix
                                                      else f" — {self.fix}")


def expected_session_bytes(protocol, traces: str = "full", redraw_margin: float = 1.5) -> int:
    """A generous estimate of what one session of ``protocol`` writes [bytes]."""
    windows = sum(len(p.samples) * p.repetitions for p in protocol.phases)
    return int(windows * redraw_margin * (PER_WINDOW_BYTES.get(traces, 0) + ROW_BYTES)) \
        + 200_000  # session.json, protocol copy, headroom


def _existing_ancestor(folder: Path) -> Path:
    p = folder.absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def data_folder_ready(folder: str | Path, need_bytes: int = 0) -> Path:
    """Make sure ``folder`` can take a session: a folder (or one that can be created there)
    that this user may write, on a writable file system, with ``need_bytes`` free. Nothing
    is created: a session that does not start leaves no trace.

    Raises
    ------
    DataFolderError
        A subclass naming the folder and the fix: not a folder, read-only, permission
        denied, disk full.
    """
    folder = Path(folder)
    base = _existing_ancestor(folder)
    if not base.is_dir():
        raise NotAFolderError(20, f"data folder {folder}: {base} is not a folder (it is a "
                                  "file or a device); give a folder for the sessions")
    try:
        if os.statvfs(base).f_flag & os.ST_RDONLY:
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(base))
        if not os.access(base, os.W_OK | os.X_OK):
            raise OSError(errno.EACCES, os.strerror(errno.EACCES), str(base))
        if base == folder.absolute():  # an existing folder: prove it with a real write
            fd, probe = tempfile.mkstemp(dir=folder, prefix=".hapticlab-probe-")
            try:
                os.write(fd, b"x")
                os.fsync(fd)
            finally:
                os.close(fd)
                os.unlink(probe)
    except OSError as exc:
        raise io_error(exc, f"data folder {folder} is not writable") from None
    free = shutil.disk_usage(base).free
    if free < need_bytes:
        raise DiskFullError(28, f"data folder {folder}: {free / 1e6:.1f} MB free, a session "
                                f"needs about {need_bytes / 1e6:.1f} MB; free some space or "
                                "record fewer traces (--traces contacts or none)")
    return folder


def check_data_folder(folder: str | Path, need_bytes: int = 0) -> Check:
    """:func:`data_folder_ready` as a preflight :class:`Check`."""
    try:
        data_folder_ready(folder, need_bytes)
    except DataFolderError as exc:
        return Check("data folder", False, str(exc))
    free = shutil.disk_usage(_existing_ancestor(Path(folder))).free
    return Check("data folder", True, f"{folder} writable, {free / 1e9:.1f} GB free "
                                      f"(a session needs about {need_bytes / 1e6:.1f} MB)")
