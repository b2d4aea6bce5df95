"""The operator console (terminal): what to place next, progress, saturations, contacts.

:class:`PlainConsole` prints lines (headless runs, logs, CI). :class:`RichConsole` draws a
live panel and reads single keys from the terminal: ``r`` ready, ``p`` pause/resume,
``e`` e-stop (latched), ``q`` abort and save, ``s`` skip, ``u`` re-queue.
"""

from __future__ import annotations

import os
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

    def wait_ready(self) -> str:
        """Nobody at the keys: go at once (or take an action queued by a program)."""
        a = self.next_action()
        return "go" if a in (None, "ready") else a

    def wait_resume(self) -> str:
        return "go"

    def close(self) -> None:
        return None


class KeyConsole(PlainConsole):
    """The operator's terminal: prints like :class:`PlainConsole` and reads single keys.

    Before each trial it waits for ``r`` (ready: the item is in place); at any time ``p``
    pauses/resumes, ``e`` latches the e-stop on the device at once, ``q`` aborts and saves,
    ``s`` skips and ``u`` re-queues the next item.
    """

    KEYS = {"p": "pause", "e": "estop", "q": "abort", "s": "skip", "u": "requeue", "r": "ready"}

    def __init__(self, device, stream=None):
        super().__init__(stream)
        import termios
        import tty

        self.device = device
        self._fd = sys.stdin.fileno()
        self._saved = termios.tcgetattr(self._fd)
        tty.setcbreak(self._fd)
        self._stop = threading.Event()
        self._cv = threading.Condition()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self.say("operator keys: r ready · p pause · e E-STOP · q abort & save · s skip · "
                 "u re-queue")

    def _read(self) -> None:
        import select

        while not self._stop.is_set():
            try:
                r, _, _ = select.select([self._fd], [], [], 0.1)
                if not r:
                    continue
                ch = os.read(self._fd, 1).decode("utf-8", "ignore").lower()  # not the buffer
            except (OSError, ValueError):  # the terminal went away: nobody is at the keys
                return
            action = self.KEYS.get(ch)
            if action == "estop":  # at once, from this thread: never queued behind a trial
                try:
                    self.device.estop()
                finally:
                    self.say("E-STOP latched: output is zero")
                continue
            if action:
                with self._cv:
                    self.actions.append(action)
                    self._cv.notify_all()

    def _next(self) -> str:
        with self._cv:
            self._cv.wait_for(lambda: bool(self.actions))
            return self.actions.popleft()

    def wait_ready(self) -> str:
        """Block until the operator is ready (``go``) or chose another action."""
        self.say("  place the item, then press r")
        a = self._next()
        return "go" if a == "ready" else a

    def wait_resume(self) -> str:
        while True:
            a = self._next()
            if a == "pause":
                return "go"
            if a == "abort":
                return a

    def contact(self, velocity: float) -> None:
        self.say(f"    tap {velocity:.3f} m/s")

    def close(self) -> None:
        import termios

        self._stop.set()
        self._reader.join(timeout=1.0)  # it wakes every 0.1 s; never read a closed terminal
        termios.tcsetattr(self._fd, termios.TCSADRAIN, self._saved)


def make_console(kind: str = "plain", quiet: bool = False, device=None) -> PlainConsole:
    """``keys`` when an operator sits at a terminal, ``plain`` otherwise."""
    if kind == "keys" and device is not None and sys.stdin.isatty():
        return KeyConsole(device)
    return PlainConsole(quiet=quiet)
