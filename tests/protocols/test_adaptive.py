"""Adaptive phase kinds (issue 57, item 1): the staircase and QUEST+ as pure functions of the
answers, their trials made by the session engine from the log, and what the loader refuses.

Reference values are hand calculations, written beside each."""

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocols import (
    Attempt,
    LogMismatch,
    ProtocolError,
    SessionEngine,
    load_protocol,
    parse_protocol,
    protocol_text,
)
from protocols.adaptive import (
    QuestPlus,
    Staircase,
    convergence,
    intensity_of,
    threshold_at,
    value_at,
    weber_fraction,
)


def test_units_move_magnitudes_and_come_back():
    # log: 10^0.1 = 1.2589; dB: 10^(6/20) = 1.9953; linear: 30 − 3
    assert value_at(100.0, 0.1, "log") == pytest.approx(125.8925, rel=1e-6)
    assert value_at(-240.0, 6.0, "dB") == pytest.approx(-478.864, rel=1e-5)
    assert value_at(30.0, 3.0, "linear", "down") == 27.0
    for units, x in (("log", 0.13), ("dB", 2.5), ("linear", 4.0)):
        for d in ("up", "down"):
            v = value_at(-150.0, x, units, d)
            assert intensity_of(-150.0, v, units) == pytest.approx(x, rel=1e-12)
    assert weber_fraction(0.1, "log") == pytest.approx(0.2589, abs=1e-4)
    assert weber_fraction(3.0, "linear", 30.0) == pytest.approx(0.1)
    assert convergence(3) == pytest.approx(0.5 ** (1 / 3))  # 0.7937, Levitt's 79.4 %


def test_a_staircase_steps_down_after_three_right_and_up_after_one_wrong():
    sc = Staircase(start=1.0, steps=(0.4, 0.2), change_after=(2,), down=3, stop_reversals=4,
                   discard=1, minimum=0.0, maximum=2.0)
    s = sc.begin()
    xs = []
    for answer in [1, 1, 1, 1, 1, 1, 0, 1, 1, 1, 0, 1, 1, 1]:
        xs.append(s.x)
        s = sc.update(s, bool(answer))
    # by hand: 1.0 ×3 → 0.6 ×3 → 0.2, wrong → up 0.6 (reversal 1 at 0.2), right ×3 →
    # down (reversal 2 at 0.6; the step is 0.2 from now) → 0.4, wrong → 0.6 (reversal 3
    # at 0.4), right ×3 → 0.4 (reversal 4 at 0.6)
    assert xs == pytest.approx([1.0, 1.0, 1.0, 0.6, 0.6, 0.6, 0.2, 0.6, 0.6, 0.6, 0.4, 0.6,
                                0.6, 0.6])
    assert s.reversals == pytest.approx((0.2, 0.6, 0.4, 0.6)) and sc.done(s)
    est = sc.estimate(s)  # the first discarded: mean of 0.6, 0.4, 0.6
    assert est["mean"] == pytest.approx(1.6 / 3) and est["n"] == 3


@settings(max_examples=60, deadline=None)
@given(st.lists(st.booleans(), max_size=80), st.integers(1, 4))
def test_a_staircase_stays_within_its_bounds_and_counts_its_reversals(answers, down):
    sc = Staircase(start=0.3, steps=(0.2, 0.1, 0.05), change_after=(1, 3), down=down,
                   stop_reversals=50, discard=0, minimum=0.05, maximum=0.5)
    s = sc.begin()
    moves = []
    for a in answers:
        before = s.x
        s = sc.update(s, a)
        assert sc.minimum <= s.x <= sc.maximum
        if s.direction and (s.x != before or s.reversal):
            moves.append(s.direction)
    assert s.trials == len(answers)
    assert len(s.reversals) <= len(answers)


def test_quest_plus_narrows_its_estimate_and_repeats_from_the_answers():
    grid = tuple(float(v) for v in np.geomspace(0.01, 0.5, 20))
    q = QuestPlus(intensities=grid, thresholds=grid, slopes=(2.0, 3.5, 5.0),
                  lapses=(0.0, 0.02, 0.04), trials=30)
    rng = np.random.default_rng(3)
    s, answers, widths = q.begin(), [], []
    for k in range(30):
        p = 0.5 + 0.48 * (1 - math.exp(-(s.x / 0.08) ** 3.5))  # a Weibull, α = 0.08
        answers.append(bool(rng.random() < p))
        s = q.update(s, answers[-1])
        if k in (3, 29):
            lo, hi = q.estimate(s)["ci"]
            widths.append(hi - lo)
    assert q.done(s) and widths[-1] < widths[0]
    truth = threshold_at(0.75, 0.08, 3.5, 0.5, 0.02)
    lo, hi = q.estimate(s)["ci"]
    assert lo < truth < hi
    again = q.begin()  # the same answers give the same state
    for a in answers:
        again = q.update(again, a)
    assert again.x == s.x and np.allclose(np.asarray(again.posterior), np.asarray(s.posterior))


