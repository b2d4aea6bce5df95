"""The PsychoPy plugin's device class, responses and scenes, in process: PsychoPy's own
DeviceManager, plugin loader and response classes against the simulated device (virtual
time), nothing mocked."""

import importlib.metadata
import threading

import numpy as np
import pytest
from psychopy.hardware import DeviceManager
from psychopy.hardware.exceptions import DeviceNotConnectedError, ManagedDeviceError
from psychopy_hapticlab import (
    ContactResponse,
    HapticContact,
    HapticFaultError,
    HapticlabDevice,
    WindowResponse,
)
from psychopy_hapticlab.scenes import builtin_samples, fields_scene, file_scene, sample_scene

from device import SceneError

#: PsychoPy's data and experiment packages look libraries up with ldconfig (a process) as they
#: load: these in-process tests are in the integration tier
pytestmark = [pytest.mark.integration]


@pytest.fixture
def sim():
    """A simulated device in DeviceManager, in virtual time; removed (closed) after."""
    dev = DeviceManager.addDevice("hapticlab", "haptic-test", spec="sim", seed=3, live=False)
    yield dev
    if DeviceManager.getDevice("haptic-test") is not None:
        DeviceManager.removeDevice("haptic-test")


def test_entry_points_resolve_to_the_plugins_classes_after_activation():
    """As PsychoPy's plugin template checks: every entry point of the distribution is
    reachable where its group says once plugins are activated, and none is a stub."""
    from psychopy.experiment.components import getAllComponents
    from psychopy.plugins import PluginStub, activatePlugins, listPlugins

    activatePlugins()
    assert "psychopy-hapticlab" in listPlugins("loaded")
    eps = list(importlib.metadata.distribution("psychopy-hapticlab").entry_points)
    assert {ep.group for ep in eps} == {"psychopy.hardware", "psychopy.experiment.components"}
    for ep in eps:
        target = getattr(importlib.import_module(ep.group), ep.name)
        assert target is ep.load()
        assert not (isinstance(target, type) and issubclass(target, PluginStub))
    comps = getAllComponents(fetchIcons=False)
    assert {"HapticContactComponent", "HapticCheckComponent"} <= set(comps)


def test_available_devices_are_what_hapticlab_lists(tmp_path):
    from device import available_devices

    got = HapticlabDevice.getAvailableDevices()
    assert [p["spec"] for p in got] == [d.spec for d in available_devices()]
    assert "sim" in [p["spec"] for p in got]
    assert all(p["deviceName"].startswith("hapticlab") for p in got)
    # DeviceManager lists them under the class, ready for Builder's Device Manager
    profiles = DeviceManager.getAvailableDevices("hapticlab")
    assert [p["spec"] for p in profiles] == [p["spec"] for p in got]


def test_a_device_is_the_same_whichever_way_its_port_is_written(sim, tmp_path):
    link = tmp_path / "haptic-port"
    link.symlink_to("/dev/null")
    probe = object.__new__(HapticlabDevice)  # only its spec: comparing opens nothing
    probe.spec = f"serial:{link}"
    assert probe.isSameDevice({"spec": "serial:/dev/null"})
    assert not probe.isSameDevice({"spec": "serial:/dev/zero"})
    assert sim.isSameDevice({"spec": "sim"}) and sim.isSameDevice(sim)
    assert not sim.isSameDevice({"port": "COM3"}) and not sim.isSameDevice(probe)
    assert sim.getDeviceProfile()["spec"] == "sim"  # PsychoPy finds its profile by it


