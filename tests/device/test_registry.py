"""Backends as plugins: found through the ``hapticlab.backends`` entry-point group, hapticlab's
own registered the same way, one installed from another distribution found without a word
in hapticlab, and an unknown or broken one a named error."""

import dataclasses
import importlib.metadata
import json
import textwrap

import pytest

import device
from device import (
    BackendError,
    UnknownBackendError,
    available_devices,
    backend,
    backends,
    broken_backends,
    open_device,
)
from device.registry import ENTRY_POINT_GROUP
from device.suite import CHECKS


def _install(root, dist, entry_points, modules):
    """A distribution installed into ``root`` as pip installs one: its modules, and a
    ``.dist-info`` with its metadata and entry points."""
    info = root / f"{dist}-1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 1.0\n")
    eps = "\n".join(f"{k} = {v}" for k, v in entry_points.items())
    (info / "entry_points.txt").write_text(f"[{ENTRY_POINT_GROUP}]\n{eps}\n")
    for name, text in modules.items():
        (root / f"{name}.py").write_text(textwrap.dedent(text))


#: a lab's simulated twin of its own device, in a package of its own: the simulated device
#: with other mechanics, and what it is and can do said through DeviceInfo
TWIN = """
    from contextlib import contextmanager
    from dataclasses import replace

    from device import AvailableDevice
    from device.sim.backend import SimDevice
    from device.sim.params import DeviceParams


    class TwinDevice(SimDevice):
        def __init__(self, **options):
            super().__init__(device=DeviceParams().with_rate(5_000.0), **options)
            self._info = replace(self._info, backend="twin", model="the lab's twin")

        @classmethod
        def from_spec(cls, arg=None, **options):
            options.pop("speed", None)
            return cls(**options)

        @classmethod
        def available(cls):
            return [AvailableDevice("twin", "the lab's simulated twin")]

        @classmethod
        @contextmanager
        def conformance_opener(cls):
            yield lambda: cls.from_spec(seed=5)
"""


@pytest.fixture
def installed(tmp_path, monkeypatch):
    """Install test-made distributions for this test only (sys.path restored after)."""
    def install(dist, entry_points, modules):
        _install(tmp_path / dist, dist, entry_points, modules)
        monkeypatch.syspath_prepend(str(tmp_path / dist))
    return install


def test_hapticlab_registers_its_own_backends_as_entry_points():
    """sim, serial and the emulator are entry points of the hapticlab distribution, as a
    plugin's backend would be: none is a special case in the code."""
    ours = {ep.name: ep.value for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)
            if ep.dist is not None and ep.dist.name == "hapticlab"}
    assert set(ours) == {"sim", "serial", "emulator"}, ours
    assert set(ours) <= set(backends())
    for name in ours:
        cls = backend(name)
        assert issubclass(cls, device.HapticDevice) and f"{cls.__module__}:" \
            f"{cls.__qualname__}" == ours[name]


def test_a_backend_from_another_distribution_is_found_opened_and_listed(installed):
    installed("lab_twin", {"twin": "lab_twin:TwinDevice"}, {"lab_twin": TWIN})
    assert "twin" in backends()
    with open_device("twin", seed=3, live=False, speed=1.0) as dev:
        i = dev.info
        assert (i.backend, i.servo_rate_hz) == ("twin", 5_000.0)
        assert i.simulated_contact and i.seeded and i.virtual_time  # said, not named
    assert [d.spec for d in available_devices() if d.backend == "twin"] == ["twin"]
    with backend("twin").conformance_opener() as opener:  # the whole suite: the how-to's test
        assert "5000 Hz" in CHECKS["info"](opener) and CHECKS["real_sample"](opener)


def test_an_unknown_backend_is_a_named_error_listing_the_registered_ones():
    with pytest.raises(UnknownBackendError, match="unknown device backend 'nope'") as err:
        open_device("nope:1")
    assert all(name in str(err.value) for name in backends())
    with pytest.raises(UnknownBackendError, match="did you mean serial:/dev/ttyACM0"):
        open_device("/dev/ttyACM0")
    with pytest.raises(UnknownBackendError, match="no device backend named 'nope'"):
        backend("nope")


