"""The speed-versus-accuracy benchmark's measuring parts (``hapticlab bench accuracy``):
that it compares the right samples, that a window compared with itself reads no error,
that a known error reads as itself, and that its summary picks the right rate."""

import math

import numpy as np
import pytest

from benchmarks import accuracy as acc
from device import Scene
from device.events import WindowResult


def test_the_reference_is_read_at_the_coarse_rates_own_tick_times():
    """A 100-kHz signal read at 1-kHz tick times (offset windows, as two runs start at
    different ticks) gives the signal at those times; a time it does not cover is NaN."""
    t_ref = 0.0123 + np.arange(20_000) / acc.REF_RATE
    ref = np.sin(2 * np.pi * 37.0 * t_ref)
    t = 0.013 + np.arange(300) / 1_000.0
    got = acc._on_ticks(t, t_ref, ref)
    inside = t <= t_ref[-1]
    assert np.allclose(got[inside], np.sin(2 * np.pi * 37.0 * t[inside]), atol=1e-12)
    assert np.all(np.isnan(got[~inside])) and (~inside).sum() > 0
    # a time between reference samples is not a tick of a rate dividing 100 kHz: refused
    assert np.isnan(acc._on_ticks(np.array([0.0123 + 0.3e-5]), t_ref, ref)[0])


def _result(t, accel, force, contacts=()):
    traces = {"t": t, "true_accel": accel, "force_out": force,
              "velocity": np.zeros_like(t), "accel": accel}
    return WindowResult(rate_hz=1.0 / (t[1] - t[0]), t_first_contact=None, traces=traces,
                        contacts=list(contacts))


def test_a_window_against_itself_reads_no_error_and_a_known_error_reads_as_itself():
    t = np.arange(1_000) / acc.REF_RATE
    a = np.sin(2 * np.pi * 500 * t) * np.exp(-50 * t)
    f = 2.0 * a
    ref = _result(t, a, f)
    same = acc.compare(ref, ref, real=False)
    assert same["accel_err"] == 0 and same["accel_peak_err"] == 0
    assert same["force_peak_err"] == 0
    # 10 % more acceleration, 5 % less force, read at 20 kHz
    t20 = t[::5]
    off = acc.compare(_result(t20, 1.1 * a[::5], 0.95 * f[::5]), ref, real=False)
    assert off["accel_err"] == pytest.approx(0.1, rel=1e-9)
    assert off["accel_peak_err"] == pytest.approx(0.1, rel=1e-9)
    assert off["force_peak_err"] == pytest.approx(-0.05, rel=1e-9)
    # nothing felt (no contact): the JND distance is undefined, not 0; a real sample has no
    # rendered force to compare
    assert math.isnan(off["jnd"])
    assert math.isnan(acc.compare(ref, ref, real=True)["force_peak_err"])


def test_the_summary_picks_the_lowest_rate_above_which_every_tap_stays_within_1_jnd():
    rows = [{"scene": "s", "rate_hz": r, "jnd": j} for r, j in [
        (1_000, 0.2), (2_000, 1.4), (4_000, 0.9), (5_000, 0.3), (10_000, 0.1),
        (20_000, 0.05)]]
    rows += [{"scene": "s", "rate_hz": 5_000, "jnd": 1.2}]  # another tap at 5 kHz
    # 1 kHz is within 1 JND by chance, but 2 and 5 kHz are not: the answer is 10 kHz
    assert acc.lowest_rate(rows, "s") == 10_000
    rows.append({"scene": "s", "rate_hz": 20_000, "jnd": math.nan})  # not felt at 20 kHz
    assert acc.lowest_rate(rows, "s") is None


@pytest.mark.slow
def test_a_spring_at_20_khz_is_felt_as_at_100_khz():
    """One real row, end to end: a 680-N/m spring tapped once at 0.11 m/s at 20 kHz against
    100 kHz. A spring's force is the held encoder reading times K, so its error falls with
    the tick; the participant model must not tell the two apart (< 0.5 JND)."""
    rows = acc.measure([("firm", Scene("firm", spring=680.0))], rates=(20_000,), taps=(0.11,),
                       repeats=1)
    (row,) = rows
    assert row["contacts"] == row["contacts_ref"] >= 1 and not row["faults"]
    assert row["jnd"] < 0.5 and abs(row["force_peak_err"]) < 0.01 and row["accel_err"] < 0.1
    assert row["realtime_factor"] > 0 and row["cost_vs_ref"] < 1.0
