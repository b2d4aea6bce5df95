"""The API's device commands: open a device for a command, list, self-test, emulate and
forecast saturation (``hapticlab device …``)."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from ..errors import UsageError
from ..guards import close_at_exit
from ._say import to_stderr

__all__ = ["open_device_for", "session_device", "emulated_spec", "device_selftest",
           "device_list", "EMULATORS", "emulate", "saturation_forecast"]


def open_device_for(spec: str, *, clear_fault: bool = False,
                    say: Callable[[str], None] | None = None, seed: int = 0,
                    person: bool = False):
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
        The simulated device's seed (``sim`` only).
    person : bool
        A person sits at it: the simulated device is paced to the wall clock (unpaced it
        tapped 910 times in 13 s of familiarization).

    Raises
    ------
    DeviceError
        The device cannot be opened, or keeps its fault (its e-stop button still pressed).
    """
    from device import open_device

    dev = (open_device(spec, seed=seed, live=person) if spec == "sim" or spec.startswith("sim:")
           else open_device(spec))
    if clear_fault and dev.fault is not None:
        (say or to_stderr)(f"clearing the latched {dev.fault.code} fault of {spec} (the operator's "
                      "decision: --clear-fault)")
        try:
            dev.clear_fault()
        except BaseException:
            dev.close()
            raise
    return dev


@contextmanager
def session_device(spec: str, seed: int, person: bool, clear_fault: bool, lsl: bool,
                    say: Callable[[str], None]) -> Iterator:
    """The device a session (run or resume) opens: LSL checked first when asked for (no
    pylsl, or no private network where one is required, is said before anything opens),
    closed at exit whatever ends the process, a fault it latched before cleared when the
    operator said so."""
    if lsl:
        from app.markers import load_pylsl

        load_pylsl()
    with open_device_for(spec, clear_fault=clear_fault, say=say, seed=seed,
                         person=person) as dev:
        close_at_exit(dev)
        yield dev


@contextmanager
def emulated_spec(spec: str, speed: float = 1.0, log: Path | None = None) -> Iterator[str]:
    """``serial:emulator`` starts a device emulator on a pty for the run, paced at ``speed``
    × real time; what it says (faults, the watchdog's timing) goes to ``log``."""
    if spec != "serial:emulator":
        yield spec
        return
    if log is not None:
        log.parent.mkdir(parents=True, exist_ok=True)
    with open(log if log is not None else os.devnull, "w") as err:
        proc = subprocess.Popen([sys.executable, "-m", "app", "device", "emulate", "--speed",
                                 repr(float(speed))],
                                stdout=subprocess.PIPE, stderr=err, text=True)
    try:
        port = proc.stdout.readline().strip()
        if not port:
            raise UsageError("the device emulator did not start"
                             + (f" (its log: {log})" if log is not None else ""))
        yield f"serial:{port}"
    finally:
        proc.terminate()
        proc.wait(timeout=10)


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
                    say: Callable[[str], None] | None = None) -> dict:
    """The backend-independent checks (:mod:`device.suite`) against the device at ``spec``.

    The device is opened once first, so a bad spec or an absent device is one named error
    before any check runs (and a fault latched before is cleared there, with
    ``clear_fault``); each check then opens it afresh.

    Returns
    -------
    dict
        ``spec``, ``checks`` (each ``name``, ``ok``, ``detail``), ``passed``, ``failed``.
    """
    from device.suite import run_selftest

    open_device_for(spec, clear_fault=clear_fault, say=say).close()
    return run_selftest(spec, lambda: open_device_for(spec))


def device_list() -> dict:
    """The registered backends, the serial ports this computer has and the simulated
    device, without opening any port (opening one can reset a board).

    Returns
    -------
    dict
        ``backends`` (names), ``ports`` (each ``spec``, ``description``, ``hwid``, sorted by
        port) and ``simulated`` (each ``spec``, ``description``).
    """
    from serial.tools import list_ports

    from device import backends

    ports = [{"spec": f"serial:{p.device}", "description": p.description or "",
              "hwid": p.hwid or ""} for p in sorted(list_ports.comports(), key=lambda p: p.device)]
    return {"backends": list(backends()), "ports": ports,
            "simulated": [{"spec": "sim", "description": "the simulated device (no hardware)"}]}


#: what ``emulate`` can serve the wire protocol with, and the servo rate each runs at [Hz]
#: (None: the Python emulator's ``rate``)
EMULATORS = {"python": None, "host": 10_000.0, "host-board": 10_000.0, "host-san": 10_000.0,
             "qemu": 10_000.0, "dhd-stub": 4_000.0, "hd-stub": 1_000.0,
             "hd-stub-tsan": 1_000.0}


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
    if firmware not in EMULATORS:
        raise UsageError(f"no emulator named {firmware!r}; one of {', '.join(EMULATORS)}")
    if not 0 < speed <= 20:
        raise UsageError(f"--speed must be in (0, 20] (device seconds per wall second), "
                         f"got {speed:g}")
    if firmware != "python":
        from device.serial.firmware import REAL_TIME_ONLY, serve

        if rate is not None:
            raise UsageError(f"the firmware's servo runs at its build's own rate "
                             f"({EMULATORS[firmware]:,.0f} Hz for {firmware}): --rate applies "
                             "to --firmware python only")
        if firmware == "qemu" and speed != 1.0:
            raise UsageError("the firmware under QEMU runs at the pace of its counted "
                             "instructions and its sleeps: --speed applies to "
                             "--firmware python, host, host-board, host-san and dhd-stub")
        if firmware in REAL_TIME_ONLY and speed != 1.0:
            raise UsageError(f"--firmware {firmware} runs in real time, in the HD "
                             "scheduler's clock: --speed must be 1")
        return serve(firmware, seed, speed)
    from device.serial.emulator import main as serve_python

    rate = 10_000.0 if rate is None else rate
    if not 1_000 <= rate <= 20_000:
        raise UsageError(f"--rate must be 1,000–20,000 Hz, got {rate:g}")
    return serve_python(rate, seed, speed)