@pytest.mark.parametrize("value, says", [
    ("lab_missing:Device", "cannot be loaded: ModuleNotFoundError: No module named "
                           "'lab_missing'"),
    ("lab_broken:Device", "cannot be loaded: ZeroDivisionError"),
    ("lab_other:Device", "names <class 'lab_other.Device'>, not a HapticDevice subclass"),
    ("lab_other:Nothing", "cannot be loaded: AttributeError"),
])
def test_a_broken_backend_is_a_named_error_and_spares_the_others(installed, value, says,
                                                                 capsys, monkeypatch):
    installed("lab_plugin", {"labdev": value},
              {"lab_broken": "1 / 0\n", "lab_other": "class Device:\n    pass\n"})
    with pytest.raises(BackendError) as err:
        open_device("labdev")
    msg = str(err.value)
    assert says in msg and "backend 'labdev'" in msg and f"'{value}'" in msg, msg
    assert "of lab_plugin 1.0" in msg, msg  # the distribution to blame
    assert broken_backends() == {"labdev": msg}
    assert "sim" in [d.spec for d in available_devices()]  # the others still listed
    from app import guards
    from app.cli import main

    monkeypatch.setattr(guards, "install_signal_guards", lambda: None)
    assert main(["device", "list", "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert listed["broken"] == {"labdev": msg} and "labdev" in listed["backends"]
    assert main(["device", "list"]) == 0
    assert f"backend labdev: cannot be used: {msg}" in capsys.readouterr().out


def test_a_backend_without_a_way_into_the_suite_says_so(installed):
    installed("lab_bare", {"bare": "lab_bare:BareDevice"}, {"lab_bare": """
        from device import HapticDevice

        class BareDevice(HapticDevice):  # a device class, and nothing said beyond it
            pass
    """})
    with pytest.raises(NotImplementedError, match="BareDevice gives no device for the "
                                                  "conformance suite"):
        backend("bare").conformance_opener()
    assert backend("bare").available() == []  # the safe default: none found


def test_no_backend_at_all_names_the_stale_install(monkeypatch):
    """hapticlab's own backends are entry points: with none, the message says to install
    again (an editable install made before they were)."""
    monkeypatch.setattr(importlib.metadata, "entry_points", lambda group: [])
    with pytest.raises(BackendError, match="install it again"):
        backends()


def test_every_backend_takes_the_common_options():
    """seed, live and speed go to every backend, which uses those that apply: a command
    opens any device the same way."""
    from device.serial.backend import SerialDevice

    with pytest.raises(device.DeviceSpecError, match="needs a port"):
        SerialDevice.from_spec(None, seed=1, live=True, speed=2.0)
    with pytest.raises(device.DeviceSpecError, match="is now the emulator backend"):
        open_device("serial:emulator", seed=1, live=False, speed=1.0)
    with open_device("sim:2000", seed=4, live=False, speed=1.0) as dev:
        assert dev.info.servo_rate_hz == 2000.0


def test_a_device_that_states_no_capabilities_is_taken_for_a_physical_one():
    """LIMITS without the capabilities bits (a device whose firmware predates them) is read
    as a physical device: no session takes it for a rehearsal."""
    from device.serial import messages as M
    from device.serial.backend import SerialDevice

    hello = M.HelloAck(protocol=2, servo_rate_hz=10_000, current_limit_ma=1400,
                       force_constant=2150, effective_mass=55_000, watchdog_ms=100,
                       encoder_nm=10_000, accel_range=490_332, model=b"board",
                       serial=b"0042", firmware=b"hlfw-2.0 board")
    limits = M.Limits(table_items=16384, play_items=16384, ring_records=1024, channels=0x3F,
                      max_decimation=16, link_bytes_s=0, tick_p99_us=0, tick_max_us=0)
    info = SerialDevice._identify(hello, limits)
    assert not (info.simulated_contact or info.seeded or info.virtual_time)
    sim = SerialDevice._identify(hello, dataclasses.replace(limits, capabilities=3))
    assert sim.simulated_contact and sim.seeded and not sim.virtual_time
