"""The bridges to commercial devices (issue 31): the firmware's device core with its servo
I/O through a vendor's SDK, here built over hapticlab's stand-ins for the SDKs (libdhd at
4 kHz, the OpenHaptics HD scheduler at 1 kHz, the simulated plant behind both). What a lab
meets: the device self-test, a session, a device that has no accelerometer, and the
builds against an SDK that is not installed. The conformance suite, the state table and
the field ranges run on both bridges too (test_conformance.py, test_state_table.py,
test_contract.py).
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from device.scene import Scene
from device.serial import messages as M
from device.serial.backend import SerialDevice
from device.serial.firmware import FIRMWARE_DIR

from ..app.test_session import MINI
from ..conftest import start_emulator, stop_emulator
from .test_firmware import assert_selftest_passes

CLI = [sys.executable, "-m", "app"]
RATES = {"dhd-stub": 4000.0, "hd-stub": 1000.0}


@pytest.fixture(params=sorted(RATES))
def bridge(request):
    emu = start_emulator("--firmware", request.param, "--seed", "7")
    emu.kind = request.param
    yield emu
    stop_emulator(emu)
    # what the bridge said (its tick periods, control frames dropped, the SDK's errors):
    # pytest shows it under a failed test
    print(f"{request.param} stderr:\n{emu.stderr()}")


def test_every_fault_a_device_can_latch_is_told_in_words():
    """A commercial device's own safety (its force button, velocity and force limits, warm
    motors, a calibration it lacks) reaches the host as a fault of its own code, and the host
    says what each means; a code this host does not know is still said to be a fault."""
    from device.serial.backend import _FAULT_WHY
    from device.serial.contract import FAULTS

    assert set(FAULTS.values()) - {"estop"} == set(_FAULT_WHY)
    assert {5: "force_button", 6: "velocity_limit", 7: "force_limit", 8: "motor_heat",
            9: "calibration"}.items() <= FAULTS.items()  # appended: 1-4 keep their meaning
    assert "force button" in _FAULT_WHY["force_button"]
    assert "not calibrated" in _FAULT_WHY["calibration"]


@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.realtime
@pytest.mark.slow
def test_the_self_test_passes_on_each_bridge(bridge):
    assert_selftest_passes(bridge.port)


@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.realtime
@pytest.mark.slow
def test_the_hd_bridges_two_threads_share_nothing_unguarded():
    """The OpenHaptics bridge runs its tick in the scheduler's thread and its link in the
    main thread: under ThreadSanitizer the whole self-test (windows, playbacks, e-stop,
    watchdog, faults) runs with no data race reported."""
    emu = start_emulator("--firmware", "hd-stub-tsan", "--seed", "9")
    try:
        assert_selftest_passes(emu.port)
        emu.proc.send_signal(signal.SIGUSR1)  # the e-stop button: a signal on any thread
        time.sleep(0.2)
        emu.proc.send_signal(signal.SIGUSR2)
    finally:
        stop_emulator(emu)
        print(f"hd-stub-tsan stderr:\n{emu.stderr()}")  # shown under a failure
    # the whole of stderr: the program's last line comes after every report TSan prints
    deadline = time.monotonic() + 10
    while not any(" ticks, " in line for line in emu.stderr_lines) and time.monotonic() < deadline:
        time.sleep(0.05)
    races = [line for line in emu.stderr_lines if "ThreadSanitizer" in line]
    assert not races, emu.stderr()
    assert emu.proc.returncode == 0, emu.stderr()  # TSan exits 66 after a report
    assert "output off in its last frame" in emu.stderr()


@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.realtime
def test_a_bridge_says_its_rate_and_that_it_records_no_acceleration(bridge):
    """HELLO_ACK carries the bridge's servo rate and its model; LIMITS leaves the accel
    channel out (bit 5), so the host streams every other channel and a window's traces
    have no accel, rather than a column of zeros that would read as a still stylus."""
    with SerialDevice(bridge.port) as dev:
        assert dev.info.servo_rate_hz == RATES[bridge.kind]
        assert dev.info.model.startswith("hapticlab: ")
        # the device's own serial number, as its SDK tells it (the stand-ins make one of
        # their seed, 7), not the program's seed
        assert dev.info.serial_number == {"dhd-stub": "DHDSTUB-4007",
                                          "hd-stub": "HDSTUB-2205007"}[bridge.kind]
        assert dev.link.limits.channels & 0x7F == 0x7F & ~(1 << M.Channel.NAMES.index("accel"))
        dev.load_scene(Scene("firm", spring=680.0))
        dev.home()
        res = dev.run_window(0.5)
    assert "accel" not in res.traces
    assert {"position", "velocity", "force_cmd", "force_out", "current", "flags"} <= set(
        res.traces)
    # a record at every tick, for the window's 0.5 s from its first contact and before it
    assert res.rate_hz == RATES[bridge.kind]
    assert len(res.traces["t"]) >= 0.5 * RATES[bridge.kind]


@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.realtime
@pytest.mark.slow
def test_a_session_runs_over_each_bridge(bridge, tmp_path):
    """A whole session (three samples twice: a real block, a spring, a pulse) with the
    simulated participant, whose felt acceleration comes from the device's velocity where
    there is no accelerometer; the traces it keeps have no acceleration column."""
    proto = tmp_path / "mini.toml"
    proto.write_text(MINI)
    out = subprocess.run([*CLI, "run", str(proto), "--participant", "P31", "--seed", "4",
                          "--data", str(tmp_path), "--device", f"serial:{bridge.port}",
                          "--responder", "simulated", "--no-audio", "--quiet"],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    folder = tmp_path / "sub-P31" / "ses-1"
    from app.recorder import read_trials

    rows, _ = read_trials(folder / "trials.tsv")
    valid = [r for r in rows if r["status"] == "valid"]
    assert len(valid) == 6
    assert all(1 <= int(r["rating"]) <= 7 for r in valid)
    meta = json.loads((folder / "session.json").read_text())
    assert meta["device"]["servo_rate_hz"] == RATES[bridge.kind]
    assert meta["device"]["accelerometer"] is False
    # the achieved rate, as LIMITS reported it when the session opened the device: the
    # 99th percentile of the tick periods at or above the nominal period (a loop on this
    # computer's clock is never early by more than its clock's grain), the longest above it
    nominal = 1 / RATES[bridge.kind]
    assert meta["device"]["tick_p99_s"] >= 0.9 * nominal
    assert meta["device"]["tick_max_s"] >= meta["device"]["tick_p99_s"]
    traces = sorted((folder / "traces").glob("*.npz"))
    assert traces
    with np.load(traces[0]) as z:
        assert "accel_counts" not in z and "position_counts" in z
        assert float(z["rate_hz"]) == RATES[bridge.kind]


@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.realtime
@pytest.mark.slow
def test_a_library_build_on_a_bridge_is_refused_for_want_of_an_accelerometer(tmp_path):
    """Acceleration matching identifies the device from its accelerometer: on a device
    without one the build stops before it measures anything and says why."""
    emu = start_emulator("--firmware", "dhd-stub", "--seed", "8", "--speed", "4")
    try:
        out = subprocess.run([*CLI, "library", "build", "--device", f"serial:{emu.port}",
                              "--windows", "2", "--out", str(tmp_path / "wood.npz")],
                             capture_output=True, text=True, timeout=600)
    finally:
        stop_emulator(emu)
    assert out.returncode != 0
    assert "no accelerometer on the stylus" in out.stderr, out.stderr
    assert not (tmp_path / "wood.npz").exists()


@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.realtime
def test_the_hd_bridge_runs_in_real_time_only():
    run = subprocess.run([*CLI, "device", "emulate", "--firmware", "hd-stub", "--speed", "2"],
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 2 and "real time" in run.stderr and "--speed must be 1" in run.stderr


@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.realtime
@pytest.mark.parametrize(("target", "variable"), [("dhd", "DHD_SDK"), ("hd", "OPENHAPTICS")])
def test_a_build_against_an_sdk_that_is_not_there_says_what_it_needs(target, variable,
                                                                      tmp_path):
    """`make -C firmware dhd DHD_SDK=…` and `make -C firmware hd OPENHAPTICS=…` build the
    bridges against a lab's installed SDK; pointed at a folder without it, each stops
    before compiling and names the variable, the folder and the header it lacks (review
    r52 item 9: it used to say "needs DHD_SDK=…" as if none was given)."""
    run = subprocess.run(["make", "-C", str(FIRMWARE_DIR), target, f"{variable}={tmp_path}"],
                         capture_output=True, text=True, timeout=120)
    header = {"dhd": "include/dhdc.h", "hd": "include/HD/hd.h"}[target]
    assert run.returncode != 0
    assert f"make {target}: {variable}={tmp_path} does not hold {header}" in run.stdout


@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.realtime
@pytest.mark.slow
def test_validate_says_up_front_what_each_bridge_cannot_render(bridge):
    """`protocol validate --device`: the factorial's 300-Hz aluminum sets are 0.3 × a 1-kHz
    servo, played at about 80 % of their peak (a warning per set, naming the rate), and
    faithfully at 4 kHz (0.075 ×: no warning); the realism protocol's matched samples need
    libraries that only a device with an accelerometer can build: refused, saying so."""
    def validate(name):
        return subprocess.run([*CLI, "protocol", "validate", name, "--device",
                               f"serial:{bridge.port}"], capture_output=True, text=True,
                              timeout=300)

    fact = validate("factorial")
    assert fact.returncode == 0, fact.stderr
    warned = sorted(line.split("'")[1] for line in fact.stdout.splitlines()
                    if line.startswith("warning: sample"))
    if bridge.kind == "hd-stub":
        assert warned == ["aluminum-HHH", "aluminum-HHL", "aluminum-HLH", "aluminum-HLL"]
        assert "a device at 1000 Hz renders 8" in fact.stdout
    else:
        assert warned == []
    real = validate("realism")
    assert real.returncode == 2
    assert "has no accelerometer on the stylus, so no library can be built on it" in real.stderr
    assert "library build" not in real.stderr  # no command that would fail in its turn


@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.realtime
def test_realtime_is_asked_for_and_its_answer_said():
    """`--realtime` asks for SCHED_FIFO and locked memory: granted (as root, or with an
    rtprio limit) it says so, refused it says what it runs at and how to grant it; either
    way the servo runs (ticks counted at exit)."""
    binary = FIRMWARE_DIR / "build" / "hlfw-dhd-stub"
    proc = subprocess.Popen([str(binary), "--realtime"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    assert proc.stdout.readline().startswith("/dev/")
    time.sleep(1.0)
    proc.terminate()
    _, err = proc.communicate(timeout=30)
    granted = "real-time scheduling: SCHED_FIFO at priority 80" in err
    refused = "real-time scheduling not granted" in err and "rtprio" in err
    assert granted != refused, err
    m = re.search(r"hlfw-dhd-stub: (\d+) ticks,", err)
    assert m and int(m.group(1)) > 0, err


@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.realtime
@pytest.mark.parametrize(("scheduler", "link"), [(40, 20), (12, 11), (0, 0)])
def test_the_openhaptics_bridges_link_thread_runs_below_the_scheduler(scheduler, link,
                                                                      monkeypatch):
    """The HD scheduler's callback ticks on while the bridge's link thread is held up, so that
    thread asks for SCHED_FIFO, at the host link's priority (20) but always below the
    scheduler's own thread (whose priority the vendor sets: the stand-in asks for
    HL_STUB_HD_SCHED_PRIORITY), and at normal priority where the scheduler has none. Checked
    on the running process, thread by thread, with what it said on stderr."""
    monkeypatch.setenv("HL_STUB_HD_SCHED_PRIORITY", str(scheduler))
    binary = FIRMWARE_DIR / "build" / "hlfw-hd-stub"
    proc = subprocess.Popen([str(binary)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        assert proc.stdout.readline().startswith("/dev/")
        threads = {int(t): (os.sched_getscheduler(int(t)),
                            os.sched_getparam(int(t)).sched_priority)
                   for t in os.listdir(f"/proc/{proc.pid}/task")}
    finally:
        proc.terminate()
        _, err = proc.communicate(timeout=30)
    main = threads.pop(proc.pid)
    if "below the HD scheduler's" in err:  # real time granted (root, or an rtprio limit)
        assert main == (os.SCHED_FIFO, link), err
        assert (os.SCHED_FIFO, scheduler) in threads.values(), threads
        said = f"the link's thread at SCHED_FIFO {link}, below the HD scheduler's {scheduler}"
        assert said in err
    elif scheduler == 0 or "scheduler's thread runs at normal priority" in err:
        assert main[0] == os.SCHED_OTHER, err
        assert "stays at normal priority too, below it" in err
    else:
        assert "not granted to the link's thread" in err and "rtprio" in err, err
        assert main[0] == os.SCHED_OTHER, err


@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.realtime
@pytest.mark.parametrize("kind", sorted(RATES))
def test_a_device_that_stops_answering_latches_a_fault_and_output_goes_off(kind, monkeypatch):
    """A real device's cable pulled mid-window: the stand-in's position readings fail after
    2 s of its time (HL_STUB_FAIL_AFTER). The bridge never renders from a made-up height:
    it latches a `device` fault at the next tick, output goes to zero, the window ends, and
    the host says what happened in words."""
    monkeypatch.setenv("HL_STUB_FAIL_AFTER", "2")
    emu = start_emulator("--firmware", kind, "--seed", "10")
    try:
        with SerialDevice(emu.port) as dev:
            dev.load_scene(Scene("firm", spring=680.0))
            dev.home()
            res = dev.run_window(10.0, from_first_contact=False)
            assert [f.code for f in res.faults] == ["device"]
            assert res.traces["t"][-1] < 3.0  # ended at the fault, not after its 10 s
            assert dev.fault is not None and dev.fault.code == "device"
            assert "own I/O failed" in dev.fault.message
            assert dev.output_force == 0.0
    finally:
        stop_emulator(emu)
