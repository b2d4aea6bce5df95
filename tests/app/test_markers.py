"""Event markers on Lab Streaming Layer (issue 32): what the runner marks, and the markers a
pylsl inlet receives against what the session recorded.

liblsl is loaded only inside a network namespace with loopback alone
(tools/private_net.py); this process never loads it (conftest sets HAPTICLAB_LSL_PRIVATE,
and a test checks it is refused here).
"""

import datetime as dt
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from analysis.session_format import read_trials
from app.markers import EVENTS, MarkerSink

from ..conftest import PRIVATE_NET, ROOT, private_net_problem, start_emulator, stop_emulator
from .test_session import MINI

CLI = [sys.executable, "-m", "app"]
RECEIVE = [sys.executable, str(ROOT / "tests" / "app" / "lsl_receive.py")]


def _needs_private_net():
    if (why := private_net_problem()) is not None:
        pytest.skip(f"no private network namespace here, so liblsl is not loaded: {why}")


class Recorded(MarkerSink):
    """The markers the runner sends, kept in a list (the base's own extension point: what
    an LSL outlet would be given, without liblsl)."""

    active = True

    def __init__(self):
        super().__init__()
        self.markers: list[tuple[float, dict]] = []

    def _push(self, text: str, stamp: float) -> None:
        self.markers.append((stamp, json.loads(text)))


