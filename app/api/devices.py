"""The API's device commands: open a device for a command, list, self-test, emulate and
forecast saturation (``hapticlab device …``)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from device.serial.firmware import BUILDS

from ..errors import UsageError
from ..guards import close_at_exit
from ._say import to_stderr

__all__ = ["open_device_for", "session_device", "device_selftest", "device_list",
           "EMULATORS", "emulate", "saturation_forecast"]

#: what ``emulate`` can serve the wire protocol with, and the servo rate each runs at [Hz]
#: (None: the Python emulator's ``rate``): the emulator backend's builds
#: (:data:`device.serial.emulated.BUILDS`)
EMULATORS = BUILDS


def open_device_for(spec: str, *, clear_fault: bool = False,
                    say: Callable[[str], None] | None = None, seed: int = 0,
                    person: bool = False, speed: float = 1.0):
    """The device a command opens, with a fault it latched before (an e-stop, the watchdog)
    cleared when the operator said so: every command that opens a device goes through here.

    Parameters
    ----------
    spec : str
        The device spec (``sim``, ``serial:/dev/ttyACM0``, ...).
    clear_fault : bool
        Clear a fault latched before (the operator's decision: ``--clear-fault``); what is
        cleared is said through ``say``.
    say : callable, optional
        Where the operator reads it (default: stderr).
    seed : int
        A simulated device's seed (a backend whose devices are not seeded ignores it).
    person : bool
        A person sits at it: a device in virtual time is paced to the wall clock (the
        simulated device unpaced tapped 910 times in 13 s of familiarization).
    speed : float
        Device seconds per wall second where the device's clock is paced (an emulator).

    Raises
    ------
    DeviceError
        The device cannot be opened, or keeps its fault (its e-stop button still pressed).
    """
    from device import open_device

    dev = open_device(spec, seed=seed, live=person, speed=speed)
    if clear_fault and dev.fault is not None:
        (say or to_stderr)(f"clearing the latched {dev.fault.code} fault of {spec} (the "
                           "operator's decision: --clear-fault)")
        try:
            dev.clear_fault()
        except BaseException:
            dev.close()
            raise
    return dev


@contextmanager
def session_device(spec: str, seed: int, person: bool, clear_fault: bool, lsl: bool,
                   say: Callable[[str], None], speed: float = 1.0) -> Iterator:
    """The device a session (run or resume) opens (``seed``, ``person`` and ``speed`` as
    :func:`open_device_for`): LSL checked first when asked for (no
    pylsl, or no private network where one is required, is said before anything opens),
    closed at exit whatever ends the process, a fault it latched before cleared when the
    operator said so."""
    if lsl:
        from app.markers import load_pylsl

        load_pylsl()
    with open_device_for(spec, clear_fault=clear_fault, say=say, seed=seed, person=person,
                         speed=speed) as dev:
        close_at_exit(dev)
        yield dev


def saturation_forecast(protocol: str | Path, *, device: str, windows: int = 12,
                        warn: float = 0.2, clear_fault: bool = False) -> dict:
    """How often each sample of ``protocol`` will saturate ``device``'s drive, from a
    simulated tapper (0.11 ± 0.033 m/s) over ``windows`` windows per sample (``hapticlab
    device check``; :func:`app.saturation_forecast.saturation_check`).

    Returns
    -------
    dict
        ``protocol`` (its name), ``device`` (the spec), ``info`` (the device's
        :class:`~device.DeviceInfo`) and ``rows`` (per sample: ``tap_rate``,
        ``trial_rate``, ``warning`` — above ``warn`` of trials —, or ``error``).
    """
    from app.saturation_forecast import saturation_check
    from protocols import load_protocol

    p = load_protocol(protocol)
    with session_device(device, 0, person=False, clear_fault=clear_fault, lsl=False,
                         say=to_stderr) as dev:
        info = dev.info
    rows = saturation_check(p, info, windows=windows, warn=warn, say=to_stderr)
    return {"protocol": p.name, "device": device, "info": info, "rows": rows}


def device_selftest(spec: str, *, clear_fault: bool = False,
                    say: Callable[[str], None] | None = None, device_alone: bool = False,
                    tap_wait_s: float = 30.0) -> dict:
    """The backend-independent checks (:mod:`device.suite`) against the device at ``spec``.

    The device is opened once first, so a bad spec or an absent device is one named error
    before any check runs (and a fault latched before is cleared there, with
    ``clear_fault``); each check then opens it afresh. A device whose contact is physical
    (``simulated_contact`` false: a bridge to a commercial device, the papers' board) needs
    a person to tap the stylus in five checks (:data:`device.suite.TAPPED`): they are said
    first, and each asks for the taps through ``say`` when its window starts, waiting up to
    ``tap_wait_s`` for the first contact; with ``device_alone`` they are not run. A
    simulated contact has nothing to leave out: ``device_alone`` is then ignored, with a
    sentence through ``say``.

    Returns
    -------
    dict
        ``spec``, ``checks`` (each ``name``, ``status``, ``ok``, ``detail``), ``passed``,
        ``failed``, ``not_run``.
    """
    from device.suite import Operator, run_selftest

    say = say or to_stderr
    with open_device_for(spec, clear_fault=clear_fault, say=say) as dev:
        physical = not dev.info.simulated_contact
    if device_alone and not physical:  # nothing to leave out: its hand taps by itself
        say(f"--device-alone ignored: {spec}'s contact is simulated, its simulated hand taps "
            "the stylus in every check, so all of them run")
        device_alone = False
    operator = Operator(say, tap_wait_s) if physical and not device_alone else None
    return run_selftest(spec, lambda: open_device_for(spec), operator=operator,
                        device_alone=device_alone, say=say)


def device_list() -> dict:
    """The registered backends and the devices they find on this computer, without
    opening any (opening a serial port can reset a board): :func:`device.available_devices`.

    Returns
    -------
    dict
        ``backends`` (names), ``devices`` (each ``spec``, ``backend``, ``description``,
        ``details``, in the order of the backends' names), ``broken`` (backend name →
        why it cannot be used) and ``none_found`` (backend name → what to check, for a
        backend that found no device and says what: the serial backend's dialout group).
    """
    from device import available_devices, backends, broken_backends, none_found_hints

    return {"backends": backends(), "devices": [d.to_dict() for d in available_devices()],
            "broken": broken_backends(), "none_found": none_found_hints()}


def emulate(firmware: str = "python", *, rate: float | None = None, seed: int = 0,
            speed: float = 1.0) -> int:
    """Serve the wire protocol (versions 2 and 3) on a new pseudo-terminal until SIGINT or
    SIGTERM, printing the port's path first; the exit status.

    Parameters
    ----------
    firmware : str
        One of :data:`EMULATORS`: the Python emulator, the C firmware built for this
        machine (``host``, ``host-board``, ``host-san``), under QEMU (``qemu``), or a bridge
        over a commercial SDK's stand-in (``dhd-stub``, ``hd-stub``, ``hd-stub-tsan``).
    rate : float, optional
        The Python emulator's servo rate [Hz], 1,000–20,000 (default 10,000); a build runs
        at its own (:data:`EMULATORS`), and refuses one given.
    seed : int
        Seed of the simulated plant and tapping.
    speed : float
        Device seconds per wall second, in (0, 20]; 1 for QEMU and the OpenHaptics bridge.

    Raises
    ------
    UsageError
        An option this emulator cannot honour, named.
    """
    from device import DeviceSpecError
    from device.serial.serving import serve

    try:
        return serve(firmware, rate=rate, seed=seed, speed=speed)
    except DeviceSpecError as exc:
        raise UsageError(str(exc)) from None
