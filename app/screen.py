"""The participant's screen (PsychoPy) — the only module of hapticlab that imports PsychoPy.

Screens: phase instructions; "tap" (the 5-s window from first contact, with a thin
progress line as the only feedback); the rating (digit keys; on a 1–10 scale 0 means 10,
and the screen says so); the identification answer (surfaces chosen with keys 1–3, then
each named); debrief free text; pause. The realism protocol shows text only — nothing
may hint at the sample; the factorial and identification protocols draw the virtual
surface and the stylus as a cursor above it.

Keys that mean nothing on a screen are ignored; the key buffer is cleared before each
screen, so a double press counts once. ``keys`` can be injected (tests, scripted demos).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable

__all__ = ["PsychoPyScreen"]

_INSTRUCTIONS = {
    "familiarization": "Tap freely on the sample in front of you.\n\n"
                       "Take your time. Press SPACE when you are done.",
    "demonstration": "You will now tap on a series of samples, one at a time.\n\n"
                     "After each one, rate it. Press SPACE to begin.",
    "testing": "Now the same, with more samples.\n\nPress SPACE to begin.",
    "rating": "Tap each surface and rate how realistic it feels compared with the real "
              "block.\n\nPress SPACE to begin.",
    "identification": "One scene, three surfaces. Press 1, 2 or 3 to choose a surface and tap "
                      "it.\nWhen you know them, press N to name each one.\n\n"
                      "Press SPACE to begin.",
}
_MM_TO_PX = 8.0  # cursor scale: stylus height above the surface


class PsychoPyScreen:
    """Participant screen; also answers the runner's participant questions.

    Parameters
    ----------
    protocol : Protocol
    fullscreen : bool
    size : (int, int)
        Window size in pixels when not full screen.
    keys : callable, optional
        Returns newly pressed key names (default: PsychoPy's keyboard).
    """

    def __init__(self, protocol, fullscreen: bool = False, size: tuple[int, int] = (1024, 768),
                 keys: Callable[[], list[str]] | None = None, clock: Callable[[], float] = None):
        from psychopy import visual

        self.protocol = protocol
        self.win = visual.Window(size, fullscr=fullscreen, units="pix", color=(-0.6, -0.6, -0.6),
                                 allowGUI=not fullscreen, waitBlanking=False)
        self._text = visual.TextStim(self.win, text="", height=30, wrapWidth=size[0] * 0.8,
                                     color="white")
        self._small = visual.TextStim(self.win, text="", height=20, pos=(0, -size[1] * 0.38),
                                      color=(0.5, 0.5, 0.5), wrapWidth=size[0] * 0.9)
        self._bar = visual.Rect(self.win, width=0, height=4, pos=(0, -size[1] * 0.45),
                                fillColor=(0.2, 0.2, 0.2), lineColor=None)
        self._surface = visual.Rect(self.win, width=size[0] * 0.6, height=16,
                                    pos=(0, -size[1] * 0.2), fillColor=(0.55, 0.45, 0.35),
                                    lineColor=None)
        self._cursor = visual.Circle(self.win, radius=10, fillColor=(0.9, 0.9, 0.2),
                                     lineColor=None)
        self._keys = keys or self._psychopy_keys
        self._clock = clock or time.perf_counter
        self.cursor = bool(protocol.cursor)
        self._height: float | None = None
        self._shown_phase: str | None = None
        self.drawn_text: list[str] = []  # what the last frame said (tests read it)
        self._done = False
        self.debrief_text = ""

    # ------------------------------------------------------------------ drawing
    @staticmethod
    def _psychopy_keys() -> list[str]:
        from psychopy import event

        return event.getKeys()

    def _flush(self) -> None:
        self._keys()  # drop everything pressed so far: a double press counts once

    def _frame(self, text: str, small: str = "", cursor: bool = False, progress: float = 0.0,
               flip: bool = True) -> None:
        self.drawn_text = [t for t in (text, small) if t]
        if cursor and self.cursor:
            self._surface.draw()
            if self._height is not None:
                y = self._surface.pos[1] + 8 + 10 + max(0.0, self._height * 1000) * _MM_TO_PX
                self._cursor.pos = (0, y)
                self._cursor.draw()
        self._text.text = text
        self._text.pos = (0, 120 if cursor and self.cursor else 0)
        self._text.draw()
        if small:
            self._small.text = small
            self._small.draw()
        if progress > 0:
            self._bar.width = self.win.size[0] * 0.6 * min(1.0, progress)
            self._bar.draw()
        if flip:
            self.win.flip()

    def screenshot(self, path: str, **frame) -> None:
        """Draw a frame and save it as an image (the back buffer, before the flip)."""
        self._frame(flip=False, **frame)
        self.win.getMovieFrame(buffer="back")
        self.win.saveMovieFrames(str(path))
        self.win.flip()

    def _wait(self, valid: Iterable[str], draw: Callable[[], None]) -> tuple[str, float]:
        valid = set(valid)
        self._flush()
        t0 = self._clock()
        while True:
            draw()
            for k in self._keys():
                if k in valid:
                    return k, self._clock() - t0
            time.sleep(0.005)

    # ------------------------------------------------------------------ screens
    def instructions(self, phase: str) -> None:
        text = _INSTRUCTIONS.get(phase, f"{phase}\n\nPress SPACE to begin.")
        self._wait(["space"], lambda: self._frame(text))
        self._shown_phase = phase

    def ready(self, trial) -> None:
        if trial.phase != self._shown_phase:
            self.instructions(trial.phase)
        self._frame("Please wait", "the experimenter is preparing the next sample")

    def before_window(self, trial, sample_id, device, rng) -> None:
        self._height = None
        self._frame("Tap", cursor=True)

    def keep_tapping(self) -> bool:
        """Familiarization: another window, unless SPACE was pressed during the last one."""
        done, self._done = self._done, False
        return not done

    def progress(self, t: float, partial, duration: float) -> None:
        """During a window: the thin bar fills over the window; the cursor follows the stylus."""
        if self._shown_phase == "familiarization" and "space" in self._keys():
            self._done = True
        self._height = getattr(partial, "live_height", None)
        started = partial.t_first_contact is not None or bool(partial.contacts)
        self._frame("Tap", cursor=True, progress=(t / duration) if started else 0.0)

    def rate(self, trial, scale, result, rng) -> tuple[int, float]:
        values = list(scale.values)
        keymap = {str(v): v for v in values if v < 10}
        if 10 in values:
            keymap["0"] = 10
        hint = "  ".join(str(v) for v in values)
        anchors = "   ".join(f"{k} = {v}" for k, v in sorted(scale.anchors.items()))
        typing = "  (press 0 for 10)" if 10 in values else ""
        key, rt = self._wait(keymap, lambda: self._frame(
            f"{scale.question}\n\n{hint}", anchors + typing))
        self._frame(f"{scale.question}\n\n{hint}", f"your rating: {keymap[key]}")
        return keymap[key], rt

    def choose_surface(self, trial, visited: set[int]) -> int | None:
        """Identification: 1–3 chooses a surface to tap; N (once all were tapped) ends."""
        n = len(trial.samples)
        valid = [str(i + 1) for i in range(n)] + (["n"] if len(visited) == n else [])
        tapped = ", ".join(str(i + 1) for i in sorted(visited)) or "none yet"
        key, _ = self._wait(valid, lambda: self._frame(
            "Choose a surface: 1, 2 or 3", f"tapped: {tapped}"
            + ("   — press N to name them" if len(visited) == n else ""), cursor=True))
        return None if key == "n" else int(key) - 1

    def identify(self, trial, choices, results, rng) -> tuple[list[str], float]:
        keys = {c[0]: c for c in choices}
        names = "   ".join(f"{c[0].upper()} = {c}" for c in choices)
        answers, total = [], 0.0
        for i in range(len(trial.samples)):
            key, rt = self._wait(keys, lambda i=i: self._frame(f"Surface {i + 1} is …", names))
            answers.append(keys[key])
            total += rt
        return answers, total

    def pause(self) -> None:
        self._frame("Paused", "the experimenter will continue shortly")

    def debrief(self) -> str:
        """Free text: what made a sample feel real? Enter ends, Backspace deletes."""
        if self.debrief_text:
            return self.debrief_text
        text = ""
        self._flush()
        while True:
            self._frame("What made a sample feel real or not?\n\n" + (text or "…"),
                        "type, then press ENTER")
            for k in self._keys():
                if k == "return":
                    self.debrief_text = text
                    return text
                if k == "backspace":
                    text = text[:-1]
                elif k == "space":
                    text += " "
                elif len(k) == 1:
                    text += k
            time.sleep(0.005)

    def close(self) -> None:
        self.win.close()
