"""What became of an attempt: :class:`TrialStatus`, the values of trials.tsv's ``status``.

Each member is a ``str`` whose value is the text a session file holds (``valid``,
``excluded_saturated``, …), so it compares and prints as that text and the files keep their
spelling. analysis/session_format.py keeps the same values as the file format's list
(:mod:`analysis` imports nothing of ours); a test holds the two equal.
"""

from __future__ import annotations

from enum import StrEnum

__all__ = ["TrialStatus", "STATUSES", "FINAL_STATUSES", "CONTROL_STATUSES", "CAPPED"]


class TrialStatus(StrEnum):
    """The status of a row of trials.tsv: an attempt's outcome or a control entry."""

    #: answered and kept
    VALID = "valid"
    #: the drive saturated: the item is drawn again later
    SATURATED = "saturated"
    #: saturated at its cap: the item is left out
    EXCLUDED_SATURATED = "excluded_saturated"
    #: the operator re-queued it: drawn again later
    REQUEUED = "requeued"
    #: no contact within the window's timeout: drawn again later
    TIMED_OUT = "timed_out"
    #: timed out at its cap: left out
    EXCLUDED_TIMEOUT = "excluded_timeout"
    #: the device failed during it: the item is tried again next
    ABORTED_DEVICE = "aborted_device"
    #: the device failed at its cap: left out
    EXCLUDED_DEVICE = "excluded_device"
    #: the operator skipped it: left out
    SKIPPED = "skipped"
    #: an emergency stop ended it: tried again next
    ESTOP = "estop"
    #: control entries: the session paused, resumed, a real reference block tapped
    PAUSED = "paused"
    RESUMED = "resumed"
    REFERENCE = "reference"

    @property
    def final(self) -> bool:
        """Whether the item is finished with this attempt (kept or left out)."""
        return self in FINAL_STATUSES

    @property
    def control(self) -> bool:
        """Whether this is a control entry of the log, not an attempt of a planned item."""
        return self in CONTROL_STATUSES


T = TrialStatus
#: an attempt's outcomes, in the order the file format lists them
STATUSES = (T.VALID, T.SATURATED, T.EXCLUDED_SATURATED, T.REQUEUED, T.TIMED_OUT,
            T.EXCLUDED_TIMEOUT, T.ABORTED_DEVICE, T.EXCLUDED_DEVICE, T.SKIPPED, T.ESTOP)
#: the outcomes that finish an item
FINAL_STATUSES = (T.VALID, T.EXCLUDED_SATURATED, T.EXCLUDED_TIMEOUT, T.EXCLUDED_DEVICE,
                  T.SKIPPED)
#: the log's control entries
CONTROL_STATUSES = (T.PAUSED, T.RESUMED, T.REFERENCE)
#: a counted failure → the status it becomes at the protocol's cap
CAPPED = {T.SATURATED: T.EXCLUDED_SATURATED, T.TIMED_OUT: T.EXCLUDED_TIMEOUT,
          T.ABORTED_DEVICE: T.EXCLUDED_DEVICE}
del T
