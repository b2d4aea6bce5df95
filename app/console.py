"""The operator's console: what to place, what happened, and the keys that act on the trial
in front of the operator.

:class:`PlainConsole` prints lines (headless runs, logs, CI) and takes no keys: trials
start at once. :class:`KeyConsole` reads single keys from the terminal and draws a live
view (phase, trial k of n, what to place, the last tap speeds, saturations, elapsed time and
time left). A key acts only in the state where it means something — otherwise it is
discarded with a line saying so (a key pressed during a trial never skips the next one):

======== ====================================================================
state    keys
======== ====================================================================
placing  r ready · s skip · u re-queue · p pause · q stop and save · n note · e E-STOP
trial    e E-STOP (everything else waits for the trial to end)
rating   e E-STOP (the participant is answering)
paused   p resume (then r to start the trial) · q stop and save · n note · e E-STOP
fault    c clear the fault and continue · q stop and save · n note · e E-STOP
reference r ready (the real block is in place) · n note · e E-STOP
======== ====================================================================

``e`` latches the device's e-stop at once, from the key reader's thread, in every state;
while a note is typed ``e`` is a letter and Ctrl-E is the e-stop (Ctrl-E works everywhere).
Keys are read as whole characters in the terminal's encoding (``ü`` is one key, never the
end of the reader); a key the reader cannot handle is reported and the reader goes on.
"""

from __future__ import annotations

import codecs
import datetime as dt
import locale
import os
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass, field

__all__ = ["PlainConsole", "KeyConsole", "make_console", "OperatorView", "KEYS", "ESTOP_CTRL"]

#: Ctrl-E: the e-stop in every state, also while a note is being typed
ESTOP_CTRL = "\x05"

#: state → {key: action}
KEYS: dict[str, dict[str, str]] = {
    "placing": {"r": "go", "s": "skip", "u": "requeue", "p": "pause", "q": "abort",
                "n": "note", "e": "estop"},
    "trial": {"e": "estop"},
    "rating": {"e": "estop"},
    "paused": {"p": "resume", "q": "abort", "n": "note", "e": "estop"},
    "fault": {"c": "clear", "q": "abort", "n": "note", "e": "estop"},
    "reference": {"r": "go", "n": "note", "e": "estop"},
    "idle": {"e": "estop"},
    "clearing": {"e": "estop"},  # the c is being acted on: nothing else queues
}
_NAMES = {"go": "ready", "skip": "skip", "requeue": "re-queue", "pause": "pause",
          "abort": "stop and save", "note": "note", "estop": "E-STOP", "resume": "resume",
          "clear": "clear the fault"}
_WHEN = {"s": "when the operator is placing the next item", "u": "when placing",
         "r": "when the item is in place", "p": "between trials", "q": "between trials (for "
         "a stop now press e)", "n": "between trials", "c": "after an e-stop"}


@dataclass
class OperatorView:
    """What the live view shows (the runner keeps it up to date)."""

    title: str = ""
    phase: str = ""
    trial: int = 0  # the attempt's trial_index (redraws and retries count)
    total: int = 0  # items in the plan
    done: int = 0  # items finished
    place: str = ""
    detail: str = ""
    block: str = ""
    taps: deque = field(default_factory=lambda: deque(maxlen=8))
    saturations: int = 0
    started: float = field(default_factory=time.monotonic)
    left_s: float | None = None
    state: str = "idle"
    messages: deque = field(default_factory=lambda: deque(maxlen=6))


