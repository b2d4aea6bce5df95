"""The application's errors: every one is a :class:`~device.errors.HapticlabError`, which the
command line prints on one line (exit 2).

:mod:`analysis` keeps its own ``ValueError`` subclasses (it imports nothing of ours, in the
manner of pingouin); the application's API wraps them here.
"""

from __future__ import annotations

from device.errors import HapticlabError

__all__ = ["HapticlabError", "SessionFileError", "MissingLibraryError", "AnalysisError",
           "UsageError"]


class UsageError(HapticlabError, ValueError):
    """An argument that cannot be used (named, with what is allowed)."""


class SessionFileError(HapticlabError, ValueError):
    """A session folder's files cannot be used (named by file and line)."""


class MissingLibraryError(HapticlabError):
    """A matched sample has no transient library built on the device in use; the message
    gives the command that builds it."""


class AnalysisError(HapticlabError, ValueError):
    """The data cannot be loaded or analysed as asked (from :mod:`analysis`)."""
