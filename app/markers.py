"""Event markers on Lab Streaming Layer: the session's events on the clock an EEG amplifier,
an eye tracker or a motion-capture system records with.

A session run with ``--lsl`` opens one string-marker outlet (``pylsl``, the ``hapticlab[lsl]``
extra): each marker is a JSON object with its ``event`` (:data:`EVENTS`), the trial's
``trial``, ``item`` and ``attempt`` (the columns of trials.tsv that name its row) and the
event's own values. Host events are stamped with :func:`pylsl.local_clock` when they happen;
device events (contacts, saturation, faults) with the device's time put on that clock
through the link's measured clock (:meth:`device.HapticDevice.host_clock`), sent when their
window ends, in time order. session.json's ``lsl`` block records, per run of the session, the
stream, the LSL clock against the UTC wall clock, and each window's device clock on the LSL
clock with its uncertainty, so markers, trials.tsv and the trace files line up afterwards.

liblsl finds its peers by multicast and broadcast: hapticlab loads it with the lab's own
configuration when ``LSLAPICFG`` names one, and otherwise with :func:`machine_config`, which
keeps discovery on this computer (LabRecorder on the same computer finds the stream).
"""

from __future__ import annotations

import datetime as dt
import json
import math
import os
import socket
import struct
import time
from collections.abc import Callable
from importlib import resources
from pathlib import Path

from device.errors import HapticlabError

__all__ = ["EVENTS", "MarkerSink", "LslMarkers", "machine_config", "LslUnavailable",
           "PRIVATE_ENV", "private_network_problem", "load_pylsl"]

#: event → what it marks (the README lists them)
EVENTS: dict[str, str] = {
    "session_start": "the session (or a resume of it) begins: participant, session, protocol",
    "trial_start": "an attempt begins: the participant is told to tap",
    "homed": "the device holds the stylus at its start height, ready for the window",
    "window_start": "the device's tapping window begins (device time)",
    "first_contact": "the stylus first touches the surface (device time)",
    "tap": "a contact, with the incoming speed the device estimated [m/s] (device time)",
    "saturation": "the commanded current was clamped: peak [A], duration [s] (device time)",
    "estop": "the emergency stop zeroed the output (device time when in a window)",
    "fault": "another latched fault zeroed the output: its code (device time in a window)",
    "rating_onset": "the rating (or naming) screen asks for an answer",
    "response": "the participant answered: rating or answer, response time [s]",
    "trial_end": "the attempt is recorded: its status (valid, saturated, timed_out, …)",
    "session_end": "the session stops: complete, interrupted or stopped",
}

_SIOCGIFFLAGS, _IFF_UP = 0x8913, 0x1  # <linux/sockios.h>, <net/if.h>

#: how long a closing outlet stays for a recorder to take its last markers [s]
_DRAIN_S = 1.0

#: the environment variable that, set to 1, makes hapticlab refuse to load liblsl outside a
#: network namespace with loopback alone (the test suite sets it)
PRIVATE_ENV = "HAPTICLAB_LSL_PRIVATE"


class LslUnavailable(HapticlabError):
    """LSL markers were asked for and cannot be sent (no pylsl, or no private network where
    one is required)."""


def machine_config() -> Path:
    """hapticlab's liblsl configuration that keeps discovery on this computer: machine
    scope, IPv6 off, loopback as the only multicast address, listening address and peer
    (keys checked against liblsl 1.18's ``api_config``)."""
    return Path(str(resources.files("app") / "data" / "lsl_machine.cfg"))


def private_network_problem() -> str | None:
    """Why this process is not in a network namespace with loopback alone, up, or None.

    Asked of the kernel for this process's namespace (``if_nameindex`` and the interface
    flags): ``/sys/class/net`` shows the namespace sysfs was mounted in, not this one's.
    """
    import fcntl  # Linux: the only system hapticlab makes private networks on

    try:
        names = sorted(name for _, name in socket.if_nameindex())
    except OSError as exc:
        return f"cannot list the network interfaces ({exc})"
    if names != ["lo"]:
        return f"network interfaces {', '.join(n for n in names if n != 'lo')} besides loopback"
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            req = struct.pack("16sh", b"lo", 0)
            flags = struct.unpack("16sh", fcntl.ioctl(s, _SIOCGIFFLAGS, req))[1]
    except OSError as exc:
        return f"cannot read loopback's flags ({exc})"
    return None if flags & _IFF_UP else "loopback is down"


def _utc() -> str:
    return dt.datetime.now(dt.UTC).isoformat(timespec="microseconds")


