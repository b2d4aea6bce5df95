"""The participant screen in a real PsychoPy window under Xvfb, with screenshots.

Screenshots land in tests/artifacts/screens/ (and are copied to docs/screens/ for the
README). Key presses are injected here; tests/app/test_test_day.py drives whole sessions
with real X key events (xdotool). Everything else — window, text, drawing — is real.
"""

from types import SimpleNamespace

import numpy as np
import pytest

from device import ContactEvent, WindowResult
from protocols import load_protocol, parse_protocol, protocol_text

pytestmark = [pytest.mark.screen, pytest.mark.realtime]

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


def make(protocol, keys, size=(800, 600)):
    from app.screen import PsychoPyScreen

    p = protocol if not isinstance(protocol, str) else load_protocol(protocol)
    return PsychoPyScreen(p, size=size, keys=keys)


def edited(name, old, new):
    source, text = protocol_text(name)
    assert old in text
    return parse_protocol(text.replace(old, new), source)


TRIAL = SimpleNamespace(phase="testing", samples=("wood",), trial_index=3, attempt=1,
                        kind="rated")
FREE = SimpleNamespace(phase="familiarization", samples=("wood",), trial_index=1, attempt=1,
                       kind="free")
ID_TRIAL = SimpleNamespace(phase="identification", samples=("wood", "rubber", "aluminum"),
                           trial_index=1, attempt=1, kind="identification")


def test_realism_screens_are_text_only_and_say_the_keys_they_use(xdisplay, shots):
    scr = make("realism", Keys([], ["return", "space"], ["return"]))
    try:
        scr.instructions("familiarization")
        text = scr.drawn_text[0]
        # the keys named are the keys used: SPACE begins, ENTER ends familiarization
        assert "Press SPACE to begin" in text and "When you are done, press ENTER" in text
        scr.screenshot(shots / "realism-instructions.png", text=text)
        scr.before_window(FREE, "wood", None, None)
        assert scr.drawn_text == ["Tap", "press ENTER when you are done"]
        partial = WindowResult(10_000, 1.0, [ContactEvent(1.0, 0.1)])
        partial.live_height = 0.01
        scr.progress(2.5, partial, 5.0)
        assert not scr.keep_tapping()  # ENTER during the window: done
        scr.screenshot(shots / "realism-tap.png", text="Tap", cursor=True, progress=0.5)
        std, img = image_stats(shots / "realism-tap.png")
        assert std > 1.0  # not blank
        assert not scr.cursor  # text only: where the factorial screen draws, nothing
        assert np.ptp(img[380:460, :]) < 5
    finally:
        scr.close()


def test_between_trials_please_wait_until_the_operator_starts(xdisplay, shots):
    scr = make("factorial", Keys([], ["x"], ["r"], [], [], [], ["space"], []))
    trial = SimpleNamespace(phase="rating", samples=("wood-HHH",), trial_index=4, attempt=1,
                            kind="rated")
    try:
        scr.waiting(trial)
        assert scr.drawn_text[0] == "Please wait"
        assert "Press R to tap the real block again" in scr.drawn_text[1]
        assert scr.poll() is None  # another key: nothing
        scr.screenshot(shots / "between-trials.png", text=scr.drawn_text[0],
                       small=scr.drawn_text[1])
        assert scr.poll() == "reference"  # R: the participant asks for the real block
        assert "is placing the real block" in scr.drawn_text[1]
        assert scr.poll() is None  # asked once
        scr.waiting(SimpleNamespace(**{**vars(trial), "kind": "reference"}))  # being placed
        assert "is placing the real block" in scr.drawn_text[1]
        assert "Press R" not in scr.drawn_text[1]
        ref = load_protocol("factorial").samples["wood-real"]
        scr.reference(trial, ref)  # the phase's instructions first (SPACE), then the block
        assert scr.drawn_text[0] == "Tap the real block" and "real wood block" in \
            scr.drawn_text[1]
        scr.screenshot(shots / "reference-block.png", text=scr.drawn_text[0],
                       small=scr.drawn_text[1], cursor=True)
        assert image_stats(shots / "reference-block.png")[0] > 1.0
        # during its window too: the real block's title stays (it once flashed to 'Tap')
        rtrial = SimpleNamespace(**{**vars(trial), "kind": "reference",
                                    "samples": ("wood-real",), "placement": "real wood block"})
        scr.before_window(rtrial, "wood-real", None, None)
        partial = WindowResult(10_000, 0.2, [ContactEvent(0.2, 0.1)])
        partial.live_height = 0.01
        scr.progress(0.5, partial, 5.0)
        assert scr.drawn_text[0] == "Tap the real block" and "real wood block" in \
            scr.drawn_text[1]
    finally:
        scr.close()


