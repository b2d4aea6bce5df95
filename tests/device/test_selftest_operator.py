"""The self-test on a device whose contact is physical (review r52 item 2): five checks need
someone to tap the stylus. The self-test says which, asks at the moment each window starts
waiting for contact, and reports a check nobody tapped for as failed by name, or, asked to
run the device-alone checks only, as not run; never as passed.

Here in process, over the simulated device declaring a physical contact (its simulated hand
taps, as a person would when asked), with a few of the checks to stay cheap; over a real
device's bridge built against the Force Dimension stand-in, with the test as the operator,
in tests/device/test_bridge_sdk.py.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import device.registry
from app.api import device_selftest
from device import suite
from device.sim.backend import SimDevice
from device.sim.tapper import HoldPlan, Tapper

# two checks the device does alone, two that need the stylus tapped (cheap ones of each)
SOME = ("spring_law", "ramp", "window_length", "bad_input")
ALL = dict(suite.CHECKS)


class PhysicalSim(SimDevice):
    """A device that says its contact is physical, simulated underneath; its windows are
    written in the same log as what the self-test says, to see when each prompt comes."""

    log: list[str] = []

    def __init__(self, **options):
        super().__init__(**options)
        self._info = dataclasses.replace(self._info, backend="bench", simulated_contact=False,
                                         seeded=False, virtual_time=False)

    def run_window(self, duration=5.0, **kw):
        res = super().run_window(duration, **kw)
        waits = kw.get("from_first_contact", True) and kw.get("on_progress") is None
        self.log.append(f"window {kw.get('timeout', 30.0):g}"
                        + (" waiting for a contact" if waits else ""))
        return res


@dataclasses.dataclass(frozen=True)
class Hovers(Tapper):
    """A hand that holds the stylus still at the top of its stroke, above the surface: the
    operator between prompts, or one who never taps when asked."""

    def plan(self, rng, duration, surface_height=0.0, speeds=None):
        return HoldPlan(surface_height + self.top)


class HoveringBench(PhysicalSim):
    """``bench`` held still above the surface throughout."""

    def __init__(self, **options):
        super().__init__(**options)
        self.tapper = self._base_tapper = Hovers()


class Unpowered(HoveringBench):
    """``bench`` with its amplifier off (every force it is asked to play comes out as
    none), held above the surface: a device that never puts out force."""

    def _play_force(self, f, heartbeats, on_progress=None):
        return super()._play_force(np.zeros_like(f), heartbeats, on_progress)


SAFETY = ("estop", "watchdog", "zero_on_exit")


@pytest.fixture
def bench(monkeypatch):
    """``bench``, a physical device, registered for this test with a few of the checks."""
    monkeypatch.setitem(device.registry._REGISTERED, "bench", PhysicalSim)
    monkeypatch.setattr(suite, "CHECKS", {n: ALL[n] for n in SOME})
    PhysicalSim.log = []
    return PhysicalSim.log


def test_a_physical_device_says_which_checks_need_a_tap_and_asks_at_each_window(bench):
    report = device_selftest("bench", say=bench.append, tap_wait_s=12.0)
    assert report["passed"] == 4 and report["failed"] == report["not_run"] == 0, report
    plan = bench[0]
    assert ("2 checks the device does alone (ramp, bad_input); 2 need someone to tap the "
            "stylus (spring_law, window_length): you will be asked at each") in plan, plan
    for name in ("spring_law", "window_length"):
        asked = bench.index(f"[{name}] tap the stylus down onto the virtual surface now, and "
                            "keep tapping until told to stop (waiting up to 12 s for contact)")
        # the prompt comes as the window starts waiting, the end of the taps after it
        assert bench[asked + 1] == "window 12 waiting for a contact", bench
        assert bench[asked + 2].startswith(f"[{name}] contact: window recorded; stop tapping")
    assert sum("tap the stylus down" in line for line in bench) == 2  # not for ramp, bad_input


def test_device_alone_reports_the_tapped_checks_not_run_never_passed(bench):
    report = device_selftest("bench", say=bench.append, device_alone=True)
    rows = {r["name"]: r for r in report["checks"]}
    assert (report["passed"], report["failed"], report["not_run"]) == (2, 0, 2)
    for name in ("spring_law", "window_length"):
        assert rows[name]["status"] == "not run" and rows[name]["ok"] is False
    assert "2 need someone to tap the stylus (spring_law, window_length): not run" in bench[0]
    assert not any("tap the stylus down" in line for line in bench)


def test_a_simulated_contact_is_not_asked_for(monkeypatch):
    """The simulated device's hand taps by itself: no plan, no prompt, as before."""
    said: list[str] = []
    monkeypatch.setattr(suite, "CHECKS", {"window_length": ALL["window_length"]})
    report = device_selftest("sim", say=said.append)
    assert report["passed"] == 1 and said == []


def test_a_wait_for_a_tap_must_be_positive():
    with pytest.raises(ValueError, match="positive number of seconds"):
        suite.Operator(print, float("nan"))


def test_the_checks_a_device_does_alone_never_wait_for_a_contact(monkeypatch, bench):
    """Two of them once ran a window from the first contact, each waiting 30 s on a device
    nobody taps (the e-stop's window after clearing, the exit's): a minute of silence for
    an operator told to hold the stylus still."""
    alone = ("estop", "end_window", "watchdog", "zero_on_exit", "bad_input")
    monkeypatch.setattr(suite, "CHECKS", {n: ALL[n] for n in alone})
    report = device_selftest("bench", say=bench.append)
    assert report["passed"] == len(alone), report
    windows = [line for line in bench if line.startswith("window")]
    assert windows and not any("waiting for a contact" in w for w in windows), windows


