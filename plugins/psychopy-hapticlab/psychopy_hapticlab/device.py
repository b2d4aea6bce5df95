"""A hapticlab device in PsychoPy's DeviceManager.

:class:`HapticlabDevice` opens any hapticlab device spec (``sim``, ``serial:PORT`` — a board,
an emulator's or a bridge's pseudo-terminal) through hapticlab's own device layer
(:func:`app.api.open_device_for`); it renders nothing itself. A tapping window runs in a
thread of its own, so PsychoPy's frame loop goes on drawing and reading keys; what the
device reports comes back as response objects (:mod:`.responses`) when PsychoPy dispatches
messages, and a latched fault reaches the experiment as :class:`HapticFaultError`, a
PsychoPy :class:`~psychopy.hardware.exceptions.ManagedDeviceError` naming the device and
the fault.

``close()`` zeroes the output and releases the link; PsychoPy's DeviceManager calls it on
every device when the experiment ends (its ``atexit`` handler: after the last routine,
after escape, after an error), and the device closes itself at exit when it was made
without DeviceManager. SIGTERM and SIGHUP (a Runner's stop, a closed terminal) unwind the
experiment as an error does, where no other handler was installed.
"""

from __future__ import annotations

import math
import os
import queue
import signal
import threading
import time
from dataclasses import dataclass, field

import numpy as np
from psychopy import logging
from psychopy.hardware.base import BaseResponseDevice
from psychopy.hardware.exceptions import DeviceNotConnectedError, ManagedDeviceError

from .responses import (
    ContactResponse,
    FaultResponse,
    HapticResponse,
    SaturationResponse,
    WindowResponse,
)

__all__ = ["HapticlabDevice", "HapticFaultError", "WindowRecord", "PEAK_SPAN_S",
           "psychopy_minus_perf"]

#: what counts as one contact's acceleration: its largest magnitude this long after the
#: contact [s] (a tap's transient and ringing; the papers' decaying sinusoids are down to
#: 1 % within 40 ms)
PEAK_SPAN_S = 0.050

#: longest a closing device waits for a running window to end [s] before it closes anyway
_CLOSE_WAIT_S = 10.0


class HapticFaultError(ManagedDeviceError):
    """A hapticlab device latched a fault (an e-stop from the keyboard or the device's own
    button, the watchdog…): output is zero until the fault is cleared. ``fault`` is the
    device's :class:`device.FaultEvent` (None when the link itself failed)."""

    def __init__(self, msg: str, deviceName: str, fault=None):
        super().__init__(msg, deviceName)
        self.fault = fault


def psychopy_minus_perf() -> tuple[float, float]:
    """PsychoPy's time base minus :func:`time.perf_counter` [s] and its uncertainty [s]:
    the tightest of 20 readings of ``psychopy.clock.getTime()`` bracketed by two of
    ``perf_counter`` (the device's clock is mapped onto ``perf_counter``)."""
    from psychopy import clock

    best = (math.inf, 0.0)
    for _ in range(20):
        a = time.perf_counter()
        p = clock.getTime()
        b = time.perf_counter()
        if b - a < best[0]:
            best = (b - a, p - (a + b) / 2)
    return best[1], best[0] / 2


def _canonical(spec: str) -> str:
    """A spec as one device is named whichever way it was written (``serial:`` ports by
    their real path; ``sim`` and ``sim:`` alike)."""
    name, _, arg = str(spec).partition(":")
    if name == "serial" and arg:
        return f"serial:{os.path.realpath(arg)}"
    return name if not arg else f"{name}:{arg}"