def test_a_window_reports_psychopy_responses_with_their_fields(sim):
    scene = fields_scene("wood", 400.0, "q_sinusoid", slope=-150.0, decay=80.0,
                         frequency=100.0)
    rec = sim.runWindow(scene, 1.0)
    contacts = sim.getResponses(kind="contact", clear=False)
    assert len(contacts) == len(rec.result.contacts) >= 1
    assert all(isinstance(r, ContactResponse) for r in contacts)
    for r, c, peak in zip(contacts, rec.result.contacts, rec.peak_accels, strict=True):
        assert (r.speed, r.tDevice, r.peakAccel) == (c.velocity, c.t, peak)
        assert r.peakAccel > 0 and not r.onHostClock  # virtual time: no host clock
    # each contact's peak is the trace's largest |accel| in the 50 ms after it
    t, a = rec.result.traces["t"], np.abs(rec.result.traces["accel"])
    first = rec.result.contacts[0].t
    assert rec.peak_accels[0] == pytest.approx(a[(t >= first) & (t < first + 0.05)].max())
    end = sim.getResponses(kind="window")
    assert len(end) == 1 and isinstance(end[0], WindowResponse)
    assert end[0].nContacts == len(contacts) and end[0].peakAccel == pytest.approx(a.max())
    assert '"class": "ContactResponse"' in contacts[0].getJSON()  # PsychoPy serialises it
    assert sim.device.output_force == 0.0  # output off between windows


def test_close_zeroes_output_and_device_manager_closes_it(sim):
    sim.prepare(fields_scene("spring", 400.0, "none"))
    sim.startWindow(30.0, fromFirstContact=False)
    dev = sim.device
    DeviceManager.closeAll()  # what PsychoPy runs at exit, mid-window
    assert dev.closed and dev.output_force == 0.0 and not sim.isOpen
    assert not sim.windowRunning
    sim.close()  # idempotent


def test_an_estop_during_a_window_is_a_psychopy_error_naming_it(sim):
    """The e-stop key is pressed (from this thread, as a key handler would) while the window
    waits at a block of ticks past 0.05 s for it: in virtual time a 20-s window takes some
    75 ms of wall time, so a wall-clock timer raced it (and lost on a busy host)."""
    sim.prepare(fields_scene("spring", 400.0, "none"))
    dev = sim.device
    start, waiting, pressed = dev.time, threading.Event(), threading.Event()

    def gate():  # before each block of ticks, in the window's thread
        if dev.time >= start + 0.05 and not waiting.is_set():
            waiting.set()
            pressed.wait(60)  # a bound for a broken test, never a deadline

    dev.input_gate = gate
    sim.startWindow(20.0, fromFirstContact=False)
    assert waiting.wait(60), "the window never reached 0.05 s"
    at = dev.time
    sim.estop("the e-stop key")
    pressed.set()
    rec = sim.finishWindow()
    assert rec.fault is not None and rec.fault.code == "estop"
    assert rec.fault.t == pytest.approx(at)  # when it was pressed, in device time
    assert rec.result.traces["t"][-1] < start + 20.0  # and the window ended there
    with pytest.raises(HapticFaultError, match=r"^sim \(sim\): an e-stop latched output at "
                                               r"zero \(estop: ") as err:
        sim.raiseFault(rec)
    assert isinstance(err.value, ManagedDeviceError) and err.value.fault.code == "estop"
    assert err.value.deviceName == "sim"  # the label it was given, else its spec
    faults = sim.getResponses(kind="fault")
    assert faults and faults[0].code == "estop" and faults[0].message == "the e-stop key"
    assert sim.device.output_force == 0.0
    with pytest.raises(HapticFaultError, match="estop"):  # latched: nothing runs until cleared
        sim.prepare(fields_scene("spring", 400.0, "none"))
    sim.clearFault()
    sim.prepare(fields_scene("spring", 400.0, "none"))


def test_device_manager_names_a_device_it_cannot_open():
    with pytest.raises(ManagedDeviceError, match="unknown device backend 'nope'") as err:
        DeviceManager.addDevice("hapticlab", "rig", spec="nope:x")
    assert err.value.deviceName == "rig"
    with pytest.raises(DeviceNotConnectedError, match="/dev/hapticlab-absent"):
        DeviceManager.addDevice("hapticlab", "rig", spec="serial:/dev/hapticlab-absent")
    assert DeviceManager.getDevice("rig") is None


