"""The simulator and the scene loader at their extremes: every value has a stated bound, and
past it a named error, never a hang, a raw numpy exception or a silent loss.

The values are those an independent check fed the simulator (issue 34): stiffness 1e15 N/m
took 33 s per 3-s window, 1e20 hung, 1e300 raised numpy's LinAlgError and 10**400 an
OverflowError; a 1e7-s window ran for hours; the 4,097th contact of a window was dropped; a
transient at 0.499 × the servo rate played 4–14 % of its peak; a chattering contact ran
hundreds of times slower than real time. Nothing was said of any of it.
"""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import device.sim.backend as backend
from device import (
    MAX_WINDOW_TICKS,
    AccelSinusoid,
    ForceSinusoid,
    Material,
    Pulse,
    Ringing,
    Scene,
    SceneError,
    Support,
)
from device.scene import (
    MAX_DAMPING,
    MAX_GAIN,
    MAX_RINGING_HZ,
    MAX_SLOPE,
    MAX_STIFFNESS,
    MIN_RENDERED,
    WARN_RENDERED,
)
from device.sim.backend import SimDevice
from device.sim.plant import MAX_CONTACT_HZ
from protocols import ProtocolError, parse_protocol

HUGE = [1e15, 1e20, 1e300, 10**400]


@pytest.mark.parametrize("k", HUGE)
@pytest.mark.parametrize("build", [
    lambda k: Material(k),
    lambda k: Material(1e4, mass=0.02, support=Support(k)),
    lambda k: Scene("s", spring=k),
    lambda k: Scene.from_dict({"name": "s", "material": {"stiffness": k}}),
], ids=["contact", "support", "spring", "from-data"])
def test_a_stiffness_past_the_bound_is_a_scene_error_that_says_why(build, k):
    with pytest.raises(SceneError) as err:
        build(k)
    msg = str(err.value)
    assert err.value.field in ("stiffness", "spring")
    assert ("must be <= 1e+08" in msg and "steel" in msg) or "must be finite" in msg


def test_the_stiffness_bound_itself_is_accepted():
    assert Material(MAX_STIFFNESS).stiffness == MAX_STIFFNESS
    assert Scene("s", spring=MAX_STIFFNESS).spring == MAX_STIFFNESS


@pytest.mark.parametrize("build,field", [
    (lambda: Material(1e4, damping=MAX_DAMPING * 1.01), "damping"),
    (lambda: Support(1e4, damping=1e300), "damping"),
    (lambda: Ringing(-1500.0, 600.0, MAX_RINGING_HZ * 1.01), "frequency"),
    (lambda: Ringing(-MAX_SLOPE * 1.01, 600.0, 592.0), "slope"),
    (lambda: AccelSinusoid(MAX_SLOPE * 1.01, 60.0, 30.0), "slope"),
    (lambda: Pulse(MAX_GAIN * 1.01, 0.01), "gain"),
    (lambda: ForceSinusoid(1e300, 0.05, 100.0), "gain"),
])
def test_every_scene_value_has_a_bound(build, field):
    with pytest.raises(SceneError) as err:
        build()
    assert err.value.field == field and ("<=" in str(err.value) or "within" in str(err.value))


@given(st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                 st.integers(min_value=-10**500, max_value=10**500)))
def test_any_number_for_a_stiffness_is_taken_or_refused_by_name(k):
    try:
        m = Material(k)
    except SceneError as exc:
        assert exc.field == "stiffness"
    else:
        assert 0 < m.stiffness <= MAX_STIFFNESS


def test_a_contact_ringing_past_what_the_simulator_resolves_is_refused_when_compiled():
    """The contact's own frequency on the masses it joins is the simulator's cost: a 1-µg
    block on the stiffest contact allowed would ring at ~1.6 MHz."""
    dev = SimDevice(seed=1)
    tiny = Scene("tiny", material=Material(MAX_STIFFNESS, mass=1e-9, support=Support(1e4)))
    with pytest.raises(SceneError) as err:
        dev.check_scene(tiny)
    f = math.sqrt(MAX_STIFFNESS / 1e-9) / (2 * math.pi)  # by hand: the block alone bounds it
    assert err.value.field == "stiffness" and f"{MAX_CONTACT_HZ:g} Hz" in str(err.value)
    assert f > MAX_CONTACT_HZ
    # the chatter example of the issue (a 1-g block on 1e7 N/m: ~16 kHz) is allowed
    dev.check_scene(Scene("light", material=Material(1e7, mass=1e-3, support=Support(1e4))))


def test_a_window_longer_than_the_device_records_is_refused_before_it_runs():
    dev = SimDevice(seed=1)
    dev.load_scene(Scene("k", spring=400.0))
    dev.home()
    limit = MAX_WINDOW_TICKS / 10_000.0
    assert dev.max_window_s == pytest.approx(limit)
    with pytest.raises(ValueError, match="longer than this device records"):
        dev.run_window(1e7)
    with pytest.raises(ValueError, match=r"wait for a first contact 30 s"):
        dev.run_window(limit - 10.0, timeout=30.0)  # the wait counts: every tick is kept
    with pytest.raises(ValueError, match="split it"):
        dev.play_force(np.zeros(MAX_WINDOW_TICKS + 1))
    assert dev.fault is None
    dev.home()
    assert dev.run_window(0.2, from_first_contact=False).traces["t"].size == 2000