MINI = """
[protocol]
name = "jnd-mini"
[window]
duration = 1.0
timeout = 10.0
[operator]
placeholders = ["block A", "block B"]
[[samples]]
id = "wood"
scene.spring = 400.0
scene.transient = { kind = "q_sinusoid", slope = -150.0, decay = 80.0, frequency = 100.0 }
[[samples]]
id = "rubber"
scene.spring = 400.0
scene.transient = { kind = "q_sinusoid", slope = -240.0, decay = 60.0, frequency = 30.0 }
[[phases]]
name = "frequency"
kind = "staircase"
samples = ["wood", "rubber"]
parameter = "frequency"
units = "log"
max_trials = 25
catch = 0.1
""" + ("staircase = { start = 0.2, steps = [0.08, 0.04], change_after = [2], down = 3, "
       "stop_reversals = 6, discard = 2, min = 0.005, max = 0.4 }\n")


def _observer(trial, rng):
    """Right with a Weibull's probability (α = 0.06 log10, β = 3)."""
    x = trial.stimulus.intensity
    return bool(rng.random() < 0.5 + 0.5 * (1 - math.exp(-(x / 0.06) ** 3)))


def _run(engine, rng, fail=None):
    """A whole session's log, answered by _observer; ``fail(trial)`` may return a status."""
    log = []
    while hasattr(t := engine.next_trial(log), "item"):
        status = fail(t) if fail else None
        if status:
            log.append(Attempt(t.item, status))
            continue
        log.append(Attempt(t.item, "valid", correct=_observer(t, rng)))
    return log


def test_tracks_interleave_by_the_seed_and_end_at_their_rule_or_cap():
    p = parse_protocol(MINI)
    log = _run(SessionEngine(p, 4, "P01"), np.random.default_rng(0))
    tracks = [a.item.split("/")[1].split("#")[0] for a in log]
    assert set(tracks) == {"wood-up", "rubber-up"}
    assert tracks != sorted(tracks)  # interleaved, not one after the other
    catch = [a for a in log if "#c" in a.item]
    assert 0 < len(catch) <= math.ceil(0.1 * 2 * 25)
    for name in ("wood-up", "rubber-up"):
        n = sum(t == name for t, a in zip(tracks, log, strict=True) if "#c" not in a.item)
        assert n <= 25
    assert log == _run(SessionEngine(p, 4, "P01"), np.random.default_rng(0))
    assert log != _run(SessionEngine(p, 5, "P01"), np.random.default_rng(0))


def test_every_prefix_of_a_log_resumes_exactly_where_it_stopped():
    """The engine's state is its log: a fresh engine (a resumed session) given any prefix
    makes the same next trial — track, intensity, comparison and its interval — as the
    engine that ran it, its cache notwithstanding."""
    p = parse_protocol(MINI)
    ran = SessionEngine(p, 9, "P01")
    log = _run(ran, np.random.default_rng(1))
    for k in range(len(log) + 1):
        a, b = SessionEngine(p, 9, "P01").next_trial(log[:k]), ran.next_trial(log[:k])
        assert a == b, k
        if hasattr(a, "stimulus"):
            assert a.stimulus.intensity == b.stimulus.intensity
            assert a.samples == b.samples


def test_a_saturated_or_stopped_trial_is_repeated_and_its_procedure_waits():
    p = parse_protocol(MINI)
    e = SessionEngine(p, 2, "P01")
    log = [Attempt(e.next_trial([]).item, "valid", correct=True)]
    t = e.next_trial(log)
    for status in ("saturated", "estop", "timed_out", "aborted_device", "requeued"):
        log.append(Attempt(t.item, status))
        again = e.next_trial(log)
        assert (again.item, again.samples, again.stimulus) == (t.item, t.samples, t.stimulus)
        assert again.attempt == t.attempt + 1
        t = again
    # left out at its cap: the track's next trial is at the same intensity (no answer taken)
    log.append(Attempt(t.item, "excluded_device"))
    nxt = e.next_trial(log)
    same = [a for a in log if a.item.startswith(t.item.split("#")[0])]
    if nxt.stimulus.track == t.stimulus.track and not nxt.stimulus.catch:
        assert nxt.stimulus.intensity == t.stimulus.intensity and same
        assert nxt.stimulus.answers == t.stimulus.answers


def test_the_procedure_takes_valid_answers_only():
    p = parse_protocol(MINI)
    e = SessionEngine(p, 2, "P01")
    t = e.next_trial([])
    with pytest.raises(LogMismatch, match="without its answer"):
        e.next_trial([Attempt(t.item, "valid")])
    after = e.state_after(t, True)
    assert after["answered"] == 1 and after["next"] == pytest.approx(t.stimulus.intensity)