def test_scenes_from_samples_files_and_fields(tmp_path):
    assert sample_scene("realism/sinusoid_firm").transient.frequency == 36.2
    assert sample_scene("sinusoid_firm") == sample_scene("realism/sinusoid_firm")
    assert "comparison/sinusoid_soft" in builtin_samples()
    with pytest.raises(SceneError, match="protocol 'realism' has no sample 'oak'"):
        sample_scene("realism/oak")
    f = tmp_path / "oak.toml"
    f.write_text('spring = 500.0\ntransient = { kind = "q_sinusoid", slope = -150.0, '
                 'decay = 80.0, frequency = 120.0 }\n')
    s = file_scene(f)
    assert (s.name, s.spring, s.transient.frequency) == ("oak", 500.0, 120.0)
    f.write_text('spring = 500.0\ntransient = { kind = "q_sinusoid", decay = 80.0 }\n')
    with pytest.raises(SceneError, match="oak.toml.*slope"):
        file_scene(f)
    # a conditions file's values: numpy numbers and numeric text are numbers
    s = fields_scene("c", np.int64(400), "q_sinusoid", slope="-150", decay=np.float64(80),
                     frequency=" 66.7 ")
    assert (s.spring, s.transient.slope, s.transient.frequency) == (400.0, -150.0, 66.7)
    with pytest.raises(SceneError, match=r"frequency.*must be > 0, got -5"):
        fields_scene("c", 400.0, "q_sinusoid", slope=-150.0, decay=80.0, frequency=-5.0)
    with pytest.raises(SceneError, match=r"frequency: must be a number, got 'fast'"):
        fields_scene("c", 400.0, "q_sinusoid", slope=-150.0, decay=80.0, frequency="fast")
    with pytest.raises(SceneError, match="transient: must be one of none, q_sinusoid"):
        fields_scene("c", 400.0, "wobble")


@pytest.mark.integration  # saving the trace looks for a library with ldconfig
def test_a_contact_records_its_row_and_its_trace_in_hapticlabs_format(sim, tmp_path):
    from psychopy import core, data

    exp = data.ExperimentHandler(name="t", dataFileName=str(tmp_path / "t"), savePickle=False,
                                 saveWideText=False)
    contact = HapticContact("haptic-test", name="tap", experiment=exp, windowDuration=1.0,
                            traceFolder=tmp_path / "t_tap", transient="q_sinusoid")
    clock = core.Clock()
    exp.addData("before", 1)
    exp.nextEntry()
    contact.setFrequency(np.float64(66.7))
    contact.arm()
    contact.start()
    while not contact.poll():
        core.wait(0.005)
    row = contact.record(exp, clock=clock)
    assert row["trial_id"] == 1 and row["status"] == "valid"
    assert "transient.frequency=66.7" in row["scene_fields"]
    entry = exp.getAllEntries()[1]
    assert entry["tap.n_contacts"] == len(row["speeds"]) >= 1
    trace = np.load(tmp_path / row["trace_file"])
    assert row["trace_file"] == "t_tap/traces/trial-0001-tap-1.npz"
    assert list(trace["contacts_v"].round(5)) == row["speeds"]
    lsb = float(trace["accel_lsb"])
    assert row["peak_accel"] == pytest.approx(np.abs(trace["accel_counts"]).max() * lsb,
                                              abs=lsb)
    # a conditions row the scene refuses stops at arm, naming field and value
    contact.setFrequency("-5")
    with pytest.raises(SceneError, match="frequency: must be > 0, got -5"):
        contact.arm()
    assert sim.device.output_force == 0.0


def test_the_device_refuses_a_foreign_device_manager_entry():
    from psychopy_hapticlab.contact import resolve_device

    with pytest.raises(DeviceNotConnectedError, match="no hapticlab device named 'rig2'.*"
                                                      "Device Manager"):
        resolve_device("rig2")
