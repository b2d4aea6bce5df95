"""What a Haptic contact component drives: one scene per routine, one tapping window, and
the routine's data.

:class:`HapticContact` is the library class behind the Builder component (as PsychoPy's
``ButtonBox`` is behind its Button Box component) and is used in Coder the same way::

    contact = HapticContact(device="haptic", name="tap", transient="q_sinusoid",
                            slope=-150.0, decay=80.0, frequency=100.0)
    contact.arm()          # Begin Routine: the scene loaded, the stylus homed, output ramped
    contact.start()        # the component starts: the window begins
    while not contact.poll():
        win.flip()         # each frame: responses dispatched, e-stop keys read
    contact.record(thisExp)  # End Routine: the row's data, the trace file

Every setter takes a value as a Builder parameter or a conditions file gives it; the scene is
made and checked by hapticlab (:mod:`.scenes`) when the routine arms it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from psychopy import logging

from . import scenes as _scenes
from .device import HapticlabDevice, WindowRecord

__all__ = ["HapticContact", "WINDOW_MODES", "TRACE_MODES", "resolve_device", "flat_fields",
           "cell"]

#: when a window's duration counts from
WINDOW_MODES = ("from first contact", "fixed")
#: what a trace file keeps: every tick, the taps alone (10 ms before to 140 ms after each
#: contact), or nothing (hapticlab's recorder modes)
TRACE_MODES = ("full", "contacts", "none")

#: scene fields and their defaults: wood's best vibration set of the factorial study (SPEC §2,
#: Table 2: A = −150 1/s, B = 80 1/s, 100 Hz) on its one 400-N/m spring
SCENE_DEFAULTS: dict[str, Any] = {
    "scene": "parameters", "sample": "realism/sinusoid_firm", "sceneFile": "",
    "surfaceHeight": 0.0, "spring": 400.0, "transient": "q_sinusoid",
    "slope": -150.0, "decay": 80.0, "frequency": 100.0,
    "gain": 15.9, "decayTime": 0.055, "pulseDuration": 0.020,
    "librarySource": "wood_on_foam", "attenuation": 0.8,
}


def resolve_device(device) -> HapticlabDevice:
    """``device`` itself, or the HapticlabDevice DeviceManager holds under that name.

    Raises
    ------
    DeviceNotConnectedError
        No device of that name: the message says how to set one up.
    """
    from psychopy.hardware import DeviceManager
    from psychopy.hardware.exceptions import DeviceNotConnectedError

    if isinstance(device, HapticlabDevice):
        return device
    found = DeviceManager.getDevice(device) if isinstance(device, str) and device else None
    if isinstance(found, HapticlabDevice):
        return found
    if found is not None:
        raise DeviceNotConnectedError(
            f"device {device!r} is a {type(found).__name__}, not a hapticlab device",
            deviceClass=HapticlabDevice)
    raise DeviceNotConnectedError(
        f"no hapticlab device named {device!r} on this computer: add one in Builder's "
        "Device Manager (backend 'hapticlab haptic device', spec 'sim' for a dry run or the "
        "lab's serial port), or in code with deviceManager.addDevice(deviceClass="
        f"'psychopy_hapticlab.device.HapticlabDevice', deviceName={device!r}, spec='sim')",
        deviceClass=HapticlabDevice)


def _setter(name: str):
    def set_(self, value, log=None):
        self.fields[name] = value

    set_.__name__ = "set" + name[0].upper() + name[1:]
    set_.__doc__ = f"Set the scene's ``{name}`` (used when the routine next arms)."
    return set_


class HapticContact:
    """One haptic contact per routine: scene, window and data.

    Parameters
    ----------
    device : str or HapticlabDevice
        The device, or its name in DeviceManager (the component's device label).
    name : str
        The component's name: the data columns are ``<name>.<field>``.
    window : str
        ``from first contact`` (``windowDuration`` counts from it, waiting up to
        ``timeout``) or ``fixed`` (from the component's start).
    windowDuration, timeout : float [s]
    traces : str
        One of :data:`TRACE_MODES`.
    traceFolder : str or Path, optional
        Where trace files go (a Builder experiment: ``<data file>_<name>_traces``); None
        keeps none.
    estopKeys : list of str
        Keys that latch the e-stop while the routine runs (empty: none; the device's own
        button always works).
    forceEndRoutine : bool
        End the routine when the window ends.
    experiment : psychopy.data.ExperimentHandler, optional
        Where :meth:`record` writes the row (Builder's ``thisExp``), whose row index is the
        trial id.
    **scene
        The scene's fields (:data:`SCENE_DEFAULTS`), each also a ``set<Field>`` method.
    """

    def __init__(self, device, name: str = "hapticContact", window: str = "from first contact",
                 windowDuration: float = 4.0, timeout: float = 30.0, traces: str = "full",
                 traceFolder=None, estopKeys=("e",), forceEndRoutine: bool = True,
                 experiment=None, **scene: Any):
        unknown = sorted(set(scene) - set(SCENE_DEFAULTS))
        if unknown:
            raise TypeError(f"HapticContact has no scene field {', '.join(unknown)}; the "
                            f"fields are {', '.join(SCENE_DEFAULTS)}")
        if window not in WINDOW_MODES:
            raise ValueError(f"{name}: window must be one of {', '.join(WINDOW_MODES)}, got "
                             f"{window!r}")
        if traces not in TRACE_MODES:
            raise ValueError(f"{name}: traces must be one of {', '.join(TRACE_MODES)}, got "
                             f"{traces!r}")
        for what, v in (("windowDuration", windowDuration), ("timeout", timeout)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name}: {what} must be a finite number of seconds > 0, got "
                                 f"{v!r}")
        self.device = resolve_device(device)
        self.name = name
        self.window = window
        self.windowDuration = float(windowDuration)
        self.timeout = float(timeout)
        self.traces = traces
        self.traceFolder = Path(traceFolder) if traceFolder not in (None, "") else None
        self.estopKeys = [k for k in (estopKeys or []) if k]
        self.forceEndRoutine = bool(forceEndRoutine)
        self.experiment = experiment
        self._phase = "idle"  # armed → running → done, this object's own (Builder sets status)
        self._interrupted = False
        self._clock = None  # the clock of the last record (a rescue records on it too)
        self.fields: dict[str, Any] = {**SCENE_DEFAULTS, **scene}
        self.status = None  # NOT_STARTED / STARTED / FINISHED (psychopy.constants)
        self.scene = None
        self.record_ = None
        self.windows = 0  # windows run by this component (numbers its trace files)
        self.tStart = self.tStop = None

    # ------------------------------------------------------------------ scene
    def makeScene(self):
        """The scene the fields describe now (checked by hapticlab).

        Raises
        ------
        SceneError
            Naming the field and its value (and the conditions row's value as given).
        """
        f = self.fields
        src = str(f["scene"]).strip()
        if src == "built-in sample":
            return _scenes.sample_scene(f["sample"])
        if src == "scene file":
            return _scenes.file_scene(f["sceneFile"])
        if src != "parameters":
            from device import SceneError

            raise SceneError(f"must be one of {', '.join(_scenes.SOURCES)}, got {src!r}",
                             "scene", where=self.name)
        extra = {k: f[k] for k in ("slope", "decay", "frequency", "gain", "decayTime",
                                   "pulseDuration", "librarySource", "attenuation")}
        kind = str(f["transient"]).strip()
        label = kind if kind != "none" else "spring"
        return _scenes.fields_scene(f"{self.name}:{label}", f["spring"], kind,
                                    f["surfaceHeight"], **extra)

    # ------------------------------------------------------------------ a routine
    def trialId(self) -> int:
        """The id this routine's row and its LSL markers share: the row's index in the
        experiment's data (0 for the first row), or this component's window count when it
        records into no experiment."""
        entries = getattr(self.experiment, "entries", None)
        return len(entries) if entries is not None else self.windows

    def arm(self) -> None:
        """Begin Routine: make the scene, load it and home the stylus (output ramped on)."""
        from psychopy.constants import NOT_STARTED

        self.status = NOT_STARTED
        self._phase = "idle"
        self.record_ = None
        self.tStart = self.tStop = None
        self.scene = self.makeScene()
        markers = self.device.markers
        markers.trial(_TrialKey(self.trialId(), f"{self.name}:{self.scene.name}"))
        markers.send("trial_start", component=self.name, scene=self.scene.name)
        self.device.prepare(self.scene)
        markers.send("homed", sample=self.scene.name, window=self.windows)
        self._phase = "armed"

    def start(self) -> None:
        """The component starts: the window begins on the armed scene."""
        from psychopy.constants import STARTED

        if self._phase != "armed":
            raise RuntimeError(f"{self.name}: arm() the scene before starting its window")
        self.device.getResponses(clear=True)  # what came before this window is not its
        self.device.startWindow(self.windowDuration, self.window == WINDOW_MODES[0],
                                self.timeout)
        self._phase = "running"
        self.status = STARTED
        self.windows += 1

    def poll(self, keyboard=None) -> bool:
        """Each frame: responses dispatched, the e-stop keys read (on ``keyboard``, or
        DeviceManager's ``defaultKeyboard``); True once the window has ended and its
        record is kept (``self.record_``)."""
        from psychopy.constants import FINISHED

        if self._phase != "running":
            return self._phase == "done"
        self.device.dispatchMessages()
        if self.estopKeys:
            kb = keyboard if keyboard is not None else _default_keyboard()
            if kb is not None and kb.getKeys(keyList=self.estopKeys, waitRelease=False):
                self.device.estop("e-stop key pressed during the window")
        if self.device.windowRunning:
            return False
        self.record_ = self.device.finishWindow()
        self.device.markers.window(self.record_.result or _NoResult(), self.device.device,
                                   window=self.windows - 1)
        self.device.dispatchMessages()
        self._phase = "done"
        self.status = FINISHED
        return True

    def stop(self) -> None:
        """The component's stop time (or the routine's end) came before the window's end:
        the window ends at the device's next report."""
        import time

        if self._phase == "running":
            self.device.endWindow()
            while not self.poll():
                time.sleep(0.005)
        elif self._phase == "armed":  # armed, never started: output off again
            self.device.device.zero()
            self._phase = "idle"

    def rescue(self) -> None:
        """The experiment ends while this component's window runs (escape): the window ends
        now and its row is recorded, status ``interrupted``, trace file and all, so that
        nothing the device recorded is lost. Builder's code runs it at the experiment's end
        (``runAtExit``); nothing happens when no window runs."""
        if self._phase == "running":
            self.stop()
            self._interrupted = True
            try:
                self.record(raise_fault=False)
            finally:
                self._interrupted = False
        elif self._phase == "armed":
            self.stop()

    # ------------------------------------------------------------------ data
    @property
    def contacts(self) -> list:
        """The last window's :class:`ContactResponse` objects."""
        return [r for r in (self.record_.responses if self.record_ else []) if r.kind == "contact"]

    def data(self, clock=None) -> dict[str, Any]:
        """The routine's data (columns without the ``<name>.`` prefix); times on ``clock``
        (a ``core.Clock``; PsychoPy's time base when None)."""
        rec: WindowRecord | None = self.record_
        dev = self.device
        zero = clock.getLastResetTime() if clock is not None else 0.0
        out: dict[str, Any] = {"scene": self.scene.name if self.scene else "",
                               "scene_kind": self.scene.kind if self.scene else "",
                               "scene_fields": flat_fields(self.scene.to_dict())
                               if self.scene else "",
                               "device": dev.spec, "device_id": dev.info.serial_number}
        if rec is None or rec.result is None:
            out["status"] = "not_run" if rec is None else "failed"
            if rec is not None:
                out["reason"] = rec.error
            return out
        res = rec.result
        status = ("interrupted" if self._interrupted else
                  "estop" if rec.fault is not None and rec.fault.code == "estop" else
                  "fault" if rec.fault is not None else "failed" if rec.error else
                  "timed_out" if res.timed_out else "saturated" if res.saturated else "valid")
        speeds = [round(float(c.velocity), 5) for c in res.contacts]
        times = [rec.on_psychopy(c.t) for c in res.contacts]
        out.update({
            "status": status,
            "reason": (f"{rec.fault.code}: {rec.fault.message}" if rec.fault is not None
                       else "the experiment ended during the window" if self._interrupted
                       else rec.error),
            "n_contacts": len(res.contacts),
            "speeds": speeds,
            "mean_speed": round(sum(speeds) / len(speeds), 5) if speeds else None,
            "contact_times": [None if t is None else round(t - zero, 6) for t in times],
            "contact_times_device": [round(float(c.t), 6) for c in res.contacts],
            "peak_accels": [round(a, 3) for a in rec.peak_accels],
            "peak_accel": None if rec.peak_accel is None else round(rec.peak_accel, 3),
            "saturated": bool(res.saturated),
            "n_saturations": len(res.saturations),
            "peak_current": round(float(res.peak_current), 4),
            "timed_out": bool(res.timed_out),
            "window_started": round(rec.started - zero, 6),
            "warnings": "; ".join(res.warnings),
        })
        if rec.clock:
            out.update({"clock_offset_s": round(rec.clock["offset_s"] - zero, 7),
                        "clock_rate": rec.clock["rate"],
                        "clock_uncertainty_s": rec.clock["uncertainty_s"]})
        else:
            out.update({"clock_offset_s": None, "clock_rate": None,
                        "clock_uncertainty_s": None})
        return out

    def saveTrace(self, stem: str) -> str | None:
        """Write the last window's traces to ``<traceFolder>/traces/<stem>.npz`` in
        hapticlab's recorder format (atomically; never over another); return its path
        relative to the trace folder's parent (the data file's folder), or None when
        nothing is kept."""
        rec = self.record_
        if self.traceFolder is None or self.traces == "none" or rec is None \
                or rec.result is None or not rec.result.traces:
            return None
        from app.recorder import SessionFiles
        from app.runner import trace_payload

        files = SessionFiles(self.traceFolder)
        files.traces.mkdir(parents=True, exist_ok=True)
        name, n = f"{stem}.npz", 1
        while (files.traces / name).exists():
            n += 1
            name = f"{stem}.{n}.npz"
        rel = files.save_trace(name, trace_payload(rec.result, self.traces, self.device.info,
                                                   self.scene.name), rec.result.contacts)
        return f"{self.traceFolder.name}/{rel}"

    def record(self, handler=None, clock=None, raise_fault: bool = True) -> dict[str, Any]:
        """End Routine: the routine's data into ``handler`` (default: the experiment given;
        anything with ``addData``) as ``<name>.<field>``, its trace file written first; an
        LSL ``trial_end`` marker with the same trial id; then a latched fault or a failed
        window raises :class:`HapticFaultError` (the row kept).

        Parameters
        ----------
        handler
            Where the row goes (``thisExp``, or a loop).
        clock : psychopy.core.Clock, optional
            The clock the row's other times are on (Builder's ``globalClock``); PsychoPy's
            time base when None.
        raise_fault : bool
            Raise :class:`HapticFaultError` for a latched fault (after recording).
        """
        handler = handler if handler is not None else self.experiment
        if clock is None:
            clock = self._clock
        self._clock = clock
        self.stop()
        trial = self.trialId()
        data = self.data(clock)
        data["trial_id"] = trial
        data["trace_file"] = self.saveTrace(f"trial-{trial:04d}-{self.name}-{self.windows}") \
            or ""
        if handler is not None:
            for k, v in data.items():
                handler.addData(f"{self.name}.{k}", cell(v))
        markers = self.device.markers
        markers.send("trial_end", status=data["status"], reason=data.get("reason", ""),
                     trace_file=data["trace_file"])
        markers.trial(None)
        logging.exp(f"hapticlab {self.name}: {data.get('status')}, "
                    f"{data.get('n_contacts', 0)} contacts, trace {data['trace_file'] or '-'}")
        self._phase = "idle"
        if raise_fault:
            self.device.raiseFault(self.record_)
        return data


def flat_fields(d: dict, prefix: str = "") -> str:
    """A scene's data as ``key=value`` pairs joined by ``;`` (nested tables dotted:
    ``transient.frequency=100.0``), a form PsychoPy's CSV keeps whole and a reader splits
    back."""
    out = []
    for k, v in d.items():
        if isinstance(v, dict):
            out.append(flat_fields(v, f"{prefix}{k}."))
        else:
            out.append(f"{prefix}{k}={v}")
    return ";".join(x for x in out if x)


def cell(v):
    """``v`` as PsychoPy's CSV writer keeps it whole: it quotes a value with a comma and
    escapes nothing, so a double quote inside becomes a single one."""
    return v.replace('"', "'") if isinstance(v, str) else v


@dataclass(frozen=True)
class _TrialKey:
    """What hapticlab's markers call a trial: a PsychoPy row and the scene felt in it."""

    trial_index: int
    item: str
    attempt: int = 1


class _NoResult:
    """A window that delivered nothing (its link failed before any record)."""

    traces: dict = {}
    t_first_contact = None
    contacts: list = []
    saturations: list = []
    faults: list = []


for _field in SCENE_DEFAULTS:  # setScene, setSpring, setFrequency, … (Builder's updates)
    setattr(HapticContact, "set" + _field[0].upper() + _field[1:], _setter(_field))
del _field


def _default_keyboard():
    from psychopy.hardware import DeviceManager

    return DeviceManager.getDevice("defaultKeyboard")