def test_single_key_rating_ignores_other_keys_and_counts_a_double_press_once(xdisplay, shots):
    keys = Keys(["a", "5", "5"],  # flushed: pressed before the screen appeared
                ["return"],  # nothing chosen yet: ENTER does nothing
                ["x", "9", "space"], ["3"], ["6", "6"], ["return"])
    scr = make("realism", keys)
    try:
        scale = scr.protocol.rating
        assert scale.entry_mode == "keys"
        rating, rt = scr.rate(TRIAL, scale, None, None)
        # 'x', '9' (off the 1–7 scale) and 'space' ignored; 3 chosen, changed to 6, confirmed
        assert rating == 6 and rt >= 0
        assert scr.drawn_text[1] == "Your rating: 6"
        low, high = scale.anchors[scale.min], scale.anchors[scale.max]
        assert scr.drawn_text[3:] == [low, high]  # each anchor under its end of the scale
        line = scr.drawn_text[2]
        assert line.index("[6]") > line.index(" 1 ") and line.rstrip().endswith("7")
        scr.screenshot(shots / "realism-rating.png", text=scale.question,
                       small="Your rating: 6 — ENTER confirms, another number changes it.",
                       scale=(line, low, high))
        assert image_stats(shots / "realism-rating.png")[0] > 1.0
    finally:
        scr.close()


def test_ratings_above_nine_are_typed_and_confirmed(xdisplay, shots):
    """On 1–10 a 0 used to record 10; on 1–100 typing '100' recorded 1. Ratings are now
    typed and confirmed with ENTER; off the scale is said so and asked again."""
    scr = make("factorial", Keys([], ["0"], ["return"], ["1", "0"], ["return"]))
    try:
        scale = scr.protocol.rating
        assert scale.entry_mode == "typed"
        rating, _ = scr.rate(TRIAL, scale, None, None)
        assert rating == 10
        # the scale's ten points are drawn, 10 marked, each end's anchor under its end
        # (they were one grey line): placed left and right of the centre, at the line's ends
        assert scr.drawn_text[3:] == [scale.anchors[1], scale.anchors[10]]
        assert scr.drawn_text[2].rstrip().endswith("[10]")
        line, low, high = scr._scale_stims
        assert line.boundingBox[1] < 1.6 * line.height  # one line: ten points wrapped once
        half = line.boundingBox[0] / 2
        assert low.pos[0] == pytest.approx(-half) and high.pos[0] == pytest.approx(half)
        assert low.pos[1] < line.pos[1] and high.pos[1] < line.pos[1]
        scr.screenshot(shots / "factorial-rating.png", text=f"{scale.question}\n\n10",
                       small="Type a number from 1 to 10, then press ENTER.",
                       scale=scr._scale_line(scale, 10))
    finally:
        scr.close()
    p = edited("realism", "min = 1\nmax = 7", "min = 0\nmax = 100")
    scr = make(p, Keys([], ["1", "0", "1", "return"], ["backspace", "backspace", "backspace",
                                                        "1", "0", "0"], ["return"]))
    try:
        rating, _ = scr.rate(TRIAL, p.rating, None, None)
        assert rating == 100  # 101 was refused ("not on the scale"), then 100
    finally:
        scr.close()
    p = edited("realism", "min = 1\nmax = 7", "min = 0\nmax = 10")
    scr = make(p, Keys([], ["0", "return"]))
    try:
        assert scr.rate(TRIAL, p.rating, None, None)[0] == 0  # 0 is 0 on a 0–10 scale
    finally:
        scr.close()


def test_a_slider_rating(xdisplay, shots):
    p = edited("realism", 'question = "How well', 'entry = "slider"\nquestion = "How well')
    scr = make(p, Keys([], ["return"], ["right", "right"], ["left"], ["return"]))
    try:
        rating, _ = scr.rate(TRIAL, p.rating, None, None)
        assert rating == 4 + 2 - 1  # from the middle (4 on 1–7): right, right, left
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
        assert np.ptp(img[380:460, :]) > 50 and (img[350:, :] > 100).sum() > 2000
    finally:
        scr.close()