@dataclass
class WindowRecord:
    """One finished window, as the experiment records it.

    Attributes
    ----------
    result : device.WindowResult
        What the device reported (whole, or what it had delivered when the window failed).
    scene : device.Scene
        What was rendered.
    peak_accels : list of float [m/s²]
        Per contact, its largest acceleration magnitude within :data:`PEAK_SPAN_S`
        (empty without an accelerometer).
    peak_accel : float or None [m/s²]
        The window's largest acceleration magnitude (None without an accelerometer or
        without traces).
    clock : dict
        Device time → PsychoPy time base: ``offset_s`` (PsychoPy time of device time 0),
        ``rate`` (PsychoPy seconds per device second), ``uncertainty_s``; empty when the
        device's clock is not this computer's (a simulation in virtual time).
    started : float [s]
        PsychoPy time the window was started at.
    fault : device.FaultEvent or None
        The fault latched at its end.
    error : str
        What went wrong with the link, in words (empty when nothing).
    responses : list of HapticResponse
        What it reported, in time order.
    """

    result: object
    scene: object
    peak_accels: list = field(default_factory=list)
    peak_accel: float | None = None
    clock: dict = field(default_factory=dict)
    started: float = 0.0
    fault: object = None
    error: str = ""
    responses: list = field(default_factory=list)

    def on_psychopy(self, t_device: float) -> float | None:
        """PsychoPy time of device time ``t_device`` [s], or None without a clock."""
        if not self.clock:
            return None
        return self.clock["offset_s"] + self.clock["rate"] * t_device


def _peaks(res, span_s: float = PEAK_SPAN_S) -> tuple[list[float], float | None]:
    """Per contact, the largest |accel| within ``span_s`` after it, and the window's."""
    tr = res.traces
    if "accel" not in tr or "t" not in tr or not len(tr["t"]):
        return [], None
    t = np.asarray(tr["t"], dtype=float)
    a = np.abs(np.asarray(tr["accel"], dtype=float))
    out = []
    for c in res.contacts:
        i, j = np.searchsorted(t, [c.t, c.t + span_s])
        out.append(float(a[i:j].max()) if j > i else float("nan"))
    return out, float(a.max())


class _Running:
    """A window running in its own thread."""

    def __init__(self):
        self.thread: threading.Thread | None = None
        self.result = None
        self.error: BaseException | None = None
        self.end_requested = False
        self.shown = 0  # contacts already sent as responses
        self.started = 0.0  # PsychoPy time
        self.scene = None