def test_the_command_counts_not_run_apart_and_exits_1(bench, capsys, monkeypatch):
    """`hapticlab device selftest --device-alone` on a physical device: the table marks the
    tapped checks *not run*, the summary counts them apart, and only 13 of 13 passed exits
    0 (a script reading the status cannot take a partial run for a whole one)."""
    from app.cli import main

    monkeypatch.setenv("COLUMNS", "300")
    assert main(["device", "selftest", "bench", "--device-alone"]) == 1
    out = capsys.readouterr()
    assert "2 passed, 0 failed, 2 not run (they need someone to tap the stylus: run without " \
           "--device-alone)" in out.out, out.out
    rows = [line for line in out.out.splitlines() if "│ spring_law " in line]
    assert len(rows) == 1 and "not run" in rows[0], out.out
    assert "2 need someone to tap the stylus (spring_law, window_length): not run" in out.err
    assert main(["device", "selftest", "bench", "--tap-wait", "0"]) == 2
    assert "--tap-wait must be a positive number of seconds" in capsys.readouterr().err


def test_a_check_of_output_cut_fails_by_name_when_there_was_no_output_to_cut(monkeypatch):
    """Review final item 1: the e-stop, watchdog and exit checks once ran windows with the
    stylus held above the surface, where no force is commanded, so "current zero after the
    e-stop" held before it too and could not fail. Each now requires force put out just
    before its event: a device that never puts any out fails them by name."""
    monkeypatch.setattr(suite, "CHECKS", {n: ALL[n] for n in SAFETY})
    report = suite.run_selftest("unpowered", lambda: Unpowered(seed=5))
    rows = {r["name"]: r for r in report["checks"]}
    assert report["failed"] == 3, report
    for name, event in zip(SAFETY, ("e-stop", "watchdog trip", "exit"), strict=True):
        assert f"no force was being output before the {event}: nothing shown" in \
            rows[name]["detail"], rows[name]


@pytest.mark.parametrize("rate_hz", [1000, 4000, 10_000])
def test_the_force_the_safety_checks_cut_shows_in_every_report_of_it(rate_hz):
    """Review r60 item 1: the e-stop and exit checks failed on the board build and the
    Force Dimension bridge with "the device reported none". Their force was a zero-mean
    100-Hz cosine, and the reference firmware reports its output at 40 Hz, every 2.5
    periods: one |phase| at every report, exactly 0 mN for 2 starts in 100 at 10 kHz. Now,
    whatever tick the playback starts on, every 40-Hz report of it (rounded to the wire's
    mN) shows force, the stated 0.5 N; and the force has no mean, which would push the
    held stylus (a 0.1–0.5-N force left it moving into the play_force check)."""
    dev = dataclasses.make_dataclass("D", ["info"])(
        dataclasses.make_dataclass("I", ["servo_rate_hz"])(rate_hz))
    f = suite._force_to_cut(dev, 1.5)
    every = rate_hz // 40  # the firmware's REPORT_TICKS
    for start in range(every):
        reported = np.round(np.abs(f[start::every]) * 1000)  # output_mn
        assert reported.min() >= 1, (start, reported.min())
    assert np.allclose(np.abs(f), 0.5, rtol=1e-9)
    assert abs(f.mean()) <= 0.5 * every / f.size  # whole periods, at most a part of one


def test_the_safety_checks_cut_a_played_force_with_the_stylus_held_above_the_surface(
        monkeypatch):
    """What a physical device's operator does during them (hold the stylus still above
    the surface): the device plays a small force in free air, and each check cuts it."""
    monkeypatch.setattr(suite, "CHECKS", {n: ALL[n] for n in SAFETY})
    report = suite.run_selftest("bench", lambda: HoveringBench(seed=5))
    assert report["passed"] == 3, report
    for row in report["checks"]:
        assert "0.50 N" in row["detail"], row  # the force that was there to cut


def test_a_tap_never_given_gives_up_by_name_in_device_time(monkeypatch):
    """Review final item 2: the gave-up path without a deadline on the host: in process,
    in the simulated device's own time, a hand that never taps and a 0.5-s wait. The
    saturation check warns of its hard pulse before it asks."""
    monkeypatch.setitem(device.registry._REGISTERED, "bench", HoveringBench)
    monkeypatch.setattr(suite, "CHECKS", {"saturation": ALL["saturation"]})
    said: list[str] = []
    report = device_selftest("bench", say=said.append, tap_wait_s=0.5)
    assert (report["passed"], report["failed"]) == (0, 1), report
    assert report["checks"][0]["detail"] == ("CheckFailed: no contact within 0.5 s of the "
                                             "prompt to tap the stylus: gave up waiting")
    warn = said.index("[saturation] warning: " + suite.Operator.WARNINGS["saturation"])
    assert "a hard pulse is coming" in said[warn]
    assert said[warn + 1].startswith("[saturation] tap the stylus down onto the virtual "
                                     "surface now"), said
    assert said[warn + 2].startswith("[saturation] no contact in 0.5 s: gave up waiting")


def test_device_alone_on_a_simulated_contact_is_ignored_with_a_sentence(monkeypatch):
    """Review final item 11: its simulated hand taps by itself, so nothing is left out
    (it once reported the tapped checks not run)."""
    monkeypatch.setattr(suite, "CHECKS", {"window_length": ALL["window_length"]})
    said: list[str] = []
    report = device_selftest("sim", say=said.append, device_alone=True)
    assert (report["passed"], report["not_run"]) == (1, 0), report
    assert said == ["--device-alone ignored: sim's contact is simulated, its simulated hand "
                    "taps the stylus in every check, so all of them run"]
