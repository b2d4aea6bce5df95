"""The application's errors: every one is a :class:`~device.errors.HapticlabError`, which the
command line prints on one line (exit 2).

:mod:`analysis` keeps its own ``ValueError`` subclasses (it imports nothing of ours, in the
manner of pingouin); the application's API wraps them here.
"""

from __future__ import annotations

import errno

from device.errors import HapticlabError

__all__ = ["HapticlabError", "SessionFileError", "MissingLibraryError", "AnalysisError",
           "UsageError", "SessionInUseError", "DataFolderError", "DiskFullError",
           "FileTooLargeError", "ReadOnlyError", "PermissionDeniedError", "NotAFolderError",
           "io_error"]


class UsageError(HapticlabError, ValueError):
    """An argument that cannot be used (named, with what is allowed)."""


class SessionFileError(HapticlabError, ValueError):
    """A session folder's files cannot be used (named by file and line)."""


class MissingLibraryError(HapticlabError):
    """A matched sample has no transient library built on the device in use; the message
    gives the command that builds it."""


class AnalysisError(HapticlabError, ValueError):
    """The data cannot be loaded or analysed as asked (from :mod:`analysis`)."""


class SessionInUseError(HapticlabError):
    """Another process is writing this session (its lock is held)."""


class DataFolderError(HapticlabError, OSError):
    """A file or folder of the data cannot be written or read (disk, permissions, kind)."""

    def __str__(self) -> str:
        return str(self.strerror)


class DiskFullError(DataFolderError):
    """No space left on the device (or over quota)."""


class FileTooLargeError(DataFolderError):
    """A file would exceed the size the system allows."""


class ReadOnlyError(DataFolderError):
    """The file system is mounted read-only."""


class PermissionDeniedError(DataFolderError):
    """This user may not write (or read) there."""


class NotAFolderError(DataFolderError):
    """A path that must be a folder is a file or a device."""


_BY_ERRNO = {errno.ENOSPC: (DiskFullError, "no space left on the disk: free some space"),
             errno.EDQUOT: (DiskFullError, "disk quota exceeded: free some space"),
             errno.EFBIG: (FileTooLargeError, "file too large for this file system"),
             errno.EROFS: (ReadOnlyError, "read-only file system: use a writable --data "
                                          "folder"),
             errno.EACCES: (PermissionDeniedError, "permission denied: choose a folder you "
                                                   "may write, or ask for access"),
             errno.EPERM: (PermissionDeniedError, "operation not permitted"),
             errno.ENOTDIR: (NotAFolderError, "not a folder"),
             errno.EISDIR: (NotAFolderError, "a folder where a file is expected")}


def io_error(exc: OSError, what: str) -> DataFolderError:
    """The one-line error for ``exc`` (an OSError met while doing ``what``)."""
    cls, hint = _BY_ERRNO.get(exc.errno, (DataFolderError, exc.strerror or str(exc)))
    where = exc.filename or ""
    return cls(exc.errno, f"{what}: {where + ': ' if where else ''}{hint}")