class PlainConsole:
    """One line per event, to a stream (stderr by default); nobody at the keys.

    ``poll`` answers ``go`` when a trial is to start (or an action a program queued), so a
    headless session runs through without waiting.
    """

    interactive = False

    def __init__(self, stream=None, quiet: bool = False):
        self.stream = stream or sys.stderr
        self.quiet = quiet
        self.actions: deque[str] = deque()
        self._lock = threading.Lock()
        self.view = OperatorView()
        self.notes: list[dict] = []

    # ---------------------------------------------------------------- output
    def say(self, text: str) -> None:
        self.view.messages.append(text)
        if not self.quiet:
            with self._lock:
                print(text, file=self.stream, flush=True)

    def set_state(self, state: str) -> None:
        self.view.state = state

    def place(self, trial, total: int, done: int, what: str = "", detail: str = "") -> None:
        v = self.view
        v.phase, v.trial, v.total, v.done = trial.phase, trial.trial_index, total, done
        v.place, v.detail = what, detail
        v.taps.clear()  # the live view's taps are this attempt's
        self.say(f"[{done}/{total}] {trial.phase} #{trial.trial_index} (attempt {trial.attempt})"
                 f": place {what}" + (f" — {detail}" if detail else ""))

    def contact(self, velocity: float) -> None:
        self.view.taps.append(velocity)

    def saturated(self) -> None:
        self.view.saturations += 1
        self.say(f"  saturation (total {self.view.saturations}): redraw")

    def result(self, status: str, n_taps: int, detail: str = "") -> None:
        self.say(f"  {status}: {n_taps} taps{(' — ' + detail) if detail else ''}")

    # ---------------------------------------------------------------- keys
    def poll(self, timeout: float = 0.0) -> str | None:
        """An action for the current state, or None after ``timeout`` [s]."""
        if self.actions:
            return self.actions.popleft()
        return {"placing": "go", "reference": "go", "paused": "resume"}.get(self.view.state)

    def clear_fault(self, device) -> str | None:
        """Clear ``device``'s latched fault for the operator's c.

        Returns
        -------
        str or None
            None when cleared; otherwise why not, in words for the operator (a console
            with keys refuses when an e-stop came after the c).

        Raises
        ------
        device.DeviceFaultError
            The device keeps its fault (its own e-stop button is held).
        """
        device.clear_fault()
        return None

    def take_notes(self) -> list[dict]:
        """Notes typed since the last call."""
        with self._lock:  # the key reader appends under the same lock
            out, self.notes = self.notes, []
        return out

    def close(self) -> None:
        return None