class HapticlabDevice(BaseResponseDevice, aliases=["hapticlab"]):
    """A hapticlab force-feedback device (any spec ``hapticlab device list`` shows).

    Parameters
    ----------
    spec : str
        The device: ``sim`` (the simulated device), ``serial:/dev/ttyACM0`` (a board, or the
        pseudo-terminal of ``hapticlab device emulate`` or of a bridge).
    seed : int
        The simulated device's seed (its tapping hand and sensor noise); ignored by hardware.
    live : bool
        Pace the simulated device to the wall clock, as a person feels it (default); False
        runs it as fast as it computes, in virtual time (dry runs, tests).
    clearFault : bool
        Clear a fault the device latched before it was opened (the experimenter's decision,
        once the device is safe); without it such a device refuses to open.
    label : str
        The name the experiment knows the device by (its Device Manager label), used in
        messages; the spec when not given.
    lsl : bool
        Send hapticlab's event markers on a Lab Streaming Layer outlet named ``hapticlab
        markers`` (``hapticlab[lsl]``): each routine's trial start and end with the data
        row's trial id, the window's contacts, saturations and faults on the LSL clock
        (:mod:`app.markers`), ``session_start`` when the device opens and ``session_end``
        when it closes.
    lslWait : float [s]
        With ``lsl``: how long to wait for a recorder (LabRecorder) to take the stream before
        the experiment starts; markers sent before one listens are lost.

    Raises
    ------
    DeviceNotConnectedError
        The device cannot be opened (no such port, no answer), said in hapticlab's words.
    HapticFaultError
        It has a latched fault and ``clearFault`` is False.
    LslUnavailable
        ``lsl`` and no pylsl (or no private network where one is required), or no recorder
        took the stream within ``lslWait``.
    """

    responseClass = HapticResponse

    def __init__(self, spec: str = "sim", seed: int = 0, live: bool = True,
                 clearFault: bool = False, label: str | None = None, lsl: bool = False,
                 lslWait: float = 60.0):
        super().__init__()
        from app.api import open_device_for
        from app.guards import close_at_exit
        from app.markers import LslUnavailable, MarkerSink, load_pylsl
        from device import DeviceError, DeviceSpecError

        self.spec = str(spec)
        self.label = str(label) if label else self.spec
        self._options = {"seed": int(seed), "live": bool(live)}
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._running: _Running | None = None
        self._closed = False
        #: where the experiment's event markers go (:class:`app.markers.MarkerSink`; an
        #: LSL outlet with ``lsl``, else one that sends nothing)
        self.markers = MarkerSink()
        if lsl:
            load_pylsl()  # before the device opens: a missing pylsl is said first
        said = []
        try:
            self._dev = open_device_for(self.spec, clear_fault=bool(clearFault),
                                        say=said.append, seed=int(seed), person=bool(live))
        except DeviceSpecError:
            raise  # a spec that cannot be: DeviceManager names the device
        except DeviceError as exc:
            raise DeviceNotConnectedError(f"{self.label}: {exc}", deviceClass=type(self)) \
                from None
        for text in said:
            logging.warning(f"hapticlab {self.label}: {text}")
        if self._dev.fault is not None:
            f = self._dev.fault
            self._dev.close()
            self._closed = True
            raise HapticFaultError(
                f"{self.label} ({self.spec}) has a latched {f.code} fault ({f.message}): output "
                "stays zero. Make the device safe (the stylus held or at rest, its e-stop "
                "button released), then open it with clearFault=True (Device Manager: "
                "'Clear a latched fault').", self.label, fault=f)
        i = self._dev.info
        if lsl:
            from app.markers import LslMarkers

            say = lambda text: logging.warning(f"hapticlab {self.label}: {text}")  # noqa: E731
            try:
                self.markers = LslMarkers(
                    "hapticlab markers", f"hapticlab:psychopy:{i.serial_number}",
                    {"device": self.spec, "model": i.model, "serial": i.serial_number,
                     "firmware": i.firmware, "host": "psychopy"}, say=say)
                if not self.markers.wait_for_consumer(float(lslWait), say):
                    raise LslUnavailable(f"no recorder received the LSL markers within "
                                         f"{float(lslWait):g} s: start LabRecorder (select "
                                         "the stream 'hapticlab markers'), then run again")
            except BaseException:
                self.markers.close()
                self._dev.close()
                raise
            self.markers.send("session_start", device=self.spec, label=self.label)
        close_at_exit(self)
        _guard_signals()
        logging.exp(f"hapticlab {self.label}: opened {self.spec}: {i.model}, serial "
                    f"{i.serial_number}, firmware {i.firmware}, {i.servo_rate_hz:g} Hz")

    # ------------------------------------------------------------------ DeviceManager
    @staticmethod
    def getAvailableDevices() -> list[dict]:
        """What ``hapticlab device list`` finds (:func:`device.available_devices`: every
        registered backend's devices, hapticlab's own and any installed), without opening
        any (opening a serial port can reset a board), each a dict of the keyword arguments
        that open it (``spec``) and a ``deviceName``."""
        from device import available_devices

        return [{"deviceName": f"hapticlab: {d.spec}"
                 + (f" ({d.description})" if d.description not in ("", "n/a") else ""),
                 "spec": d.spec} for d in available_devices()]

    def isSameDevice(self, other) -> bool:
        """True when ``other`` (a HapticlabDevice, or a dict with ``spec``) names this
        device (serial ports compared by their real path)."""
        if isinstance(other, HapticlabDevice):
            spec = other.spec
        elif isinstance(other, dict) and "spec" in other:
            spec = other["spec"]
        else:
            return False
        return _canonical(spec) == _canonical(self.spec)

    # ------------------------------------------------------------------ identity
    @property
    def info(self):
        """The device's :class:`device.DeviceInfo` (model, serial number, rates, limits)."""
        return self._dev.info

    @property
    def device(self):
        """hapticlab's :class:`device.HapticDevice` behind this object (for what PsychoPy
        does not ask: system identification, libraries)."""
        return self._dev

    @property
    def fault(self):
        """The latched :class:`device.FaultEvent`, or None."""
        return self._dev.fault

    @property
    def isOpen(self) -> bool:
        return not self._closed

    # ------------------------------------------------------------------ messages
    def dispatchMessages(self) -> None:
        """Hand what the device reported since the last call to PsychoPy (listeners,
        callbacks, the log, :attr:`responses`); in the thread that calls it."""
        while True:
            try:
                msg = self._queue.get_nowait()
            except queue.Empty:
                return
            self.receiveMessage(msg)

    def parseMessage(self, message):
        """Responses are made already parsed (the device layer decodes its wire)."""
        if isinstance(message, HapticResponse):
            return message
        raise TypeError(f"{type(self).__name__} receives HapticResponse objects, got "
                        f"{type(message).__name__}")

    def getResponses(self, kind: str | None = None, clear: bool = True) -> list:
        """Responses received so far (dispatched first): all, or those of one ``kind``
        (``contact``, ``saturation``, ``fault``, ``window``); ``clear`` removes those
        returned."""
        self.dispatchMessages()
        got = [r for r in self.responses if kind is None or r.kind == kind]
        if clear:
            self.responses = [r for r in self.responses if r not in got]
        return got

    # ------------------------------------------------------------------ windows
    def prepare(self, scene, clearance: float | None = None) -> None:
        """Load ``scene`` (a :class:`device.Scene`) and home the stylus above it, output
        ramped on: the device is armed for a window.

        Raises
        ------
        SceneError
            This device cannot present the scene (named).
        HapticFaultError
            A latched fault.
        """
        self._usable()
        self._dev.load_scene(scene)
        self._dev.home(clearance)
        logging.exp(f"hapticlab {self.label}: armed with scene {scene.name} ({scene.kind})")

    def startWindow(self, duration: float, fromFirstContact: bool = True,
                    timeout: float = 30.0) -> None:
        """Start a tapping window on the armed scene, in a thread of its own: ``duration``
        [s] from the first contact (waiting up to ``timeout`` [s] for it), or from now when
        ``fromFirstContact`` is False. Contacts come back as :class:`ContactResponse` while
        it runs."""
        self._usable()
        if self._running is not None:
            raise RuntimeError(f"hapticlab {self.label}: a window is running already")
        from psychopy import clock

        run = _Running()
        run.started = clock.getTime()
        run.scene = self._dev.scene
        self._running = run

        def progress(_t, partial) -> None:
            offset = None
            for c in partial.contacts[run.shown:]:
                if offset is None:
                    offset = self._device_to_psychopy()
                t, mapped = (offset(c.t), True) if offset else (clock.getTime(), False)
                self._queue.put(ContactResponse(t, c.velocity, c.t, mapped, device=self))
            run.shown = len(partial.contacts)
            if run.end_requested:
                run.end_requested = False
                self._dev.end_window()

        def target() -> None:
            try:
                run.result = self._dev.run_window(float(duration),
                                                  from_first_contact=bool(fromFirstContact),
                                                  timeout=float(timeout), on_progress=progress)
            except BaseException as exc:  # noqa: BLE001 - handed to the main thread
                run.error = exc
                run.result = getattr(exc, "partial", None)

        run.thread = threading.Thread(target=target, name=f"hapticlab window {self.label}",
                                      daemon=True)
        run.thread.start()
        logging.exp(f"hapticlab {self.label}: window started ({duration:g} s "
                    f"{'from the first contact' if fromFirstContact else 'fixed'})")

    @property
    def windowRunning(self) -> bool:
        """True while a window started by :meth:`startWindow` runs."""
        return self._running is not None and self._running.thread.is_alive()

    def endWindow(self) -> None:
        """Ask the running window to end at the device's next progress report (the routine
        ended before it did); nothing when none runs."""
        if self._running is not None:
            self._running.end_requested = True

    def finishWindow(self) -> WindowRecord:
        """Wait for the running window to end, zero the output, and return its record; its
        saturations, faults and end come back as responses.

        The record is returned even when the window ended on a fault or a failed link
        (``record.fault``, ``record.error``), so that the experiment records it; call
        :meth:`raiseFault` after recording."""
        run = self._running
        if run is None:
            raise RuntimeError(f"hapticlab {self.label}: no window was started")
        run.thread.join()
        self._running = None
        from psychopy import clock

        res = run.result
        rec = WindowRecord(result=res, scene=run.scene, started=run.started)
        if run.error is not None:
            rec.error = f"{type(run.error).__name__}: {run.error}"
        if res is not None:
            rec.peak_accels, rec.peak_accel = _peaks(res)
            t = res.traces.get("t")
            span = (float(t[0]), float(t[-1])) if t is not None and len(t) else None
            rec.clock = self._clock_mapping(span)
        try:
            if not self._closed and run.error is None:
                self._dev.zero()  # output off between windows: only a window keeps it on
        except Exception as exc:  # noqa: BLE001 - the link failed after the window: said
            rec.error = rec.error or f"{type(exc).__name__}: {exc}"
        rec.fault = self._dev.fault if not self._closed else None
        if res is None:
            return rec
        now = clock.getTime()

        def when(t_dev):
            t = rec.on_psychopy(t_dev)
            return (t, True) if t is not None else (now, False)

        resp = []
        shown = {(r.tDevice, r.value): r for r in self.responses + self._pending()
                 if isinstance(r, ContactResponse)}
        for k, c in enumerate(res.contacts):
            peak = rec.peak_accels[k] if k < len(rec.peak_accels) else None
            r = shown.get((c.t, c.velocity))
            if r is None:  # reported after the window's last progress
                t, mapped = when(c.t)
                r = ContactResponse(t, c.velocity, c.t, mapped, peakAccel=peak, device=self)
                self._queue.put(r)
            else:
                r.peakAccel = peak
            resp.append(r)
        for s in res.saturations:
            t, mapped = when(s.t)
            r = SaturationResponse(t, s.peak_current, s.t, mapped, duration=s.duration,
                                   device=self)
            self._queue.put(r)
            resp.append(r)
        for f in res.faults:
            t, mapped = when(f.t)
            r = FaultResponse(t, f.code, f.t, mapped, message=f.message, device=self)
            self._queue.put(r)
            resp.append(r)
        end = float(res.traces["t"][-1]) if len(res.traces.get("t", ())) else None
        t, mapped = when(end) if end is not None else (now, False)
        r = WindowResponse(t, len(res.contacts), end, mapped, peakAccel=rec.peak_accel,
                           saturated=res.saturated, timedOut=res.timed_out, device=self)
        self._queue.put(r)
        resp.append(r)
        rec.responses = sorted(resp, key=lambda x: (x.tDevice is None, x.tDevice or 0.0))
        logging.exp(f"hapticlab {self.label}: window ended: {len(res.contacts)} contacts, "
                    f"{len(res.saturations)} saturations"
                    + (f", fault {rec.fault.code}" if rec.fault is not None else ""))
        return rec

    def runWindow(self, scene, duration: float, fromFirstContact: bool = True,
                  timeout: float = 30.0) -> WindowRecord:
        """Arm ``scene``, run one window and wait for it (Coder's one call); raises
        :class:`HapticFaultError` when it ended on a fault."""
        self.prepare(scene)
        self.startWindow(duration, fromFirstContact, timeout)
        rec = self.finishWindow()
        self.dispatchMessages()
        self.raiseFault(rec)
        return rec

    def raiseFault(self, record: WindowRecord | None = None) -> None:
        """Raise :class:`HapticFaultError` when the device has a latched fault, or
        ``record``'s window failed; nothing otherwise."""
        if record is not None and record.error and record.fault is None:
            raise HapticFaultError(f"{self.label} ({self.spec}): the window failed: "
                                   f"{record.error}; output is zero", self.label)
        f = self._dev.fault if not self._closed else None
        if f is None and record is not None:
            f = record.fault
        if f is not None:
            source = ("the device's own e-stop button" if "button" in f.message else
                      "an e-stop" if f.code == "estop" else f"a {f.code} fault")
            raise HapticFaultError(
                f"{self.label} ({self.spec}): {source} latched output at zero ({f.code}: "
                f"{f.message}); the experiment stops here, its data so far are saved",
                self.label, fault=f)

    def estop(self, why: str = "e-stop") -> None:
        """Latched emergency stop: output to zero now and until the fault is cleared, and
        the running window (if any) ends at the device's next report; a
        :class:`FaultResponse` says so. Callable from any thread."""
        from psychopy import clock

        try:
            self._dev.estop()
        finally:
            self.endWindow()  # nothing is rendered any more: the trial is over
            self._queue.put(FaultResponse(clock.getTime(), "estop", None, False,
                                          message=why, device=self))
            logging.warning(f"hapticlab {self.label}: E-STOP latched ({why}): output is zero")

    def clearFault(self) -> None:
        """Clear a latched fault (output resumes, ramped, at the next :meth:`prepare`)."""
        self._dev.clear_fault()

    # ------------------------------------------------------------------ checks
    def selftest(self, deviceAlone: bool = False, tapWait: float = 30.0, say=None) -> dict:
        """hapticlab's device self-test (``hapticlab device selftest``): every check of the
        interface against this device, which is released meanwhile and opened again.

        On a device whose contact is physical (a board, a bridge: ``info.simulated_contact``
        false) five checks need someone to tap the stylus (:data:`device.suite.TAPPED`): the
        self-test says so first, then asks for the taps as each of them starts, through
        ``say``; a check nobody tapped for fails by name. A simulated device's hand taps by
        itself: nothing is said, and every check runs.

        Parameters
        ----------
        deviceAlone : bool
            On a device whose contact is physical, run only the checks the device does
            alone: the five others are reported as not run, never as passed. Ignored by a
            device whose contact is simulated (it runs them all, nobody needed).
        tapWait : float [s]
            How long each of the five waits for the first contact after its prompt.
        say : callable, optional
            Where what the operator must read goes, one line each (default: PsychoPy's log
            as warnings, which its console shows).

        Returns
        -------
        dict
            ``spec``, ``checks`` (each ``name``, ``status`` — ``passed``, ``failed`` or
            ``not run`` —, ``ok``, ``detail``), ``passed``, ``failed``, ``not_run``.
        """
        from app.api import device_selftest, open_device_for

        self._usable()
        if say is None:
            def say(text: str) -> None:
                logging.warning(f"hapticlab {self.label}: {text}")
        physical = not self.info.simulated_contact
        spec, opts = self.spec, self._options
        self._dev.close()
        try:
            return device_selftest(spec, say=say, device_alone=bool(deviceAlone) and physical,
                                   tap_wait_s=float(tapWait))
        finally:
            self._dev = open_device_for(spec, seed=opts["seed"], person=opts["live"])

    def preflight(self, scenes=()) -> list:
        """hapticlab's preflight of this device: it answers and has no latched fault, and
        it can present each of ``scenes`` (nothing moves). Returns
        :class:`app.preflight.Check` objects (``name``, ``ok``, ``detail``, ``fix``)."""
        from app.preflight import Check, check_device
        from device import SceneError

        checks = [check_device(self._dev, self.spec)]
        for s in scenes:
            try:
                self._dev.check_scene(s)
                checks.append(Check(f"scene {s.name}", True, f"{s.kind} can be presented"))
            except SceneError as exc:
                checks.append(Check(f"scene {s.name}", False, str(exc)))
        return checks

    # ------------------------------------------------------------------ clock
    def _device_to_psychopy(self, span=None):
        """A function from device time to PsychoPy time, or None without a clock."""
        m = self._clock_mapping(span)
        if not m:
            return None
        return lambda t: m["offset_s"] + m["rate"] * t

    def _clock_mapping(self, span) -> dict:
        clock = self._dev.host_clock(span) if not self._closed else None
        if clock is None:
            return {}
        d, d_unc = psychopy_minus_perf()
        return {"offset_s": clock.offset_s + d, "rate": clock.rate,
                "uncertainty_s": clock.uncertainty_s + d_unc, "pairs": clock.pairs}

    # ------------------------------------------------------------------ closing
    def close(self) -> None:
        """End a running window, zero the output and release the link. Idempotent; the
        device is closed afterwards."""
        if self._closed:
            return
        run = self._running
        if run is not None and run.thread.is_alive():
            run.end_requested = True
            run.thread.join(_CLOSE_WAIT_S)
        try:
            self._dev.close()
        finally:
            self._closed = True
            self.markers.send("session_end", status="closed")
            self.markers.close()
            logging.exp(f"hapticlab {self.label}: closed {self.spec} (output "
                        f"{self._dev.output_force:g} N)")

    def __enter__(self) -> HapticlabDevice:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _pending(self) -> list:
        """Responses queued, not yet dispatched (put back in order)."""
        items = []
        while True:
            try:
                items.append(self._queue.get_nowait())
            except queue.Empty:
                break
        for m in items:
            self._queue.put(m)
        return items

    def _usable(self) -> None:
        if self._closed:
            raise HapticFaultError(f"{self.label} ({self.spec}) is closed", self.label)
        self.raiseFault()


def _guard_signals() -> None:
    """SIGTERM and SIGHUP unwind the experiment (so the device closes) where nothing else
    handles them: PsychoPy installs no handler of its own."""
    from app.guards import install_signal_guards

    if threading.current_thread() is not threading.main_thread():
        return
    if all(signal.getsignal(s) in (signal.SIG_DFL, None) for s in (signal.SIGTERM,
                                                                   signal.SIGHUP)):
        install_signal_guards()