class MarkerSink:
    """Where a session's events go: this base sends nothing (a session without ``--lsl``).

    Subclasses implement :meth:`_push` and :meth:`now`; the runner calls :meth:`send` for
    host events and :meth:`window` for the device events of a finished window. A marker
    that cannot be sent never stops the session: the first failure is said once
    (``say``) and every failure counted in the run's record.
    """

    active = False

    def __init__(self, say: Callable[[str], None] | None = None) -> None:
        self.sent = 0
        #: this run's record for session.json (see :meth:`LslMarkers.__init__`)
        self.run: dict = {}
        self._say = say or (lambda _text: None)
        self._trial_key: dict = {}
        self._open = False  # a trial_start without its trial_end
        self._faults: set[tuple[str, float]] = set()  # (code, device time) already marked

    def now(self) -> float:
        """The markers' clock [s]."""
        return time.perf_counter()

    def from_perf(self, t: float) -> float:
        """A :func:`time.perf_counter` time [s] on the markers' clock."""
        return t

    def _push(self, text: str, stamp: float) -> None:
        pass

    def wait_for_consumer(self, timeout: float, say) -> bool:
        """True once a recorder receives the markers (this base: at once)."""
        return True

    def close(self) -> None:
        pass

    def trial(self, trial) -> None:
        """The attempt later markers belong to (None: between attempts)."""
        self._trial_key = {} if trial is None else {
            "trial": trial.trial_index, "item": trial.item, "attempt": trial.attempt}

    def send(self, event: str, stamp: float | None = None, **fields) -> None:
        """One marker: ``event`` (a key of :data:`EVENTS`) with the attempt's keys and
        ``fields`` (a value that is not a finite number goes as null), stamped ``stamp``
        [s, the markers' clock] or now."""
        if event not in EVENTS:
            raise ValueError(f"unknown marker event {event!r}")
        if not self.active:
            return
        if event == "trial_start":
            self._open = True
        elif event == "trial_end":
            self._open = False
        body = {"event": event, **self._trial_key,
                **{k: _json_value(v) for k, v in fields.items()}}
        try:
            self._push(json.dumps(body, separators=(",", ":"), allow_nan=False),
                       self.now() if stamp is None else stamp)
        except Exception as exc:  # noqa: BLE001 — markers never stop a session
            failed = self.run.get("send_failures", 0)
            self.run["send_failures"] = failed + 1
            if not failed:
                self._say(f"warning: an LSL marker could not be sent ({exc}); the session "
                          "goes on, and session.json counts the markers lost")
            return
        self.sent += 1

    def unfinished(self, why: str) -> None:
        """An attempt that began and ends without a row (a fault before its window, an
        answer the scale refuses): its ``trial_end`` says so, status ``not_recorded``."""
        if self._open:
            self.send("trial_end", status="not_recorded", reason=why)
        self.trial(None)

    def window(self, res, device, *, window: int) -> None:
        """The device events of a window ``res`` (whole, or the part a device error left),
        in device time order, each stamped with the device's time on the markers' clock
        through ``device``'s clock over the window (:meth:`device.HapticDevice.host_clock`;
        a device without one, as the simulator in virtual time, has its events stamped
        now, when the host learned of them). Each carries its device time ``t_device_s``;
        the window's clock goes into the run's record."""
        if not self.active:
            return
        traces_t = res.traces.get("t")
        t0 = float(traces_t[0]) if traces_t is not None and len(traces_t) else None
        clock = device.host_clock(None if t0 is None else (t0, float(traces_t[-1])))
        events: list[tuple[float, str, dict]] = []
        if t0 is not None:
            events.append((t0, "window_start", {"window": window}))
        if res.t_first_contact is not None:
            events.append((res.t_first_contact, "first_contact", {}))
        events += [(c.t, "tap", {"speed_m_s": round(c.velocity, 5)}) for c in res.contacts]
        events += [(s.t, "saturation", {"peak_current_a": round(s.peak_current, 4),
                                        "duration_s": round(s.duration, 6)})
                   for s in res.saturations]
        for f in res.faults:
            self._faults.add((f.code, f.t))
            events.append((f.t, "estop" if f.code == "estop" else "fault",
                           {"code": f.code, "message": f.message}))
        events.sort(key=lambda e: e[0])  # stable: window start, first contact, its tap
        now = self.now()
        entry = {**self._trial_key, "window": window, "t0_device_s": t0}
        if clock is None:
            entry["clock"] = "none: device events stamped when the window ended"
        else:
            entry.update(t0_lsl_s=None if t0 is None else self.from_perf(clock.on_host(t0)),
                         offset_s=self.from_perf(clock.offset_s), rate=clock.rate,
                         uncertainty_s=_json_value(clock.uncertainty_s),
                         round_trip_s=clock.round_trip_s, frames=clock.pairs)
        self.run.setdefault("windows", []).append(entry)
        for t, event, fields in events:
            stamp = now if clock is None else self.from_perf(clock.on_host(t))
            self.send(event, stamp, t_device_s=round(t, 6), **fields)

    def fault(self, fault) -> None:
        """A latched fault the runner meets (an e-stop between trials, a pause for one):
        marked now, unless its window's markers already carried it."""
        if (fault.code, fault.t) in self._faults:
            return
        self._faults.add((fault.code, fault.t))
        self.send("estop" if fault.code == "estop" else "fault", code=fault.code,
                  message=fault.message)