def test_identification_surfaces_and_names_by_number_keys(xdisplay, shots):
    """Choices that share a first letter or use capitals left the participant stuck: names
    are now answered with the number shown beside each."""
    keys = Keys([], ["2"], [], ["1"], [], ["n"], ["3"], [], ["n"], [], ["2"], [], ["1"], [],
                ["3"])
    scr = make("identification", keys)
    try:
        visited: set[int] = set()
        order = []
        while (k := scr.choose_surface(ID_TRIAL, visited)) is not None:
            order.append(k)
            visited.add(k)
            if len(visited) == 2:
                scr.screenshot(shots / "identification-choose.png",
                               text="Choose a surface: 1, 2, 3", small="tapped: 1, 2",
                               cursor=True)
        assert order == [1, 0, 2]  # 'n' is refused until all three were tapped
        choices = ("Rubber", "rosewood", "aluminum")  # a shared first letter, a capital
        answers, _ = scr.identify(ID_TRIAL, choices, [], None)
        assert answers == ["rosewood", "Rubber", "aluminum"]
        assert scr.drawn_text[1] == "1 = Rubber   2 = rosewood   3 = aluminum"
        scr.screenshot(shots / "identification-answer.png", text="Surface 1 is …",
                       small="1 = rubber   2 = wood   3 = aluminum")
    finally:
        scr.close()


def test_identification_switches_surface_during_a_window(xdisplay, shots):
    """Issue 30 (9): during a surface's window another surface's number ends it and goes
    there; the surface's own number does nothing, N only once every surface was tapped."""
    keys = Keys([], ["1"],  # choose surface 1 before any window
                ["1"], ["3"],  # tapping 1: its own key nothing, 3 moves on
                ["n"], ["num_2"],  # tapping 3: N refused (2 not tapped yet), 2 moves on
                ["n"])  # tapping 2: all tapped, N goes to naming
    scr = make("identification", keys)
    partial = WindowResult(10_000, 1.0, [ContactEvent(1.0, 0.1)])
    partial.live_height = 0.004
    try:
        visited: set[int] = set()
        order, moves = [], []
        while (k := scr.choose_surface(ID_TRIAL, visited)) is not None:
            order.append(k)
            scr.before_window(ID_TRIAL, ID_TRIAL.samples[k], None, None)
            if k == 2:
                assert scr.drawn_text == ["Tap · Surface 3", "another surface: 1, 2"]
                scr.screenshot(shots / "identification-switch.png", text=scr.drawn_text[0],
                               small=scr.drawn_text[1], cursor=True, progress=0.4)
            if k == 1:
                assert scr.drawn_text[1] == "another surface: 1, 3   — press N to name them"
            polls = 0
            while not scr.moving_on():
                scr.progress(1.0, partial, 20.0)
                polls += 1
            moves.append(polls)
            visited.add(k)
        assert order == [0, 2, 1]
        assert moves == [2, 2, 1]  # the own key and an early N did not end a window
    finally:
        scr.close()


def test_identification_real_block_choice_saturation_notice_and_surface_title(xdisplay,
                                                                              shots):
    """R in identification: the participant picks which real block (by number, in the
    protocol's order; ESC for none); a saturated trial is said on the next 'please wait'
    (also with the sound off); while tapping, the screen says which surface — not its name."""
    blocks = [("rubber-real", "real rubber block"), ("wood-real", "real wood block"),
              ("aluminum-real", "real aluminum block")]
    scr = make("identification", Keys([], ["9"], ["3"], [], ["escape"], [], [], [], [], []))
    try:
        assert scr.choose_reference(ID_TRIAL, blocks) == "aluminum-real"
        assert scr.drawn_text[1] == "The experimenter is placing the real block."
        scr.screenshot(shots / "identification-which-block.png",
                       text="Which real block would you like to tap again?",
                       small="1 = real rubber block   2 = real wood block   3 = real aluminum "
                             "block      (ESC: none)")
        assert scr.choose_reference(ID_TRIAL, blocks) is None  # ESC: none after all
        assert scr.choose_reference(ID_TRIAL, blocks[:1]) == "rubber-real"  # one: no question
        scr.saturated(ID_TRIAL)
        scr.waiting(ID_TRIAL)
        assert "too hard for the device" in scr.drawn_text[1]
        scr.screenshot(shots / "saturated-notice.png", text=scr.drawn_text[0],
                       small=scr.drawn_text[1])
        scr.waiting(ID_TRIAL)  # said once
        assert "too hard" not in scr.drawn_text[1]
        scr.saturated(ID_TRIAL, comes_back=False)  # the protocol's last attempt at the item
        scr.waiting(ID_TRIAL)
        assert "tap more gently" in scr.drawn_text[1] and "comes back" not in scr.drawn_text[1]
        scr.before_window(ID_TRIAL, "rubber", None, None)
        assert scr.drawn_text[0] == "Tap · Surface 2"
        assert not any("rubber" in t for t in scr.drawn_text)
    finally:
        scr.close()