def test_the_right_answer_is_the_larger_rendering():
    p = parse_protocol(MINI.replace('units = "log"', 'units = "log"\ndirections = ["up", "down"]'))
    e = SessionEngine(p, 6, "P01")
    log = _run(e, np.random.default_rng(2))
    seen = set()
    for k in range(len(log)):
        t = e.next_trial(log[:k])
        vals = [t.sample_of(p, s).scene.transient.frequency for s in t.samples]
        assert t.samples[t.stimulus.larger] == t.samples[int(np.argmax(vals))]
        seen.add((t.stimulus.track.endswith("down"), t.samples.index(t.stimulus.standard)))
    assert len(seen) == 4  # up and down tracks, the standard first and second


def test_the_thresholds_protocols_measure_the_factorial_best_sets():
    for name in ("thresholds", "thresholds_quest"):
        p = load_protocol(name)
        adaptive = [ph for ph in p.phases if ph.adaptive is not None]
        assert [ph.adaptive.parameter for ph in adaptive] == ["frequency", "decay", "slope"]
        for ph in adaptive:
            assert [t.standard for t in ph.adaptive.tracks] == ["rubber", "wood", "aluminum"]
        tr = p.samples["aluminum"].scene.transient  # SPEC §2, Table 2
        assert (tr.slope, tr.decay, tr.frequency) == (-300.0, 90.0, 300.0)
        design = p.design()["phases"][1]
        assert design["adaptive"]["parameter"] == "frequency"
        assert design["fit"] == {"criterion": 0.75, "function": "weibull", "lapse_max": 0.06}


def test_a_device_that_cannot_render_a_comparison_is_refused_by_name():
    from device import open_device

    with open_device("sim:1000") as dev:
        info = dev.info
    source, text = protocol_text("thresholds")
    with pytest.raises(ProtocolError, match=r"phase 'frequency', track 'aluminum-up', its "
                                            r"comparison at intensity 0.4 log \(frequency "
                                            r"753.566\).*Nyquist"):
        parse_protocol(text, source, info)
    assert replace(info, servo_rate_hz=10_000.0)  # the same device at 10 kHz renders them
    parse_protocol(text, source, replace(info, servo_rate_hz=10_000.0))


@pytest.mark.parametrize("change, message", [
    (('staircase = {', 'questplus = { intensities = [0.1, 0.2] }\nstaircase = {'),
     "runs its 'staircase' table, not 'questplus'"),
    (('staircase = {', '# staircase = {'), r"staircase: missing"),
    (('parameter = "frequency"', 'parameter = "colour"'), r"nonzero 'colour'"),
    (('units = "log"', 'units = "linear"\ndirections = ["down"]'),
     r"track 'wood-down': the comparison at intensity 150 linear is not a transient"),
    (('discard = 2,', 'discard = 9,'), "must exceed discard"),
    (('max = 0.4 }', 'max = 0.4 }\nno_repeat = true'), "a staircase trial has two"),
    (('catch = 0.1', 'catch = 0.9'), r"catch: must be <= 0.5"),
])
def test_what_an_adaptive_phase_cannot_be_is_named(change, message):
    assert change[0] in MINI
    text = MINI.replace(*change, 1)
    if "linear" in change[1]:  # a linear step below the standard must not pass zero
        text = text.replace("max = 0.4 }", "max = 150.0 }")
    with pytest.raises(ProtocolError, match=message):
        parse_protocol(text)


def test_only_an_adaptive_phase_takes_a_procedure():
    text = MINI.replace('kind = "staircase"', 'kind = "free"')
    with pytest.raises(ProtocolError, match="only an adaptive phase"):
        parse_protocol(text)


def test_a_phase_presents_its_trials_as_two_intervals_or_two_surfaces():
    """Two-interval (one window each, in turn; a placeholder swapped as for any virtual
    trial) or a two-alternative choice in space: both renderings as surfaces of one scene
    that the participant goes between, as identification's."""
    p = parse_protocol(MINI)
    t = SessionEngine(p, 1, "P01").next_trial([])
    assert (t.windows, t.surfaces, t.placement) == ("each_sample", False, "block A")
    p = parse_protocol(MINI.replace('units = "log"', 'units = "log"\npresentation = "surfaces"'))
    t = SessionEngine(p, 1, "P01").next_trial([])
    assert (t.windows, t.surfaces, t.placement) == ("surfaces", True, None)
    assert p.phases[0].adaptive.presentation == "surfaces"
    with pytest.raises(ProtocolError, match="presentation: must be one of intervals, surfaces"):
        parse_protocol(MINI.replace('units = "log"', 'units = "log"\npresentation = "mixed"'))
