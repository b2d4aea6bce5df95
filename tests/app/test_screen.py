"""The participant screen in a real PsychoPy window under Xvfb, with screenshots.

Screenshots land in tests/artifacts/screens/ (and are copied to docs/screens/ for the
README). Key presses are injected; everything else — window, text, drawing — is real.
"""

from types import SimpleNamespace

import numpy as np
import pytest

from device import ContactEvent, WindowResult
from protocols import load_protocol

psychopy = pytest.importorskip("psychopy", reason="the `ui` extra is installed by make test")


class Keys:
    """Scripted key presses: each call returns the next batch; running out is an error
    (a screen still waiting then would wait for ever)."""

    def __init__(self, *batches):
        self.batches = list(batches)

    def __call__(self):
        if not self.batches:
            raise AssertionError("the screen is still waiting but the scripted keys ran out")
        return self.batches.pop(0)


def image_stats(path):
    from PIL import Image

    a = np.asarray(Image.open(path).convert("L"), dtype=float)
    return a.std(), a


@pytest.fixture
def shots(artifacts):
    d = artifacts / "screens"
    d.mkdir(exist_ok=True)
    return d


def make(protocol, keys):
    from app.screen import PsychoPyScreen

    return PsychoPyScreen(load_protocol(protocol), size=(800, 600), keys=keys)


TRIAL = SimpleNamespace(phase="testing", samples=("wood",), trial_index=3, attempt=1)
ID_TRIAL = SimpleNamespace(phase="identification", samples=("wood", "rubber", "aluminum"),
                           trial_index=1, attempt=1)


def test_realism_screens_are_text_only(xdisplay, shots):
    scr = make("realism", Keys([], ["x", "space"], []))  # the last: polled during the window
    try:
        scr.instructions("familiarization")
        assert "Press SPACE when you are done" in scr.drawn_text[0]
        scr.screenshot(shots / "realism-instructions.png", text=scr.drawn_text[0])
        scr.before_window(TRIAL, "wood", None, None)
        assert scr.drawn_text == ["Tap"]
        partial = WindowResult(10_000, 1.0, [ContactEvent(1.0, 0.1)])
        partial.live_height = 0.01
        scr.progress(2.5, partial, 5.0)
        scr.screenshot(shots / "realism-tap.png", text="Tap", cursor=True, progress=0.5)
        std, img = image_stats(shots / "realism-tap.png")
        assert std > 1.0  # not blank
        # text only: where the factorial screen draws its surface and cursor, nothing
        assert not scr.cursor
        assert np.ptp(img[380:460, :]) < 5
    finally:
        scr.close()


def test_rating_ignores_other_keys_and_counts_a_double_press_once(xdisplay, shots):
    keys = Keys(["a", "5", "5"],  # flushed: pressed before the screen appeared
                ["x", "9", "space"], ["6", "6"])
    scr = make("realism", keys)
    try:
        scale = scr.protocol.rating
        rating, rt = scr.rate(TRIAL, scale, None, None)
        assert rating == 6 and rt >= 0  # 'x', '9' (off the 1–7 scale) and 'space' ignored
        assert "your rating: 6" in scr.drawn_text[1]
        scr.screenshot(shots / "realism-rating.png",
                       text=f"{scale.question}\n\n1  2  3  4  5  6  7",
                       small="1 = not at all like the real wood   7 = exactly like the real wood")
        assert image_stats(shots / "realism-rating.png")[0] > 1.0
    finally:
        scr.close()


def test_factorial_rating_types_ten_as_zero(xdisplay, shots):
    scr = make("factorial", Keys([], ["0"]))
    try:
        rating, _ = scr.rate(TRIAL, scr.protocol.rating, None, None)
        assert rating == 10
        text = scr.drawn_text
        scr.screenshot(shots / "factorial-rating.png", text=text[0],
                       small="1 = least realistic   10 = most realistic  (press 0 for 10)")
    finally:
        scr.close()


def test_factorial_tap_screen_draws_surface_and_cursor(xdisplay, shots):
    scr = make("factorial", Keys([]))
    try:
        assert scr.cursor
        partial = WindowResult(10_000, None, [])
        partial.live_height = 0.012  # 12 mm above the surface
        scr.progress(0.0, partial, 5.0)
        scr.screenshot(shots / "factorial-tap.png", text="Tap", cursor=True)
        std, img = image_stats(shots / "factorial-tap.png")
        # the surface band (and the cursor above it) are drawn
        assert np.ptp(img[380:460, :]) > 50 and (img[350:, :] > 100).sum() > 2000
    finally:
        scr.close()


def test_identification_switches_surfaces_then_names_each(xdisplay, shots):
    # each screen first clears the key buffer (the [] batches), then reads keys
    keys = Keys([], ["2"], [], ["1"], [], ["n"], ["3"], [], ["n"], [], ["w"], [], ["r"], [], ["a"])
    scr = make("identification", keys)
    try:
        visited: set[int] = set()
        order = []
        while (k := scr.choose_surface(ID_TRIAL, visited)) is not None:
            order.append(k)
            visited.add(k)
            if len(visited) == 2:
                scr.screenshot(shots / "identification-choose.png", text="Choose a surface: 1, 2 "
                               "or 3", small="tapped: 1, 2", cursor=True)
        # 'n' is refused until all three were tapped; '3' then completes the set
        assert order == [1, 0, 2]
        answers, rt = scr.identify(ID_TRIAL, ("rubber", "wood", "aluminum"), [], None)
        assert answers == ["wood", "rubber", "aluminum"]
        scr.screenshot(shots / "identification-answer.png", text="Surface 1 is …",
                       small="R = rubber   W = wood   A = aluminum")
    finally:
        scr.close()


def test_pause_and_debrief(xdisplay, shots):
    scr = make("realism", Keys([], ["s", "u", "d", "d", "e", "n", "backspace", "space", "s",
                                    "t", "o", "p", "return"]))
    try:
        scr.pause()
        assert scr.drawn_text[0] == "Paused"
        scr.screenshot(shots / "pause.png", text="Paused",
                       small="the experimenter will continue shortly")
        text = scr.debrief()
        assert text == "sudde stop"
        scr.screenshot(shots / "debrief.png", text="What made a sample feel real or not?\n\n"
                       "a sudden stop, no buzzing", small="type, then press ENTER")
    finally:
        scr.close()
