"""The plugin from Coder: the shipped example as a user runs it, its LSL markers received by a
pylsl inlet in a private network (the same trial ids as the data rows), SIGTERM closing the
device, and the device's own e-stop button on the reference firmware over a pty."""

import json
import os
import signal
import subprocess
import sys
import time

import pandas as pd
import pytest

from ..conftest import PRIVATE_NET, ROOT, private_net_problem

pytestmark = [pytest.mark.integration]

EXAMPLE = ROOT / "plugins" / "psychopy-hapticlab" / "psychopy_hapticlab" / "examples" \
    / "coder_contact.py"
RECEIVE = [sys.executable, str(ROOT / "tests" / "app" / "lsl_receive.py")]


def test_the_coder_example_runs_and_writes_its_rows(tmp_path):
    out = subprocess.run([sys.executable, str(EXAMPLE), "--data", str(tmp_path)],
                         capture_output=True, text=True, timeout=120,
                         env={**os.environ, "HOME": str(tmp_path)})
    assert out.returncode == 0, out.stderr
    lines = [ln for ln in out.stdout.splitlines() if " Hz: trial " in ln]
    assert [ln.split(",")[0] for ln in lines] == ["100 Hz: trial 0", "66.7 Hz: trial 1"]
    assert out.stdout.count("<ContactResponse from hapticlab") >= 2
    d = pd.read_csv(tmp_path / "coder_contact.csv")
    assert d["tap.trial_id"].tolist() == [0, 1] and (d["tap.status"] == "valid").all()
    assert all((tmp_path / f).is_file() for f in d["tap.trace_file"])


def test_lsl_markers_carry_the_data_rows_trial_ids(tmp_path):
    """The Coder example with LSL markers, received by a pylsl inlet inside a network
    namespace with loopback alone: each routine's markers carry its row's trial id, the tap
    markers the row's speeds, and trial_end the row's status and trace file."""
    if (why := private_net_problem()) is not None:
        pytest.skip(f"no private network namespace here, so liblsl is not loaded: {why}")
    got = tmp_path / "received.json"
    out = subprocess.run([*PRIVATE_NET, *RECEIVE, str(got), sys.executable, str(EXAMPLE),
                          "--lsl", "--data", str(tmp_path)], capture_output=True, text=True,
                         timeout=300, env={**os.environ, "HOME": str(tmp_path)})
    assert out.returncode == 0, out.stderr
    received = json.loads(got.read_text())
    assert received["returncode"] == 0, received["stderr"]
    markers = [json.loads(text) for _, text, _ in received["markers"]]
    events = [m["event"] for m in markers]
    assert events[0] == "session_start" and events[-1] == "session_end"
    d = pd.read_csv(tmp_path / "coder_contact.csv")
    for _, row in d.iterrows():
        mine = [m for m in markers if m.get("trial") == row["tap.trial_id"]]
        kinds = [m["event"] for m in mine]
        assert kinds[:3] == ["trial_start", "homed", "window_start"] and kinds[-1] == "trial_end"
        taps = [m["speed_m_s"] for m in mine if m["event"] == "tap"]
        assert taps == pytest.approx(json.loads(row["tap.speeds"]), abs=1e-5)
        end = mine[-1]
        assert (end["status"], end["trace_file"]) == (row["tap.status"], row["tap.trace_file"])
    # a marker is never stamped after it was received
    assert all(s <= r for s, _, r in received["markers"])


SIGTERM_SCRIPT = """
import time
from psychopy import logging
logging.console.setLevel(logging.EXP)
from psychopy.hardware import DeviceManager
from psychopy_hapticlab.scenes import fields_scene
dev = DeviceManager.addDevice("hapticlab", "haptic", spec="sim", live=True, label="haptic")
dev.prepare(fields_scene("spring", 400.0, "none"))
dev.startWindow(60.0, fromFirstContact=False)
print("window running", flush=True)
while True:
    time.sleep(0.05)
"""


def test_sigterm_mid_window_closes_the_device_with_zero_output(tmp_path):
    proc = subprocess.Popen([sys.executable, "-c", SIGTERM_SCRIPT], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=tmp_path,
                            env={**os.environ, "HOME": str(tmp_path)})
    try:
        assert proc.stdout.readline().strip() == "window running"
        proc.send_signal(signal.SIGTERM)
        log, err = proc.communicate(timeout=60)  # PsychoPy's console log is stdout
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode != 0 and "Terminated: signal SIGTERM" in err
    assert "hapticlab haptic: closed sim (output 0 N)" in log, log[-2000:]


@pytest.mark.firmware
def test_the_devices_own_estop_button_is_a_psychopy_error_naming_it(emulator_factory):
    """The reference firmware built for this machine, on a pty (its e-stop button pressed by
    SIGUSR1, released by SIGUSR2): the window ends, the error names the device's own button,
    the fault stays latched across connections (the device refuses to open) until the
    button is released and the experimenter clears it."""
    from psychopy_hapticlab import HapticFaultError, HapticlabDevice
    from psychopy_hapticlab.scenes import fields_scene

    emu = emulator_factory(14, "--firmware", "host")
    spec = f"serial:{emu.port}"
    dev = HapticlabDevice(spec, label="rig")
    try:
        dev.prepare(fields_scene("spring", 680.0, "none"))
        dev.startWindow(5.0, fromFirstContact=False)
        time.sleep(0.3)
        os.kill(emu.proc.pid, signal.SIGUSR1)
        rec = dev.finishWindow()
        assert rec.fault is not None and rec.fault.code == "estop"
        assert rec.result.traces["t"][-1] < 4.5  # the button ended the 5-s window
        with pytest.raises(HapticFaultError, match=r"^rig \(serial:.*\): the device's own "
                                                   r"e-stop button latched output at zero"):
            dev.raiseFault(rec)
        assert [r.code for r in dev.getResponses(kind="fault")] == ["estop"]
    finally:
        dev.close()
    with pytest.raises(HapticFaultError, match="has a latched estop fault.*clearFault=True"):
        HapticlabDevice(spec, label="rig")
    os.kill(emu.proc.pid, signal.SIGUSR2)
    time.sleep(0.1)
    with HapticlabDevice(spec, label="rig", clearFault=True) as again:
        assert again.fault is None
