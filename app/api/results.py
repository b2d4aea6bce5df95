"""How a session and a simulated study ended: what the API's session functions return."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from analysis.session_format import SessionStatus

__all__ = ["SessionResult", "StudyResult"]


@dataclass(frozen=True)
class SessionResult:
    """How a session ended.

    Attributes
    ----------
    folder : Path
        The session folder.
    status : SessionStatus
        ``complete``, ``interrupted`` (the device failed or the operator aborted; resume it)
        or ``stopped`` (a signal or Ctrl-C; resume it). A ``str``: it compares and prints
        as its text.
    attempts : int
        Rows recorded in trials.tsv.
    message : str
        What happened, for people (how to resume).
    """

    folder: Path
    status: SessionStatus
    attempts: int
    message: str = ""

    @property
    def exit_code(self) -> int:
        """0 complete, 3 interrupted, 130 stopped (the CLI's exit status)."""
        return {SessionStatus.COMPLETE: 0, SessionStatus.INTERRUPTED: 3}.get(self.status, 130)


@dataclass(frozen=True)
class StudyResult:
    """A simulated study: its sessions (in order) and how long each stage took [s]."""

    sessions: list[SessionResult] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def complete(self) -> bool:
        return all(s.status == SessionStatus.COMPLETE for s in self.sessions)
