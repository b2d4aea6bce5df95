"""A device's clock on the host's (issue 32): the mapping event markers stamp device events
with, against clocks whose truth the test knows."""

import time

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from device import open_device
from device.serial.backend import device_clock_on_host


def _frames(rng, offset, rate, n=200, span=10.0, floor=2e-4, mean=3e-3):
    """STATUS frames of a device whose time t happened at host time offset + rate·t: each
    stamped at a device time and received after a delay (at least ``floor`` [s], an
    exponential tail of mean ``mean`` [s] above it, as a serial link's queueing)."""
    t = np.sort(rng.uniform(0, span, n))
    delay = floor + rng.exponential(mean, n)
    return list(zip(offset + rate * t + delay, t, strict=True)), float(delay.min())


@given(seed=st.integers(0, 2**32 - 1), rate=st.floats(0.7, 1.3),
       offset=st.floats(-1e5, 1e5), rtt_extra=st.floats(0, 2e-3))
def test_a_straight_clock_is_mapped_within_its_uncertainty(seed, rate, offset, rtt_extra):
    """A device clock that runs straight at any rate (QEMU's ran at 0.71×): every time in
    the frames' span maps within the stated uncertainty, given a round trip whose two legs
    are each no faster than the fastest frame."""
    rng = np.random.default_rng(seed)
    pairs, fastest = _frames(rng, offset, rate)
    clock = device_clock_on_host(pairs, 2 * fastest + rtt_extra)
    for t in np.linspace(0, 10, 21):
        err = clock.on_host(t) - (offset + rate * t)
        assert abs(err) <= clock.uncertainty_s + 1e-9 * (1 + abs(offset)), (err, clock)
    assert clock.uncertainty_s < 0.005  # and the bound says something


def test_a_clock_that_stepped_widens_the_uncertainty_to_cover_the_step():
    """A simulated device that slipped 20 ms halfway: one line cannot follow it, and the
    stated uncertainty grows past half the step and holds at each quarter's fastest
    frame."""
    rng = np.random.default_rng(3)
    pairs, fastest = _frames(rng, 100.0, 1.0)
    stepped = [(h + (0.02 if t > 5 else 0.0), t) for h, t in pairs]
    clock = device_clock_on_host(stepped, 2 * fastest)
    straight = device_clock_on_host(pairs, 2 * fastest)
    assert clock.uncertainty_s > 0.01 > straight.uncertainty_s
    h, t = np.array(stepped).T
    lag = h - clock.rate * t
    for q in np.array_split(np.arange(len(t)), 4):
        i = q[np.argmin(lag[q])]
        truth = 100.0 + t[i] + (0.02 if t[i] > 5 else 0.0)
        assert abs(clock.on_host(t[i]) - truth) <= clock.uncertainty_s


def test_without_a_round_trip_the_uncertainty_is_unknown():
    pairs, _ = _frames(np.random.default_rng(1), 0.0, 1.0)
    assert device_clock_on_host(pairs, None).uncertainty_s == float("inf")


def test_a_simulated_device_in_virtual_time_has_no_host_clock():
    assert open_device("sim", seed=1).host_clock() is None


def test_a_live_simulated_device_puts_its_window_on_the_host_clock():
    """Paced to the wall clock, the simulated device's window lies between the call that
    started it and its return, within the stated uncertainty."""
    from device import Scene

    with open_device("sim", seed=2, live=True) as dev:
        dev.load_scene(Scene("spring", spring=340.0))
        dev.home()
        before = time.perf_counter()
        res = dev.run_window(0.3, timeout=5.0)
        after = time.perf_counter()
        t = res.traces["t"]
        clock = dev.host_clock((float(t[0]), float(t[-1])))
    assert clock is not None and clock.rate == 1.0
    assert before - clock.uncertainty_s <= clock.on_host(float(t[0]))
    assert clock.on_host(float(t[-1])) <= after + clock.uncertainty_s
