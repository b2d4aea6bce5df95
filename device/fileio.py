"""Durable file writes shared by the session recorder and the transient libraries, and what
kind of file a path is (for the errors of the readers of a user's files)."""

from __future__ import annotations

import errno
import os
import tempfile
from pathlib import Path

__all__ = ["atomic_write", "file_kind"]


def file_kind(path: str | Path) -> str:
    """What ``path`` is, in words: 'a regular file', 'a directory', 'a named pipe', 'a
    character device', 'a block device', 'a socket' or 'missing' — a reader checks it before
    opening, since opening a named pipe waits for a writer forever."""
    import stat

    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return "missing"
    for test, name in ((stat.S_ISREG, "a regular file"), (stat.S_ISDIR, "a directory"),
                       (stat.S_ISFIFO, "a named pipe"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def _umask() -> int:
    """The process umask (read without changing it where the system allows)."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except OSError:
        pass
    mask = os.umask(0o022)  # elsewhere: the classic read-and-restore
    os.umask(mask)
    return mask


def _place_new(tmp: str, path: Path) -> None:
    """Give ``tmp`` the name ``path`` only if the name is free: a hard link, which fails
    when it is taken; where the file system has no hard links (FAT and exFAT sticks, many
    SMB mounts) a check, then the rename (the session lock makes the recorder the only
    writer of its folder)."""
    try:
        os.link(tmp, path)
    except FileExistsError:
        raise
    except OSError as exc:
        if exc.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.ENOSYS,
                             errno.EMLINK, errno.EACCES):
            raise
        if os.path.lexists(path):
            raise FileExistsError(errno.EEXIST, "file exists", str(path)) from None
        os.replace(tmp, path)


def atomic_write(path: str | Path, data: bytes, overwrite: bool = True) -> None:
    """Write ``data`` to ``path`` atomically: a reader sees the old file or the new one,
    never a part, and a crash right after the call loses neither.

    Temporary file in the same folder, fsync, rename over the target, fsync the folder. The
    file gets the permissions any new file of this user gets (0666 less the umask): a
    temporary file is private (0600), which would hide session files from colleagues.

    Raises
    ------
    FileExistsError
        ``overwrite=False`` and ``path`` exists (the temporary file is hard-linked to its
        name, which fails rather than replace: no window in which another writer's file
        could be lost).
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.fchmod(fd, 0o666 & ~_umask())
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        if overwrite:
            os.replace(tmp, path)
        else:
            _place_new(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    dfd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(dfd)
    finally:
        os.close(dfd)