def test_pause_and_a_debrief_with_capitals_and_punctuation(xdisplay, shots):
    shift = {"shift": True}
    scr = make("realism", Keys([], [("a", shift), "space", "s", "u", "d", "d", "e", "n"],
                               ["backspace", "comma", "space", "s", "t", "o", "p",
                                # X reports the character Shift made: ! is 'exclamation', and
                                # a layout whose Shift+key is a digit gives that digit
                                ("exclamation", shift), ("4", shift), "return"]))
    try:
        scr.pause(fault=True)
        assert scr.drawn_text[0] == "Paused"
        scr.screenshot(shots / "pause.png", text="Paused",
                       small="The experimenter will continue shortly.")
        text = scr.debrief()
        assert text == "A sudde, stop!4"
        scr.screenshot(shots / "debrief.png", text="What made a sample feel real or not?\n\n"
                       "A sudden stop, no buzzing.", small="Type, then press ENTER.")
    finally:
        scr.close()


def test_texts_come_from_the_protocol(xdisplay):
    p = edited("realism", "[saturation]", '[texts]\nlanguage = "de"\nwait = "Bitte warten"\n'
               '[texts.instructions]\ntesting = "Klopfen Sie und bewerten Sie."\n\n[saturation]')
    assert p.texts["language"] == "de"
    scr = make(p, Keys([], [], ["space"]))
    try:
        scr.waiting(TRIAL)
        assert scr.drawn_text[0] == "Bitte warten"
        scr.instructions("testing")
        assert scr.drawn_text[0] == "Klopfen Sie und bewerten Sie."
    finally:
        scr.close()


@pytest.mark.parametrize("size", [(1024, 768), (1920, 1080)])
def test_layout_scales_with_the_window(xdisplay, shots, size):
    """The same screen at 1024×768 and 1920×1080: text, surface, cursor and bar keep their
    places as fractions of the window."""
    scr = make("factorial", Keys([]), size=size)
    try:
        w, h = scr.win.size
        assert (w, h) == size
        partial = WindowResult(10_000, 1.0, [ContactEvent(1.0, 0.1)])
        partial.live_height = 0.01
        scr._height = 0.01
        name = shots / f"factorial-tap-{w}x{h}.png"
        scr.screenshot(name, text="Tap", cursor=True, progress=0.5)
        _, img = image_stats(name)
        rows = np.flatnonzero((img > 90).sum(axis=1) > 0.5 * w)  # the surface band
        assert rows.size and abs(rows.mean() / h - 0.7) < 0.02  # 0.2 h below the centre
        assert abs(scr._text.height / h - 0.042) < 1e-6
    finally:
        scr.close()


PAIR = SimpleNamespace(phase="pairs", samples=("pulse_firm", "soft_spring"), trial_index=4,
                       attempt=1, kind="comparison")


def test_a_comparison_titles_its_two_windows_and_takes_one_key_of_1_or_2(xdisplay, shots):
    """The comparison kind (issue 33): each window says which of the two it is, and the
    choice is one press of 1 or 2 (number row or keypad); any other key is ignored."""
    scr = make("comparison", Keys([], ["3", "n"], [], ["num_2"]))
    try:
        assert scr._tap_title(PAIR, "pulse_firm") == "Tap · sample 1 of 2"
        assert scr._tap_title(PAIR, "soft_spring") == "Tap · sample 2 of 2"
        k, rt = scr.choose(PAIR, [None, None], None)
        assert k == 1 and rt >= 0
        assert scr.drawn_text[:2] == ["Which felt more like touching a real object?",
                                      "1 = the first        2 = the second"]
        scr.screenshot(shots / "comparison-choice.png",
                       text="Which felt more like touching a real object?",
                       small="1 = the first        2 = the second")
        std, _ = image_stats(shots / "comparison-choice.png")
        assert std > 5  # text was drawn, not a blank window
    finally:
        scr.close()