PROTO = """
[protocol]
name = "long"

[window]
duration = {duration}
timeout = {timeout}

[rating]
min = 1
max = 7
question = "How real?"

[[samples]]
id = "firm"
scene.spring = 680.0

[[phases]]
name = "testing"
samples = ["firm"]
repetitions = 1
"""


def test_a_protocol_whose_window_outgrows_the_device_is_refused_on_load():
    info = SimDevice(seed=1).info
    ok = parse_protocol(PROTO.format(duration=600.0, timeout=30.0), "long.toml", info)
    assert ok.window.duration == 600.0
    with pytest.raises(ProtocolError, match=r"window.*timeout.*838\.861 s"):
        parse_protocol(PROTO.format(duration=600.0, timeout=3600.0), "long.toml", info)
    parse_protocol(PROTO.format(duration=600.0, timeout=3600.0), "long.toml")  # no device


def _many_contacts(monkeypatch, capacity):
    monkeypatch.setattr(backend, "_EVENTS", capacity)
    monkeypatch.setattr(backend, "_CHUNK_S", 0.0005)  # 5 ticks a chunk: the buffers grow often
    dev = SimDevice(seed=3)
    dev.load_scene(Scene("k", spring=400.0))
    dev.home()
    return dev.run_window(6.0, from_first_contact=False)


def test_no_contact_is_dropped_when_a_window_has_more_than_its_buffers_held(monkeypatch):
    """The buffers grow before a chunk could fill them: with room for 2 contacts at the
    start and chunks of 5 ticks (so they grow again and again), a window reports exactly
    what it reports with room for 4,096 (same seed), and each reported contact is a tick
    where the encoder crossed the surface."""
    roomy = _many_contacts(monkeypatch, 4096)
    tight = _many_contacts(monkeypatch, 2)
    assert len(roomy.contacts) > 4
    assert [(c.t, c.velocity) for c in tight.contacts] == \
        [(c.t, c.velocity) for c in roomy.contacts]
    # independent of the event list: onsets of the CONTACT flag, re-armed by the hysteresis
    below = tight.traces["position"] < 0.0
    onsets = np.flatnonzero(below[1:] & ~below[:-1]) + 1
    assert len(tight.contacts) <= onsets.size


def test_a_chattering_contact_is_said_and_an_ordinary_one_is_not():
    dev = SimDevice(seed=2)
    dev.load_scene(Scene("light", material=Material(1e7, mass=1e-3, support=Support(1e4))))
    dev.home()
    res = dev.run_window(0.3)
    assert any("chattered" in w for w in res.warnings), res.warnings
    dev.load_scene(Scene("foam", material=Material(220.0, 2.0)))
    dev.home()
    assert dev.run_window(1.0).warnings == []


def _sinusoid_peak(f, d):
    """The continuous peak of e^(−t/d)·sin(2πft), by hand: where its derivative is 0,
    tan(ωt) = ω·d."""
    w = 2 * math.pi * f
    t = math.atan(w * d) / w
    return math.exp(-t / d) * math.sin(w * t)


@pytest.mark.parametrize("ratio", [0.1, 0.2, 0.25, 1 / 3, 0.4, 0.45, 0.499])
@pytest.mark.parametrize("d", [0.005, 0.05])
def test_the_share_of_a_transients_peak_a_device_renders_is_measured(ratio, d):
    """By hand: the largest sample of e^(−n/(R·d))·sin(2π·ratio·n) against the continuous
    peak, times the hold's gain at the frequency, sin(π·ratio)/(π·ratio)."""
    rate = 10_000.0
    tr = ForceSinusoid(1.0, d, ratio * rate)
    n = np.arange(int(d * math.log(100) * rate) + 1)
    sampled = np.abs(np.exp(-n / rate / d) * np.sin(2 * np.pi * ratio * n)).max()
    hold = math.sin(math.pi * ratio) / (math.pi * ratio)
    assert tr.rendered_share(rate) == pytest.approx(
        sampled / _sinusoid_peak(ratio * rate, d) * hold, rel=1e-3)


def test_a_transient_near_nyquist_is_refused_and_one_that_loses_its_peak_is_warned():
    rate = 10_000.0
    near = ForceSinusoid(1.0, 0.005, 0.499 * rate)
    assert near.rendered_share(rate) < MIN_RENDERED
    with pytest.raises(SceneError, match="renders only") as err:
        near.check_for(rate)
    assert err.value.field == "frequency"
    third = ForceSinusoid(1.0, 0.05, rate / 3)
    third.check_for(rate)
    assert MIN_RENDERED <= third.rendered_share(rate) < WARN_RENDERED
    assert "72%" in third.rendering_note(rate)
    assert ForceSinusoid(1.0, 0.05, rate / 4).rendering_note(rate) is None
    assert Pulse(5.7, 0.01).rendering_note(rate) is None  # no frequency to lose