class KeyConsole(PlainConsole):
    """The operator's terminal: reads single keys (cbreak mode) and draws a live view."""

    interactive = True

    def __init__(self, device, stream=None, live: bool = True):
        super().__init__(stream)
        import termios
        import tty

        self.device = device
        self._fd = sys.stdin.fileno()
        self._saved = termios.tcgetattr(self._fd)
        tty.setcbreak(self._fd)
        self._stop = threading.Event()
        self._cv = threading.Condition()
        self._note: list[str] | None = None  # characters of a note being typed
        self._estops = 0  # e-stop keys pressed so far
        self._counting = threading.Lock()  # the reader and a re-sent e-stop both count
        self._marks: deque[int] = deque()  # _estops when each queued action's key came
        self._polled_mark = 0  # ... and for the action poll() returned last
        self._esc = ""  # an escape sequence being skipped ("", ESC, "[" or "O")
        self._live = None
        if live:
            from rich.console import Console
            from rich.live import Live

            self._rich = Console(file=self.stream, force_terminal=True)
            self._live = Live(self._render(), console=self._rich, refresh_per_second=4,
                              transient=False, get_renderable=self._render)
            self._live.start()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        if self._live is None:  # the live view shows the keys of the moment instead
            self.say("operator keys: r ready · s skip · u re-queue · p pause · q stop and "
                     "save · n note · e E-STOP (Ctrl-E while typing a note)")

    # ---------------------------------------------------------------- the view
    def say(self, text: str) -> None:
        self.view.messages.append(text)
        if self._live is None:
            super().say(text)

    def _render(self):
        from rich.console import Group
        from rich.panel import Panel
        from rich.rule import Rule
        from rich.table import Table
        from rich.text import Text

        v = self.view
        # copies: the reader and the runner append while this (Rich's thread) draws
        taps, messages, note = list(v.taps), list(v.messages), self._note
        note = None if note is None else list(note)
        t = Table.grid(padding=(0, 2))
        t.add_column(style="bold", no_wrap=True)
        t.add_column()
        el = time.monotonic() - v.started
        left = "—" if v.left_s is None else f"≈ {v.left_s / 60:.0f} min"
        t.add_row("trial", f"{v.phase} · item {min(v.done + 1, v.total)} of {v.total} "
                           f"(trial #{v.trial}) · elapsed {int(el // 60):02d}:"
                           f"{int(el % 60):02d} · left {left}")
        t.add_row("PLACE", Text.assemble((f" {v.place or '—'} ", "reverse bold"),
                                         f"  {v.detail}"))
        if v.block:
            t.add_row("block", v.block)
        t.add_row("taps", "  ".join(f"{x:.3f}" for x in taps) + (" m/s" if taps else "—"))
        t.add_row("saturations", str(v.saturations))
        keys = " · ".join(f"{k} {_NAMES[a]}" for k, a in KEYS.get(v.state, {}).items())
        t.add_row("keys", Text.assemble((f"{v.state}:", "bold yellow" if v.state != "fault"
                                         else "bold red"), f" {keys}"))
        if note is not None:
            t.add_row("NOTE", "".join(note) + "▏  (ENTER saves · ESC cancels · "
                      "Ctrl-E E-STOP)")
        log = [Text(m, style="dim" if i < len(messages) - 1 else "") for i, m in
               enumerate(messages)]  # wrapped, never cut: the newest may be an instruction
        return Panel(Group(t, Rule(style="dim"), *log), title=v.title or "hapticlab",
                     border_style="red" if v.state == "fault" else "cyan")

    # ---------------------------------------------------------------- keys
    def _read(self) -> None:
        """Whole characters in the terminal's encoding, until close(); never dies on a key."""
        import select

        enc = getattr(sys.stdin, "encoding", None) or locale.getpreferredencoding(False)
        try:
            decoder = codecs.getincrementaldecoder(enc)(errors="replace")
        except LookupError:
            decoder = codecs.getincrementaldecoder("utf-8")(errors="replace")
        while not self._stop.is_set():
            try:
                r, _, _ = select.select([self._fd], [], [], 0.1)
                if not r:
                    continue
                data = os.read(self._fd, 64)
            except (OSError, ValueError) as exc:  # the terminal went away
                self.say(f"the operator's terminal is gone ({exc}): keys are no longer read; "
                         "the device's own e-stop button still acts")
                return
            if not data:
                self.say("the operator's terminal closed: keys are no longer read; the "
                         "device's own e-stop button still acts")
                return
            for ch in decoder.decode(data):  # a multibyte key may end in the next read
                if ch == "\ufffd":  # bytes that are no character in the terminal's encoding
                    self.say(f"a key that is not {enc} text was ignored (is the terminal's "
                             "encoding set?); the keys still act")
                    continue
                if self._escape(ch):
                    continue
                try:
                    self._key(ch)
                except Exception as exc:  # noqa: BLE001 — the reader must outlive any key
                    self.say(f"key {ch!r} failed ({type(exc).__name__}: {exc}); the keys "
                             "still act")

    def _escape(self, ch: str) -> bool:
        """Whether ``ch`` belongs to a terminal escape sequence (an arrow key is ESC [ C:
        its C must not clear a fault). ESC itself still reaches a note (it cancels it)."""
        if self._esc == "":
            if ch == "\x1b" and self._note is None:
                self._esc = "\x1b"
                return True
            return False
        if self._esc == "\x1b":
            self._esc = ch if ch in "[O" else ""
            return ch in "[O"  # ESC then another key: that key acts
        if "@" <= ch <= "~":  # the final byte of a CSI/SS3 sequence
            self._esc = ""
        return True

    def _estop(self) -> None:
        with self._counting:  # before the device is told: a clear on its way sees it
            self._estops += 1
        try:
            self.device.estop()
        except Exception as exc:  # noqa: BLE001 — said, never swallowed: the operator acts
            self.say(f"E-STOP NOT CONFIRMED ({type(exc).__name__}: {exc}): press the "
                     "device's own e-stop button or switch the amplifier off")
            return
        self.say("E-STOP latched: output is zero")

    def _key(self, ch: str) -> None:
        if ch == ESTOP_CTRL:  # in every state, also in the middle of a note
            self._estop()
            return
        if self._note is not None:  # typing a note: every key is text but ENTER and ESC
            if ch in "\r\n":
                text = "".join(self._note).strip()
                self._note = None
                if text:
                    with self._lock:
                        self.notes.append({"utc": dt.datetime.now(dt.UTC).isoformat(
                            timespec="seconds"), "trial_index": self.view.trial, "text": text})
                    self.say(f"note saved: {text}")
            elif ch == "\x1b":
                self._note = None
                self.say("note cancelled")
            elif ch in "\x7f\b":
                self._note = self._note[:-1]
            elif ch.isprintable():
                self._note.append(ch)
            return
        key = ch.lower()
        state = self.view.state
        if key == "e":  # at once, from this thread, whatever the state: never queued
            self._estop()
            return
        action = KEYS.get(state, {}).get(key)
        if action is None:
            if any(key in keys for keys in KEYS.values()):
                self.say(f"key '{key}' ignored: {state} — it acts {_WHEN.get(key, 'later')}")
            return
        if action == "note":
            self._note = []
            return
        with self._cv:
            if self.actions:  # one action per state: a second key is not carried over
                self.say(f"key '{key}' ignored: '{_NAMES[self.actions[0]]}' was pressed first")
                return
            self.actions.append(action)
            self._marks.append(self._estops)
            self._cv.notify_all()

    def set_state(self, state: str) -> None:
        with self._cv:
            self.view.state = state
            self.actions.clear()  # nothing pressed in another state acts in this one
            self._marks.clear()

    def poll(self, timeout: float = 0.0) -> str | None:
        with self._cv:
            if not self.actions and timeout > 0:
                self._cv.wait(timeout)
            if not self.actions:
                return None
            action = self.actions.popleft()
            self._polled_mark = self._marks.popleft()
            if action == "go":  # the trial starts now: a second r already belongs to it
                self.view.state = "trial"
            if action == "clear":  # keys pressed while it is acted on are said ignored
                self.view.state = "clearing"
            self.actions.clear()
            self._marks.clear()
            return action

    def clear_fault(self, device) -> str | None:
        """Clear ``device``'s fault for the c key, unless an e-stop was pressed after it: the
        later key wins. The e-stop never waits for this (the reader sends it at once), so
        one pressed while the clear is on its way is sent again once the clear is done."""
        pressed = self._polled_mark
        if self._estops != pressed:
            return "an E-STOP was pressed after c"
        device.clear_fault()
        if self._estops != pressed:
            self._estop()
            return "an E-STOP was pressed while it was being cleared, and is latched again"
        return None

    def close(self) -> None:
        import termios

        self._stop.set()
        self._reader.join(timeout=1.0)  # it wakes every 0.1 s; never read a closed terminal
        try:
            if self._live is not None:
                self._live.stop()  # its last frame stays on the terminal, summary included
            termios.tcsetattr(self._fd, termios.TCSADRAIN, self._saved)
        except (termios.error, OSError):  # the terminal is gone: nothing to draw or restore
            pass


def make_console(kind: str = "plain", quiet: bool = False, device=None,
                 live: bool = True) -> PlainConsole:
    """``keys`` when an operator sits at a terminal, ``plain`` otherwise."""
    if kind == "keys" and device is not None and sys.stdin.isatty():
        return KeyConsole(device, live=live)
    return PlainConsole(quiet=quiet)