def test_an_adaptive_trial_asks_the_phases_question_and_takes_1_or_2(xdisplay, shots):
    """The threshold kinds (issue 57): the two windows are numbered as a pair's, the
    question is the phase's (what the parameter is, in words), and the answer one press of
    1 or 2; screenshots of the tap and the question."""
    p = load_protocol("thresholds")
    phase = next(ph for ph in p.phases if ph.name == "frequency")
    trial = SimpleNamespace(phase="frequency", samples=("wood@125.893", "wood"),
                            trial_index=9, attempt=1, kind="staircase")
    scr = make(p, Keys([], ["space", "n"], [], ["2"]))
    try:
        assert scr._tap_title(trial, "wood@125.893") == "Tap · sample 1 of 2"
        assert scr._tap_title(trial, "wood") == "Tap · sample 2 of 2"
        scr.screenshot(shots / "threshold-tap.png", text=scr._tap_title(trial, "wood"),
                       progress=0.4)
        k, rt = scr.discriminate(trial, phase.adaptive.question, None)
        assert k == 1 and rt >= 0
        assert scr.drawn_text[:2] == ["Which vibrated faster (the higher pitch)?",
                                      "1 = the first        2 = the second"]
        scr.screenshot(shots / "threshold-question.png", text=phase.adaptive.question,
                       small=scr.t("discriminate_keys"))
        for name in ("threshold-tap.png", "threshold-question.png"):
            std, _ = image_stats(shots / name)
            assert std > 5  # text was drawn, not a blank window
    finally:
        scr.close()


def test_an_adaptive_trial_as_two_surfaces_says_surface_and_n_answers(xdisplay, shots):
    """Presented as two surfaces (2AFC in space), an adaptive trial's windows are titled
    by surface, N answers once both were tapped, and the phase's instructions say so."""
    from protocols import SessionEngine

    source, text = protocol_text("thresholds")
    p = parse_protocol(text.replace('parameter = "frequency"',
                                    'parameter = "frequency"\npresentation = "surfaces"', 1),
                       source)
    trial = SessionEngine(p, 3, "P01").next_trial(
        [__import__("protocols").Attempt("familiarization/wood#1", "valid")])
    assert trial.surfaces and trial.phase == "frequency"
    scr = make(p, Keys([], ["space"], [], ["1"], [], ["2"], [], ["n"]))
    try:
        scr.instructions("frequency")
        assert scr.drawn_text[0].startswith("Two surfaces: press 1 or 2")
        first = trial.samples[0]
        assert scr._tap_title(trial, first) == "Tap · Surface 1"
        assert scr.choose_surface(trial, set()) == 0
        assert scr.choose_surface(trial, {0}) == 1
        assert scr.choose_surface(trial, {0, 1}) is None  # N: to the question
        assert scr.drawn_text[1].endswith("press N to answer")
    finally:
        scr.close()


def test_the_screen_log_has_a_line_per_screen_and_one_where_keys_start_to_count(
        xdisplay, tmp_path, monkeypatch):
    """HAPTICLAB_SCREEN_LOG: a line when what the screen says changes, and one on the first
    frame after the key buffer is cleared even when the text is the same (the second
    'please wait'), so a program waiting for the line knows its keys count; frames that say
    the same (a progress bar filling) write nothing."""
    log = tmp_path / "screens.log"
    monkeypatch.setenv("HAPTICLAB_SCREEN_LOG", str(log))
    # one batch of keys per look: the clearing of each wait and of the rating, five polls
    scr = make("realism", Keys(*[[]] * 8, ["3"], ["return"]))
    try:
        scr.waiting(TRIAL)
        for _ in range(5):
            scr.poll()  # the same screen, kept alive
        scr.waiting(TRIAL)  # the next trial's wait: keys cleared, the same words
        scr.rate(TRIAL, scr.protocol.rating, None, None)
    finally:
        scr.close()
    lines = log.read_text(encoding="utf-8").splitlines()
    times = [float(ln.split("\t")[0]) for ln in lines]
    said = [ln.split("\t")[1] for ln in lines]
    assert times == sorted(times)
    assert [s.split(" | ")[0] for s in said[:2]] == ["Please wait", "Please wait"]
    # the rating: its first frame (nothing chosen), 3 chosen, 3 confirmed
    question = scr.protocol.rating.question
    assert [s.split(" | ")[0] for s in said[2:]] == [question] * 3
    assert "Your rating: 3" in said[3] and len(lines) == 5
