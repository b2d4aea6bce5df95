"""The participant's screen (PsychoPy) — the only module of hapticlab that imports PsychoPy.

Screens: phase instructions; "please wait" between trials (from the end of a rating until
the operator's ``r``; it offers R for the real block again when the phase has reference
blocks); "tap" (the window from first contact, with a thin progress line); the rating (one
number key, digits and ENTER, or a slider, as the protocol's scale says); surfaces chosen
with number keys and named with the number shown beside each name (identification); the
real block to tap; "paused" (the operator's pause or an e-stop); debrief free text; thanks.

Every text comes from the protocol (``[texts]``, defaults in English: see
:mod:`protocols.texts`); every size and position is a fraction of the window, so the layout
is the same at 1024×768 and 1920×1080. The realism protocol shows text only; protocols with
``[display] cursor`` draw the surface and the stylus as a cursor from the device's reported
height. Keys that mean nothing on a screen are ignored; the key buffer is cleared before
each screen, so a double press counts once. ``keys`` can be injected (tests, scripted
demos): a callable returning newly pressed keys, each a name or a (name, modifiers) pair.

The screen log: with ``HAPTICLAB_SCREEN_LOG`` naming a file, every screen the participant
sees is appended to it as one line when it is first shown (the time on the perf-counter
clock [s], a tab, its texts joined by `` | ``), and again whenever its text changes. A
screen that clears the key buffer is logged on its first frame after the clearing, so a
key pressed once its line is there counts: a program driving the screen (the test-day
tests) waits for the line instead of sleeping, and a lab can see afterwards what was shown
and when.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Iterable

from protocols.kinds import RATED, REFERENCE, phase_kind
from protocols.model import choice_keys

from .participants import Responder

__all__ = ["PsychoPyScreen", "info_dialog"]

#: pyglet's key names (as PsychoPy reports them, lower case) → the character: a layout
#: that has ! or ( on its own key, or a shifted key reported by its symbol, types it
_PUNCT = {name: chr(code) for name, code in (
    ("exclamation", 0x21), ("doublequote", 0x22), ("hash", 0x23), ("pound", 0x23),
    ("dollar", 0x24), ("percent", 0x25), ("ampersand", 0x26), ("apostrophe", 0x27),
    ("parenleft", 0x28), ("parenright", 0x29), ("asterisk", 0x2A), ("plus", 0x2B),
    ("comma", 0x2C), ("minus", 0x2D), ("period", 0x2E), ("slash", 0x2F), ("colon", 0x3A),
    ("semicolon", 0x3B), ("less", 0x3C), ("equal", 0x3D), ("greater", 0x3E),
    ("question", 0x3F), ("at", 0x40), ("bracketleft", 0x5B), ("backslash", 0x5C),
    ("bracketright", 0x5D), ("asciicircum", 0x5E), ("underscore", 0x5F), ("grave", 0x60),
    ("quoteleft", 0x60), ("braceleft", 0x7B), ("bar", 0x7C), ("braceright", 0x7D),
    ("asciitilde", 0x7E))}
#: a US layout's shifted digits and punctuation where the key is reported unshifted (pyglet
#: on Windows and macOS); on X11 the key is reported as the character Shift made, so this is
#: not applied there (a French layout's Shift+4 is 4, not $)
_US_SHIFTED = {"1": "!", "2": "@", "3": "#", "4": "$", "5": "%", "6": "^", "7": "&", "8": "*",
               "9": "(", "0": ")", "slash": "?", "apostrophe": '"', "semicolon": ":",
               "minus": "_", "equal": "+", "comma": "<", "period": ">", "bracketleft": "{",
               "bracketright": "}", "backslash": "|", "grave": "~", "quoteleft": "~"}
_SHIFTED = {} if sys.platform.startswith("linux") else _US_SHIFTED
_NUM = {f"num_{d}": str(d) for d in range(10)}


def _fmt(text: str, **kw) -> str:
    """A protocol text with its placeholders filled (unknown ones left as written)."""
    class Keep(dict):
        def __missing__(self, key):
            return "{" + key + "}"

    return text.format_map(Keep(**kw))


class PsychoPyScreen(Responder):
    """A person at the PsychoPy window; also answers the runner's participant questions.

    Parameters
    ----------
    protocol : Protocol
    fullscreen : bool
    size : (int, int)
        Window size in pixels when not full screen.
    keys : callable, optional
        Returns newly pressed keys (default: PsychoPy's keyboard, with modifiers).
    """

    name = "person"

    def __init__(self, protocol, fullscreen: bool = False, size: tuple[int, int] = (1024, 768),
                 keys: Callable[[], list] | None = None, clock: Callable[[], float] = None):
        from psychopy import logging, visual

        # PsychoPy's own messages ("monitor specification not found", …) would scroll
        # through the operator's live view; only its errors reach the terminal
        logging.console.setLevel(logging.ERROR)
        self.protocol = protocol
        self.texts = dict(protocol.texts) if protocol.texts else _default_texts()
        self.win = visual.Window(size, fullscr=fullscreen, units="pix", color=(-0.6, -0.6, -0.6),
                                 allowGUI=not fullscreen, waitBlanking=False)
        w, h = self.win.size
        self.W, self.H = float(w), float(h)
        self._text = visual.TextStim(self.win, text="", height=0.042 * h, wrapWidth=0.8 * w,
                                     color="white")
        self._small = visual.TextStim(self.win, text="", height=0.028 * h, pos=(0, -0.38 * h),
                                      color=(0.5, 0.5, 0.5), wrapWidth=0.9 * w)
        self._bar = visual.Rect(self.win, width=0, height=max(2.0, 0.005 * h),
                                pos=(0, -0.45 * h), fillColor=(0.2, 0.2, 0.2), lineColor=None)
        self._surface = visual.Rect(self.win, width=0.6 * w, height=0.02 * h,
                                    pos=(0, -0.2 * h), fillColor=(0.55, 0.45, 0.35),
                                    lineColor=None)
        self._cursor = visual.Circle(self.win, radius=0.013 * h, fillColor=(0.9, 0.9, 0.2),
                                     lineColor=None)
        self._slider = None
        self._scale_stims = None  # the scale's points and its end anchors, made when needed
        self._keys = keys or self._psychopy_keys
        self._clock = clock or time.perf_counter
        self.cursor = bool(protocol.cursor)
        self._height: float | None = None
        self._shown_phase: str | None = None
        self._waiting: tuple | None = None  # what the "please wait" screen shows, while shown
        self.drawn_text: list[str] = []  # what the last frame said (tests read it)
        self._done = False
        # identification: the surface being tapped, those tapped before it, and where the
        # participant went during its window (a surface's index, or None: to answer)
        self._surface_now: int | None = None
        self._n_surfaces = 0
        self._visited: set[int] = set()
        self._moving = False
        self._moved_to: int | None = None
        self._notice = ""  # said once on the next 'please wait' (a saturated trial)
        self._tapping = ""  # the title while tapping ('Tap', 'Tap · Surface 2')
        self._detail = ""  # and the line below it
        self.debrief_text = ""
        log = os.environ.get("HAPTICLAB_SCREEN_LOG")
        self._log = open(log, "a", encoding="utf-8", buffering=1) if log else None  # noqa: SIM115
        self._logged: tuple[str, ...] | None = None  # the texts of the last screen logged

    # ------------------------------------------------------------------ drawing
    @staticmethod
    def _psychopy_keys() -> list:
        from psychopy import event

        return event.getKeys(modifiers=True)

    def _names(self) -> list[str]:
        return [k[0] if isinstance(k, tuple) else k for k in self._keys()]

    def _flush(self) -> None:
        self._keys()  # drop everything pressed so far: a double press counts once
        self._logged = None  # the next frame is logged: keys count from there

    def _log_frame(self) -> None:
        """The screen log's line for this frame, when its texts differ from the last one's
        (or keys were cleared since)."""
        shown = tuple(self.drawn_text)
        if self._log is not None and shown != self._logged:
            self._logged = shown
            flat = " | ".join(t.replace("\n", " / ") for t in shown)
            self._log.write(f"{self._clock():.3f}\t{flat}\n")

    def _frame(self, text: str, small: str = "", cursor: bool = False, progress: float = 0.0,
               flip: bool = True, slider: bool = False,
               scale: tuple[str, str, str] | None = None) -> None:
        """One frame: ``text`` (centred), ``small`` (grey, at the bottom); ``scale`` = (the
        scale's points, the low anchor, the high anchor) draws the points under ``text``
        with each anchor under its end."""
        self.drawn_text = [t for t in (text, small, *(scale or ())) if t]
        if scale is not None:
            self._draw_scale(*scale)
        if cursor and self.cursor:
            self._surface.draw()
            if self._height is not None:
                top = self._surface.pos[1] + self._surface.height / 2 + self._cursor.radius
                # 1 mm of stylus height is 1 % of the window's height
                self._cursor.pos = (0, top + max(0.0, self._height * 1000) * 0.01 * self.H)
                self._cursor.draw()
        self._text.text = text
        self._text.pos = (0, 0.16 * self.H if (cursor and self.cursor) or slider or scale
                          else 0)
        self._text.draw()
        if slider and self._slider is not None:
            self._slider.draw()
        if small:
            self._small.text = small
            self._small.draw()
        if progress > 0:
            self._bar.width = self.W * 0.6 * min(1.0, progress)
            self._bar.draw()
        if flip:
            self.win.flip()
            self._log_frame()

    def _draw_scale(self, points: str, low: str, high: str) -> None:
        from psychopy import visual

        if self._scale_stims is None:
            h = self.H
            self._scale_stims = (
                visual.TextStim(self.win, text="", height=0.042 * h, pos=(0, 0), color="white",
                                wrapWidth=0.96 * self.W),  # one line, up to 11 points
                *(visual.TextStim(self.win, text="", height=0.026 * h, color=(0.5, 0.5, 0.5),
                                  wrapWidth=0.24 * self.W) for _ in range(2)))
        line, lo, hi = self._scale_stims
        line.text = points
        line.draw()
        half = line.boundingBox[0] / 2
        for stim, word, x in ((lo, low, -half), (hi, high, half)):
            if word:  # centred under its end point, wrapped to a quarter of the window
                stim.text = word
                stim.pos = (x, -0.07 * self.H - stim.boundingBox[1] / 2)
                stim.draw()

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
            for k in self._names():
                if k in valid:
                    return k, self._clock() - t0
            time.sleep(0.005)

    def t(self, key: str, **kw) -> str:
        return _fmt(self.texts[key], **kw)

    # ------------------------------------------------------------------ screens
    def instructions(self, phase: str) -> None:
        ph = next((p for p in self.protocol.phases if p.name == phase), None)
        kind = phase_kind(ph.kind) if ph is not None else RATED
        default = kind.instructions
        if ph is not None and ph.adaptive is not None and ph.adaptive.presentation == "surfaces":
            default = self.t("discriminate_surfaces")  # two surfaces, not two intervals
        text = self.texts.get("instructions", {}).get(phase) or default
        n = len(ph.samples) if ph is not None else 3
        text = _fmt(text, n=n, keys=", ".join(str(i + 1) for i in range(n)))
        self._wait(["space"], lambda: self._frame(text))
        self._shown_phase = phase

    def waiting(self, trial) -> None:
        """From the end of a trial until the operator starts the next: please wait (and R for
        the real block again, when the phase has reference blocks)."""
        if trial.kind == REFERENCE:  # the real block is on its way (due, or asked for)
            self._waiting = (self.t("wait"), self.t("reference_requested"), False)
        else:
            ph = next((p for p in self.protocol.phases if p.name == trial.phase), None)
            offer = (ph is not None and ph.references != "none"
                     and phase_kind(trial.kind).references)
            notice, self._notice = self._notice, ""  # said once, on this wait
            self._waiting = (self.t("wait"), (notice + "\n" if notice else "")
                             + self.t("wait_detail") + (
                "\n" + self.t("reference_offer") if offer else ""), offer)
        self._flush()
        self._frame(*self._waiting[:2])

    def poll(self) -> str | None:
        """Between trials: keep the window alive; ``"reference"`` when R was pressed."""
        if self._waiting is None:
            return None
        keys = self._names()
        self._frame(*self._waiting[:2])
        if self._waiting[2] and "r" in keys:
            self._waiting = (self.t("wait"), self.t("reference_requested"), False)
            self._frame(*self._waiting[:2])
            return "reference"
        return None

    def saturated(self, trial, comes_back: bool = True) -> None:
        """Said on the next 'please wait' screen: the participant sees why the sample will
        come back (or, at the protocol's cap, will not), with or without the tone."""
        self._notice = self.t("saturated" if comes_back else "saturated_last")

    def choose_reference(self, trial, blocks: list[tuple[str, str]]) -> str | None:
        """Several real blocks (identification): the participant picks one with its number
        key, or ESC for none; the order is the protocol's, never the scene's."""
        if len(blocks) < 2:
            return blocks[0][0] if blocks else None
        names = "   ".join(f"{i + 1} = {label}" for i, (_, label) in enumerate(blocks))
        valid = [str(i + 1) for i in range(len(blocks))] + [
            f"num_{i + 1}" for i in range(len(blocks))] + ["escape"]
        key, _ = self._wait(valid, lambda: self._frame(
            self.t("reference_which"), self.t("reference_which_keys", names=names)))
        if key == "escape":  # the runner shows 'please wait' (and the offer) again
            return None
        self._waiting = (self.t("wait"), self.t("reference_requested"), False)
        self._frame(*self._waiting[:2])
        return blocks[int(key.removeprefix("num_")) - 1][0]

    def ready(self, trial) -> None:
        self._waiting = None
        if trial.phase != self._shown_phase:
            self.instructions(trial.phase)

    def reference(self, trial, sample) -> None:
        """The real block to tap (shown while the operator places it and during the taps);
        a phase that begins with its real blocks shows its instructions first."""
        if trial.phase != self._shown_phase:
            self.instructions(trial.phase)
        self._waiting = None
        self._height = None
        self._frame(self.t("reference"), self.t("reference_detail",
                                                 block=sample.placement or sample.id),
                    cursor=True)

    def _tap_title(self, trial, sample_id) -> str:
        """'Tap', and in identification which surface ('Surface 2') — never its name; 'Tap
        the real block' for as long as a real block is tapped."""
        if trial.kind == REFERENCE:
            return self.t("reference")
        kind = phase_kind(trial.kind)
        if _surfaces(trial) and sample_id in trial.samples:
            return f"{self.t('tap')} · {self.t('surface', i=trial.samples.index(sample_id) + 1)}"
        if kind.items in ("pairs", "adaptive") and sample_id in trial.samples:
            return f"{self.t('tap')} · {self.t('pair', i=trial.samples.index(sample_id) + 1)}"
        return self.t("tap")

    def before_window(self, trial, sample_id, device, rng) -> None:
        self._height = None
        self._tapping = self._tap_title(trial, sample_id)
        self._surface_now, self._moving = None, False
        self._detail = (self.t("reference_detail", block=trial.placement or sample_id)
                        if trial.kind == REFERENCE else
                        self.t("done_hint") if phase_kind(trial.kind).windows == "until_done"
                        else "")
        if trial.kind != REFERENCE and _surfaces(trial) \
                and sample_id in trial.samples:
            self._surface_now = now = trial.samples.index(sample_id)
            n = len(trial.samples)
            others = ", ".join(str(i + 1) for i in range(n) if i != now)
            self._detail = self.t("switch_hint", keys=others) + (
                f"   — {self._answer_hint(trial)}" if self._visited | {now} >= set(range(n))
                else "")
        self._frame(self._tapping, self._detail, cursor=True)

    def keep_tapping(self) -> bool:
        """Familiarization: another window, unless ENTER was pressed during the last one."""
        done, self._done = self._done, False
        return not done

    def progress(self, t: float, partial, duration: float) -> None:
        """During a window: the thin bar fills over the window; the cursor follows the stylus."""
        keys = self._names()
        free = self._shown_phase is not None and any(
            p.name == self._shown_phase and phase_kind(p.kind).windows == "until_done"
            for p in self.protocol.phases)
        if free and "return" in keys:
            self._done = True
        if self._surface_now is not None and not self._moving:
            self._move_on(keys)
        self._height = partial.live_height
        started = partial.t_first_contact is not None or bool(partial.contacts)
        self._frame(self._tapping or self.t("tap"), self._detail, cursor=True,
                    progress=(t / duration) if started else 0.0)

    # ------------------------------------------------------------------ answers
    def rate(self, trial, scale, result, rng) -> tuple[int, float]:
        mode = scale.entry_mode
        anchors = "   ".join(f"{k} = {v}" for k, v in sorted(scale.anchors.items()))
        if mode == "keys":
            return self._rate_keys(scale)
        if mode == "slider":
            return self._rate_slider(scale, anchors)
        return self._rate_typed(scale, anchors)

    def _rate_keys(self, scale) -> tuple[int, float]:
        """A number key chooses (shown in brackets), another changes it, BACKSPACE clears,
        ENTER confirms; the response time runs to the confirming ENTER (PsychoPy's rating
        scale counts to its accept the same way)."""
        keymap = scale.key_map()
        inner = self._inner_anchors(scale)
        chosen: int | None = None
        self._flush()
        t0 = self._clock()
        while True:
            drawn = self._scale_line(scale, chosen)
            hint = (self.t("rating_chosen", value=chosen) if chosen is not None
                    else self.t("rating_keys"))
            self._frame(scale.question, f"{inner}\n{hint}" if inner else hint, scale=drawn)
            for k in self._names():
                if k in keymap:
                    chosen = keymap[k]
                elif k == "backspace":
                    chosen = None
                elif k in ("return", "num_enter") and chosen is not None:
                    rt = self._clock() - t0
                    self._frame(scale.question, self.t("rating_confirmed", value=chosen),
                                scale=self._scale_line(scale, chosen))
                    return chosen, rt
            time.sleep(0.005)

    def _scale_line(self, scale, chosen: int | None) -> tuple[str, str, str]:
        """The scale's points (``chosen`` in brackets) and the anchors of its two ends."""
        gap = "     " if len(scale.values) <= 7 else "  "
        line = gap.join(f"[{v}]" if v == chosen else f" {v} " for v in scale.values)
        return line, scale.anchors.get(scale.min, ""), scale.anchors.get(scale.max, "")

    def _inner_anchors(self, scale) -> str:
        """Anchors of points between the ends (the ends' own are drawn under them)."""
        return "   ".join(f"{k} = {v}" for k, v in sorted(scale.anchors.items())
                          if k not in (scale.min, scale.max))

    def _rate_typed(self, scale, anchors: str) -> tuple[int, float]:
        """Digits typed, ENTER confirms; BACKSPACE deletes; a number off the scale is said so.
        The scale's points are drawn (up to 11 of them) with its end anchors under its ends,
        the number typed so far marked on it."""
        typed, note = "", ""
        inner = self._inner_anchors(scale)
        drawn = len(scale.values) <= 11
        self._flush()
        t0 = self._clock()
        while True:
            shown = typed or "_"
            hint = note or self.t("rating_typed", min=scale.min, max=scale.max)
            value = int(typed) if typed not in ("", "-") else None
            if drawn:
                self._frame(f"{scale.question}\n\n{shown}",
                            f"{inner}\n{hint}" if inner else hint,
                            scale=self._scale_line(scale, value))
            else:
                self._frame(f"{scale.question}\n\n{shown}", f"{anchors}\n{hint}")
            for k in self._names():
                k = _NUM.get(k, k)
                if k.isdigit() and len(k) == 1 and len(typed) < 6:
                    typed, note = typed + k, ""
                elif k == "minus" and not typed and scale.min < 0:
                    typed = "-"
                elif k == "backspace":
                    typed = typed[:-1]
                elif k in ("return", "num_enter") and typed not in ("", "-"):
                    value = int(typed)
                    if scale.min <= value <= scale.max:
                        rt = self._clock() - t0
                        self._frame(f"{scale.question}\n\n{value}",
                                    self.t("rating_confirmed", value=value),
                                    scale=self._scale_line(scale, value) if drawn else None)
                        return value, rt
                    note = self.t("rating_invalid", value=value, min=scale.min, max=scale.max)
                    typed = ""
            time.sleep(0.005)

    def _rate_slider(self, scale, anchors: str) -> tuple[int, float]:
        """A PsychoPy Slider over the scale's points: arrow keys or the mouse, ENTER."""
        from psychopy import visual

        values = list(scale.values)
        labels = [scale.anchors.get(v, str(v)) if v in (values[0], values[-1]) else str(v)
                  for v in values]
        self._slider = visual.Slider(self.win, ticks=values, labels=labels, granularity=1,
                                     size=(0.7 * self.W, 0.03 * self.H), pos=(0, -0.05 * self.H),
                                     labelHeight=0.025 * self.H, style="rating")
        value: int | None = None
        self._flush()
        t0 = self._clock()
        try:
            while True:
                self._frame(scale.question, self.t("rating_slider"), slider=True)
                got = self._slider.getRating()
                if got is not None:
                    value = int(round(got))
                for k in self._names():
                    if k in ("left", "right"):
                        start = value if value is not None else (values[0] + values[-1]) // 2
                        value = min(values[-1], max(values[0], start + (1 if k == "right"
                                                                        else -1)))
                        self._slider.markerPos = value
                    elif k in ("return", "num_enter") and value is not None:
                        rt = self._clock() - t0
                        self._frame(scale.question, self.t("rating_confirmed", value=value),
                                    slider=True)
                        return value, rt
                time.sleep(0.005)
        finally:
            self._slider = None

    def _move_on(self, keys: list[str]) -> None:
        """During an identification window: another surface's number key, or N once every
        surface has been tapped, ends the window and goes there (the surface being tapped
        and other keys do nothing)."""
        n = self._n_surfaces
        for k in keys:
            k = k.removeprefix("num_")
            if k.isdigit() and 1 <= int(k) <= n and int(k) - 1 != self._surface_now:
                self._moving, self._moved_to = True, int(k) - 1
                return
            if k == "n" and self._visited | {self._surface_now} >= set(range(n)):
                self._moving, self._moved_to = True, None
                return

    def _answer_hint(self, trial) -> str:
        """What N does once every surface was tapped: name them (identification), or answer
        (an adaptive phase's two surfaces)."""
        adaptive = getattr(trial, "stimulus", None) is not None
        return self.t("answer_hint" if adaptive else "name_hint")

    def moving_on(self) -> bool:
        return self._moving

    def choose_surface(self, trial, visited: set[int]) -> int | None:
        """Identification: number keys choose a surface to tap; N (once all were tapped).
        A choice made during the last window is taken at once."""
        self._visited, self._surface_now = set(visited), None
        self._n_surfaces = n = len(trial.samples)
        if self._moving:
            self._moving = False
            return self._moved_to
        keys = ", ".join(str(i + 1) for i in range(n))
        valid = [str(i + 1) for i in range(n)] + [f"num_{i + 1}" for i in range(n)] + (
            ["n"] if len(visited) == n else [])
        tapped = ", ".join(str(i + 1) for i in sorted(visited)) or "—"
        key, _ = self._wait(valid, lambda: self._frame(
            self.t("choose", keys=keys), self.t("tapped", list=tapped)
            + (f"   — {self._answer_hint(trial)}" if len(visited) == n else ""), cursor=True))
        return None if key == "n" else int(key.removeprefix("num_")) - 1

    def choose(self, trial, results, rng) -> tuple[int, float]:
        """Which of the two felt more real: 1 or 2 (number row or keypad), one key press."""
        keys = {"1": 0, "num_1": 0, "2": 1, "num_2": 1}
        key, rt = self._wait(keys, lambda: self._frame(self.t("choice"),
                                                       self.t("choice_keys")))
        return keys[key], rt

    def discriminate(self, trial, question: str, rng) -> tuple[int, float]:
        """An adaptive phase's forced choice: the phase's question (which of the two had
        more), 1 or 2 (number row or keypad), one key press."""
        keys = {"1": 0, "num_1": 0, "2": 1, "num_2": 1}
        key, rt = self._wait(keys, lambda: self._frame(question, self.t("discriminate_keys")))
        return keys[key], rt

    def identify(self, trial, choices, results, rng) -> tuple[list[str], float]:
        """Each surface named with the number key shown beside each name."""
        keymap = choice_keys(choices)
        names = "   ".join(f"{i + 1} = {c}" for i, c in enumerate(choices))
        answers, total = [], 0.0
        for i in range(len(trial.samples)):
            key, rt = self._wait(keymap, lambda i=i: self._frame(
                self.t("name", i=i + 1), self.t("names", names=names)))
            answers.append(keymap[key])
            total += rt
        return answers, total

    def pause(self, fault: bool = False) -> None:
        self._waiting = None
        self._frame(self.t("paused"), self.t("paused_detail"))

    def debrief(self) -> str:
        """Free text: what made a sample feel real? ENTER ends, BACKSPACE deletes; SHIFT gives
        capitals and the shifted signs."""
        if self.debrief_text:
            return self.debrief_text
        text = ""
        self._flush()
        while True:
            self._frame(f"{self.t('debrief')}\n\n{text or '…'}", self.t("debrief_hint"))
            for item in self._keys():
                k, mods = (item if isinstance(item, tuple) else (item, {}))
                shift = bool(mods.get("shift") or mods.get("capslock")) if mods else False
                if k in ("return", "num_enter"):
                    self.debrief_text = text
                    return text
                if k == "backspace":
                    text = text[:-1]
                elif k == "space":
                    text += " "
                elif shift and k in _SHIFTED:
                    text += _SHIFTED[k]
                elif k in _PUNCT:
                    text += _PUNCT[k]
                elif len(k) == 1:
                    text += k.upper() if shift else k
            time.sleep(0.005)

    def finished(self, summary: str = "") -> None:
        self._frame(self.t("thanks"))

    def close(self) -> None:
        self.win.close()
        if self._log is not None:
            self._log.close()
            self._log = None


def _surfaces(trial) -> bool:
    """Whether ``trial``'s samples are surfaces the participant goes between: as the trial
    says (an adaptive phase's presentation), else as its kind does."""
    windows = getattr(trial, "windows", "") or (
        "" if trial.kind == REFERENCE else phase_kind(trial.kind).windows)
    return windows == "surfaces"


def _default_texts() -> dict:
    from protocols.texts import resolve_texts

    return resolve_texts({}, {})


def info_dialog(fields: dict, title: str = "Participant") -> dict | None:
    """A PsychoPy dialog asking the fields a protocol declares (``[participant] fields``):
    a text field per default, a choice per list. Returns the answers, or None if cancelled."""
    from psychopy import gui

    info = {k: (list(v) if isinstance(v, list) else v) for k, v in fields.items()}
    dlg = gui.DlgFromDict(info, title=title, sortKeys=False)
    return dict(info) if dlg.OK else None