@pytest.mark.integration
def test_the_private_network_has_loopback_alone_before_liblsl_is_loaded():
    """The wrapper's command sees loopback alone, up, and liblsl's configuration of the
    project's; the wrapper refuses to run a command in a namespace that has more."""
    _needs_private_net()
    probe = ("import os, socket, sys; from app.markers import private_network_problem; "
             "print(private_network_problem(), sorted(n for _, n in socket.if_nameindex()), "
             "'pylsl' in sys.modules, os.environ['LSLAPICFG'])")
    out = subprocess.run([*PRIVATE_NET, sys.executable, "-c", probe], capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["None", "['lo']", "False",
                                  str(ROOT / "app" / "data" / "lsl_machine.cfg")]
    import socket

    if [n for _, n in socket.if_nameindex() if n != "lo"]:  # this namespace has more
        out = subprocess.run([*PRIVATE_NET, "true"], capture_output=True, text=True,
                             env={"_HAPTICLAB_PRIVATE_NET": "1", "PATH": "/usr/bin:/bin"},
                             timeout=60)
        assert out.returncode == 2
        assert "refusing to run true" in out.stderr and "besides loopback" in out.stderr


def test_lsl_is_refused_outside_a_private_network_before_liblsl_loads():
    """With HAPTICLAB_LSL_PRIVATE=1 (as in every test) an outlet outside a private network
    is refused with the reason, and liblsl is never loaded."""
    from app.markers import LslMarkers, LslUnavailable, private_network_problem

    if private_network_problem() is None:
        pytest.skip("this process is itself in a private network")
    with pytest.raises(LslUnavailable, match="not in a private network .*besides loopback"):
        LslMarkers("hapticlab markers", "test", {})
    assert "pylsl" not in sys.modules


_OUTLET_AND_INLET = """
import pylsl
out = pylsl.StreamOutlet(pylsl.StreamInfo("probe", "Markers", 1, 0, pylsl.cf_string, "p"))
found = pylsl.resolve_byprop("name", "probe", timeout=10)
inlet = pylsl.StreamInlet(found[0])
inlet.open_stream(timeout=10)
out.push_sample(["x"])
assert inlet.pull_sample(timeout=10)[0] == ["x"]
"""


def _destinations(log: Path) -> set[str]:
    text = log.read_text()
    return set(re.findall(r'inet_addr\("([0-9.]+)"\)', text)) | set(
        re.findall(r'inet_pton\(AF_INET6, "([0-9a-f:]+)"', text))


@pytest.mark.integration
@pytest.mark.skipif(shutil.which("strace") is None, reason="needs strace (make test installs "
                    "it)")
def test_liblsl_with_the_projects_configuration_sends_to_loopback_alone(tmp_path):
    """Every address liblsl sends to or connects to, as the kernel saw the calls (strace),
    while an outlet is found and read: loopback alone. liblsl's defaults would send to
    224.0.0.1, 224.0.0.183, 239.255.172.215, 255.255.255.255 and two IPv6 groups (seen
    once inside the private network, which drops them; not rerun, since liblsl loads only
    with the project's configuration)."""
    _needs_private_net()
    log = tmp_path / "lsl.strace"
    out = subprocess.run([*PRIVATE_NET, "strace", "-f", "-qq", "-o", str(log), "-e",
                          "trace=sendto,sendmsg,connect", sys.executable, "-c",
                          _OUTLET_AND_INLET], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    seen = _destinations(log)
    assert seen == {"127.0.0.1"}, seen


def _estop_after_first_tap():
    from app.participants import ScriptedResponder

    class EstopsAfterATap(ScriptedResponder):
        """Presses the e-stop in the second window, once a tap was felt."""

        def __init__(self):
            super().__init__()
            self.windows, self.device = 0, None

        def before_window(self, trial, sample_id, device, rng):
            self.windows, self.device = self.windows + 1, device

        def progress(self, t, partial, duration):
            if self.windows == 2 and self.device.fault is None and partial.contacts:
                self.device.estop()

    return EstopsAfterATap()


def test_an_estop_is_marked_at_the_device_time_it_zeroed_output(tmp_path):
    """An e-stop in a window: its marker among the window's device events at the device's
    time (after the tap that set it off), and the attempt's end says it was aborted; an
    attempt that then meets the latched fault ends unrecorded and says so; an e-stop
    latched between trials is marked when the runner meets it."""
    from app.recorder import SessionFiles, new_session_dir
    from app.runner import SessionInterrupted, SessionRunner
    from device import open_device
    from protocols import SessionEngine, parse_protocol

    p = parse_protocol(MINI, "mini.toml")
    folder, _ = new_session_dir(tmp_path, "P01")
    files = SessionFiles(folder)
    files.start(MINI)
    dev = open_device("sim", seed=4)
    sink = Recorded()
    runner = SessionRunner(protocol=p, engine=SessionEngine(p, 4, "P01"), device=dev,
                           files=files, responder=_estop_after_first_tap(),
                           participant="P01", session=1, seed=4, traces="full", markers=sink)
    runner._attempt(runner.engine.next_trial(runner.log))  # window 1: no e-stop
    with pytest.raises(SessionInterrupted, match="estop"):
        runner._attempt(runner.engine.next_trial(runner.log))
    second = [m for _, m in sink.markers if m.get("trial") == 2]
    events = [m["event"] for m in second]
    assert events[:4] == ["trial_start", "homed", "window_start", "first_contact"]
    assert events[-1] == "trial_end" and events.count("estop") == 1
    # the device's events in its time order (the stylus may touch again with output off)
    device = second[2:-1]
    assert [m["t_device_s"] for m in device] == sorted(m["t_device_s"] for m in device)
    (estop,) = [m for m in device if m["event"] == "estop"]
    taps = [m for m in device if m["event"] == "tap"]
    assert taps[0]["t_device_s"] <= estop["t_device_s"] <= device[-1]["t_device_s"]
    assert estop["code"] == "estop"
    assert second[-1]["status"] == "aborted_device"
    assert second[-1]["reason"].startswith("estop")
    (row,) = [r for r in read_trials(folder / "trials.tsv")[0] if r["trial_index"] == "2"]
    assert ";".join(f"{t['speed_m_s']:.5f}" for t in taps) == row["tap_velocities"]
    # the fault stays latched: the next attempt meets it before its window, ends without
    # a row and says so; the fault was marked once, when it happened
    n = len(sink.markers)
    with pytest.raises(SessionInterrupted):
        runner._attempt(runner.engine.next_trial(runner.log))
    assert [m["event"] for _, m in sink.markers[n:]] == ["trial_start", "trial_end"]
    assert sink.markers[-1][1]["status"] == "not_recorded"
    assert "fault latched" in sink.markers[-1][1]["reason"]
    # a fault first met between trials is marked when the runner meets it
    dev.clear_fault()
    dev.estop()
    n = len(sink.markers)
    with pytest.raises(SessionInterrupted):
        runner._attempt(runner.engine.next_trial(runner.log))
    assert [m["event"] for _, m in sink.markers[n:]] == ["trial_start", "estop", "trial_end"]
    assert all(m["event"] in EVENTS for _, m in sink.markers)


def _utc(text: str) -> float:
    return dt.datetime.fromisoformat(text).timestamp()


@pytest.mark.realtime
@pytest.mark.integration
@pytest.mark.slow
def test_markers_a_pylsl_inlet_receives_line_up_with_the_recorded_session(tmp_path):
    """The mini protocol with the simulated participant over the serial link to the device
    emulator, first without a recorder (the session stops before its first trial, to be
    resumed), then resumed while a pylsl inlet receives the markers. Against trials.tsv,
    the traces and session.json: every attempt's markers in order, each tap's speed, the
    ratings and statuses, and every marker within its attempt's recorded times on the UTC
    clock, mapped through the clock pairs session.json keeps."""
    _needs_private_net()
    proto = tmp_path / "mini.toml"
    proto.write_text(MINI)
    emu = start_emulator("--seed", "12")
    try:
        base = ["--lsl", "--no-audio", "--quiet"]
        out = subprocess.run([*PRIVATE_NET, *CLI, "run", str(proto), "--participant", "P32",
                              "--seed", "6", "--data", str(tmp_path), "--device",
                              f"serial:{emu.port}", "--responder", "simulated", *base,
                              "--lsl-wait", "1"], capture_output=True, text=True, timeout=300)
        assert out.returncode == 3, out.stderr
        assert "no recorder received the LSL markers within 1 s" in out.stderr
        folder = tmp_path / "sub-P32" / "ses-1"
        assert f"hapticlab resume {folder} --lsl" in out.stderr
        got = tmp_path / "received.json"
        out = subprocess.run([*PRIVATE_NET, *RECEIVE, str(got), *CLI, "resume", str(folder),
                              *base, "--lsl-wait", "120"], capture_output=True, text=True,
                             timeout=900)
        assert out.returncode == 0, out.stderr
    finally:
        stop_emulator(emu)
    received = json.loads(got.read_text())
    assert received["returncode"] == 0, received["stderr"]
    markers = [(s, json.loads(t), r) for s, t, r in received["markers"]]
    assert markers, received["stderr"]
    meta = json.loads((folder / "session.json").read_text())
    lsl = meta["lsl"]
    assert lsl["stream"]["source_id"] == "hapticlab:mini:sub-P32:seed-6"
    first, run = lsl["runs"]  # the run no recorder received, then the resume
    assert first["markers_sent"] == 1 and not first["windows"]
    assert run["markers_sent"] == len(markers)
    assert [m["event"] for _, m, _ in markers[:1] + markers[-1:]] == ["session_start",
                                                                      "session_end"]
    assert markers[-1][1]["status"] == "complete"
    # a marker is never stamped after it was received (device events are sent when their
    # window ends, stamped with when they happened)
    assert all(s <= r for s, _, r in markers)

    # the UTC wall clock on the LSL clock, from the pairs at the run's start and end
    (w0, w1) = run["wall"]
    slope = (w1["lsl_s"] - w0["lsl_s"]) / (_utc(w1["utc"]) - _utc(w0["utc"]))
    assert abs(slope - 1) < 1e-3  # the two clocks tick alike (NTP slews by < 500 ppm)

    def on_lsl(utc: str) -> float:
        return w0["lsl_s"] + (_utc(utc) - _utc(w0["utc"]))

    rows, _ = read_trials(folder / "trials.tsv")
    assert len(rows) == 6 and all(r["status"] == "valid" for r in rows)
    windows = {(w["trial"], w["window"]): w for w in run["windows"]}
    for row in rows:
        mine = [(s, m) for s, m, _ in markers if m.get("trial") == int(row["trial_index"])]
        events = [m["event"] for _, m in mine]
        n_taps = int(row["n_taps"])
        assert events == ["trial_start", "homed", "window_start", "first_contact",
                          *["tap"] * n_taps, "rating_onset", "response", "trial_end"], row
        assert all(m["item"] == row["item"] and m["attempt"] == int(row["attempt"])
                   for _, m in mine)
        taps = [m for _, m in mine if m["event"] == "tap"]
        assert ";".join(f"{t['speed_m_s']:.5f}" for t in taps) == row["tap_velocities"]
        with np.load(folder / row["trace_file"]) as z:  # the device's own record
            np.testing.assert_allclose([t["t_device_s"] for t in taps], z["contacts_t"],
                                       atol=1e-6)
            t0 = float(z["t0"])
        assert mine[3][1]["t_device_s"] == pytest.approx(taps[0]["t_device_s"], abs=1e-6)
        (resp,) = [m for _, m in mine if m["event"] == "response"]
        assert resp["rating"] == int(row["rating"])
        assert mine[-1][1]["status"] == row["status"]
        w = windows[(int(row["trial_index"]), 0)]
        assert w["t0_device_s"] == pytest.approx(t0, abs=1e-6)
        unc = w["uncertainty_s"]
        assert unc is not None and 0 < unc < 1.0, w
        assert w["frames"] >= 4 and w["round_trip_s"] > 0
        assert mine[2][0] == pytest.approx(w["t0_lsl_s"], abs=1e-6)
        # in time order within the clocks' uncertainty: host events bracket the device's
        stamps = [s for s, _ in mine]
        assert stamps[0] <= stamps[1] <= stamps[2] + unc
        assert all(a <= b + 1e-9 for a, b in zip(stamps[2:-3], stamps[3:-2], strict=True))
        assert stamps[-4] - unc <= stamps[-3] <= stamps[-2] <= stamps[-1]
        # taps on the LSL clock where the device's clock puts them (its rate)
        for t in taps:
            (s,) = [s for s, m in mine if m is t]
            assert s - mine[2][0] == pytest.approx((t["t_device_s"] - t0) * w["rate"],
                                                   abs=1e-6)
        # within the attempt's recorded UTC times (written to the millisecond, truncated)
        start, end = on_lsl(row["t_start"]), on_lsl(row["t_end"]) + 1e-3
        pad = w0["uncertainty_s"] + w1["uncertainty_s"] + 1e-3
        assert start - pad <= stamps[0] and stamps[-2] <= end + pad
        assert start - pad - unc <= stamps[2] and stamps[-4] <= end + pad + unc
        assert stamps[-1] >= end - 1e-3 - pad  # trial_end: after the row was written


@pytest.mark.integration
def test_a_session_that_cannot_send_markers_stops_before_its_folder(tmp_path):
    """Outside a private network (where the tests require one) --lsl is refused in one
    line before the device opens, and no session folder is left behind to trip the
    participant's next run."""
    proto = tmp_path / "mini.toml"
    proto.write_text(MINI)
    from app.markers import private_network_problem

    if private_network_problem() is None:
        pytest.skip("this process is itself in a private network")
    out = subprocess.run([*CLI, "run", str(proto), "--participant", "P33", "--dry-run",
                          "--data", str(tmp_path / "data"), "--lsl", "--no-audio", "--quiet"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 2
    assert "not in a private network" in out.stderr and "Traceback" not in out.stderr
    assert not (tmp_path / "data" / "sub-P33").exists()


@pytest.mark.integration
def test_ctrl_c_while_waiting_for_a_recorder_stops_cleanly(tmp_path):
    """SIGTERM during the wait for a recorder acts at once (the wait polls), and the
    session is recorded as stopped with its LSL run, resumable."""
    _needs_private_net()
    import signal
    import time

    proto = tmp_path / "mini.toml"
    proto.write_text(MINI)
    err = tmp_path / "stderr.txt"
    with open(err, "w") as f:
        proc = subprocess.Popen([*PRIVATE_NET, *CLI, "run", str(proto), "--participant", "P34",
                                 "--dry-run", "--data", str(tmp_path), "--lsl", "--lsl-wait",
                                 "120", "--no-audio"], stderr=f, stdout=subprocess.DEVNULL)
    try:
        end = time.monotonic() + 100
        while "LSL: waiting" not in err.read_text() and time.monotonic() < end:
            assert proc.poll() is None, err.read_text()
            time.sleep(0.1)
        proc.send_signal(signal.SIGTERM)  # unshare execs: the PID is hapticlab's
        rc = proc.wait(timeout=60)  # well before the 120-s wait would end
    finally:
        if proc.poll() is None:
            proc.kill()
    assert rc == 130, err.read_text()
    meta = json.loads((tmp_path / "sub-P34" / "ses-1" / "session.json").read_text())
    assert meta["status"] == "interrupted"
    assert meta["interruptions"] == ["stopped (Terminated)"]
    (run,) = meta["lsl"]["runs"]
    assert len(run["wall"]) == 2 and run["markers_sent"] == 1  # its session_end
    assert not read_trials(tmp_path / "sub-P34" / "ses-1" / "trials.tsv")[0]


def test_a_marker_that_cannot_be_sent_never_stops_the_session(tmp_path):
    """A sink whose every send fails: the attempts run and are recorded, the operator is
    told once, and the run's record counts what was lost; a value that is not a finite
    number goes as null."""
    from app.participants import ScriptedResponder
    from app.recorder import SessionFiles, new_session_dir
    from app.runner import SessionRunner
    from device import open_device
    from protocols import SessionEngine, parse_protocol

    said = []

    class Broken(Recorded):
        def _push(self, text, stamp):
            raise OSError("no route")

    p = parse_protocol(MINI, "mini.toml")
    folder, _ = new_session_dir(tmp_path, "P01")
    files = SessionFiles(folder)
    files.start(MINI)
    sink = Broken()
    sink._say = said.append
    runner = SessionRunner(protocol=p, engine=SessionEngine(p, 4, "P01"),
                           device=open_device("sim", seed=4), files=files,
                           responder=ScriptedResponder(), participant="P01", session=1,
                           seed=4, traces="none", markers=sink)
    for _ in range(2):
        runner._attempt(runner.engine.next_trial(runner.log))
    assert len(read_trials(folder / "trials.tsv")[0]) == 2
    assert len(said) == 1 and "could not be sent" in said[0]
    assert sink.run["send_failures"] >= 2 * 6 and sink.sent == 0
    ok = Recorded()
    ok.send("response", rating=3, response_time_s=float("nan"))
    assert ok.markers[0][1] == {"event": "response", "rating": 3, "response_time_s": None}


def test_a_fault_its_window_marked_is_not_marked_again_when_the_runner_meets_it():
    from device import FaultEvent, WindowResult

    sink = Recorded()
    f = FaultEvent(1.25, "estop", "operator")
    res = WindowResult(1000.0, None, faults=[f])

    class NoClock:
        def host_clock(self, span=None):
            return None

    sink.window(res, NoClock(), window=0)
    sink.fault(f)  # the pause that follows the window
    sink.fault(FaultEvent(3.0, "watchdog", "no heartbeat"))  # a later one
    assert [(m["event"], m.get("code")) for _, m in sink.markers] == [
        ("estop", "estop"), ("fault", "watchdog")]