def _json_value(v):
    """``v`` as a marker carries it: a number that is not finite as None."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def load_pylsl():
    """pylsl, with liblsl configured: the lab's ``LSLAPICFG`` when set, else
    :func:`machine_config`. Called before a session folder is made, so that a session that
    cannot send markers leaves nothing behind.

    Raises
    ------
    LslUnavailable
        pylsl is not installed, or :data:`PRIVATE_ENV` asks for a private network and this
        process is not in one (checked before liblsl loads).
    """
    if os.environ.get(PRIVATE_ENV) == "1" and (why := private_network_problem()):
        raise LslUnavailable(f"{PRIVATE_ENV}=1 and this process is not in a private "
                             f"network ({why}): liblsl is not loaded")
    os.environ.setdefault("LSLAPICFG", str(machine_config()))
    try:
        import pylsl
    except ImportError as exc:
        raise LslUnavailable("LSL markers need pylsl: pip install 'hapticlab[lsl]'") from exc
    return pylsl


class LslMarkers(MarkerSink):
    """The session's markers on an LSL string outlet.

    Parameters
    ----------
    name : str
        Stream name (LabRecorder lists it).
    source_id : str
        Stable id of the session, so a recorder picks the stream up again after a resume.
    description : dict of str → str
        Written into the stream's description (participant, session, protocol, device).
    say : callable, optional
        Where a marker that could not be sent is said (once).

    Raises
    ------
    LslUnavailable
        As :func:`load_pylsl`, or liblsl could not open the outlet.
    """

    active = True

    def __init__(self, name: str, source_id: str, description: dict[str, str],
                 say: Callable[[str], None] | None = None):
        super().__init__(say)
        pylsl = load_pylsl()
        self._lsl = pylsl
        try:
            info = pylsl.StreamInfo(name, "Markers", 1, pylsl.IRREGULAR_RATE,
                                    pylsl.cf_string, source_id)
            desc = info.desc()
            desc.append_child_value("manufacturer", "hapticlab")
            for k, v in description.items():
                desc.append_child_value(k, str(v))
            desc.append_child_value("format", "one JSON object per marker; 'event' names it")
            self._outlet = pylsl.StreamOutlet(info)
        except Exception as exc:  # noqa: BLE001 — liblsl's errors are RuntimeError and kin
            raise LslUnavailable(f"liblsl could not open the marker stream: {exc}") from exc
        self._offset, self._offset_unc = self._perf_offset()
        self.run = {"started_utc": _utc(), "config": os.environ["LSLAPICFG"],
                    "liblsl": pylsl.library_version(),
                    "lsl_minus_perf_s": self._offset,
                    "lsl_minus_perf_uncertainty_s": self._offset_unc,
                    "wall": [self._wall_pair()], "windows": []}
        self.stream = {"name": name, "type": "Markers", "source_id": source_id,
                       "format": "string: one JSON object per marker"}

    def now(self) -> float:
        return self._lsl.local_clock()

    def from_perf(self, t: float) -> float:
        return t + self._offset

    def _perf_offset(self) -> tuple[float, float]:
        """local_clock − perf_counter [s] and its uncertainty: the tightest of 50 readings
        of the LSL clock bracketed by two of perf_counter."""
        best = (math.inf, 0.0)
        for _ in range(50):
            a = time.perf_counter()
            lsl = self._lsl.local_clock()
            b = time.perf_counter()
            if b - a < best[0]:
                best = (b - a, lsl - (a + b) / 2)
        return best[1], best[0] / 2

    def _wall_pair(self) -> dict:
        """The UTC wall clock against the LSL clock, within the bracket's half-width (and
        the microsecond the UTC text is written to)."""
        a = self._lsl.local_clock()
        utc = _utc()
        b = self._lsl.local_clock()
        return {"utc": utc, "lsl_s": (a + b) / 2, "uncertainty_s": (b - a) / 2 + 1e-6}

    def _push(self, text: str, stamp: float) -> None:
        self._outlet.push_sample([text], stamp)

    def wait_for_consumer(self, timeout: float, say) -> bool:
        """Wait up to ``timeout`` [s] for a recorder, in 0.1-s steps (so Ctrl-C and SIGTERM
        act at once)."""
        if self._outlet.have_consumers():
            return True
        say(f"LSL: waiting up to {timeout:g} s for a recorder to receive the stream "
            f"'{self.stream['name']}' (select it in LabRecorder and start recording)")
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self._outlet.wait_for_consumers(min(0.1, max(0.0, end - time.monotonic()))):
                return True
        return bool(self._outlet.have_consumers())

    def close(self) -> None:
        """End the stream. liblsl drops what an outlet has not sent when it goes, and the
        last markers were pushed a moment ago: a recorder gets 1 s to take them."""
        if self._outlet is None:
            return
        if self._outlet.have_consumers():
            time.sleep(_DRAIN_S)
        self.run["wall"].append(self._wall_pair())
        self.run["markers_sent"] = self.sent
        self._outlet = None  # the stream disappears from the network
        self.active = False
