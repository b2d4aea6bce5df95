"""Participant identifiers: safe as folder names on every operating system."""

from __future__ import annotations

import re

from device.errors import HapticlabError

__all__ = ["validate_participant", "ParticipantIdError"]

_OK = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]{0,31}$")
_RESERVED = {"CON", "PRN", "AUX", "NUL", *(f"COM{i}" for i in range(1, 10)),
             *(f"LPT{i}" for i in range(1, 10))}
#: what pandas (``read_csv``'s default NA values), R, JASP and SPSS read as missing or as a
#: truth value rather than as an id (compared in lower case)
_MISSING = {"nan", "na", "n-a", "null", "none", "nil", "inf", "infinity", "nat", "true",
            "false", "t", "f"}


class ParticipantIdError(HapticlabError, ValueError):
    """A participant id that cannot safely name a folder."""


def validate_participant(pid: str, new: bool = True) -> str:
    """Return ``pid`` if it is 1–32 letters, digits, '_' or '-', starting with a letter or digit.

    Refused, each with a message that says why: empty ids, path separators, '..',
    control characters, other punctuation or spaces, names reserved by Windows (CON,
    NUL, COM1 …), ids longer than 32 characters, and words that data readers take for a
    missing or truth value (``nan``, ``NA``, ``null``, ``none``, ``true`` …). Ids that look
    like numbers (``001``, ``1e5``) are kept as text: every export quotes them and its
    codebook says they are text. ``new=False`` (an existing session, resumed) skips the
    missing-value rule: a session recorded before it still resumes.
    """
    if not isinstance(pid, str) or not pid:
        raise ParticipantIdError("participant id is empty")
    if any(ord(c) < 32 or ord(c) == 127 for c in pid):
        raise ParticipantIdError(f"participant id {pid!r} contains control characters")
    if "/" in pid or "\\" in pid:
        raise ParticipantIdError(f"participant id {pid!r} contains a path separator")
    if ".." in pid:
        raise ParticipantIdError(f"participant id {pid!r} contains '..'")
    if pid.split(".")[0].upper() in _RESERVED:
        raise ParticipantIdError(f"participant id {pid!r} is a reserved device name")
    if len(pid) > 32:
        raise ParticipantIdError(f"participant id {pid!r} is longer than 32 characters")
    if new and pid.lower() in _MISSING:
        raise ParticipantIdError(f"participant id {pid!r} reads as a missing value or a truth "
                                 "value in pandas, R, JASP and SPSS: choose another (e.g. P01)")
    if not _OK.match(pid):
        raise ParticipantIdError(f"participant id {pid!r}: use letters, digits, '_' and '-' "
                                 "only, starting with a letter or digit (e.g. P01)")
    return pid
