"""The ``serial:`` backend: a device speaking the hapticlab wire protocol over USB serial.

``open_device("serial:/dev/ttyACM0")``. This module is the device layer — scene upload,
homing, windows and playbacks, traces — over :class:`~device.serial.link.Link`, which owns
the port, the reader thread, sequencing, retries and heartbeats. An unplugged or silent
device ends the current window with :class:`DeviceGoneError`; nothing already received is
lost, and reconnecting is only done by :meth:`SerialDevice.reconnect`.

The driver installs no signal or exit handlers: the application does (``app.guards``), so
a library user decides what a signal means in their program.

Size: over 700 lines on purpose. :class:`SerialDevice` is the whole device interface over
one link — a scene uploaded in chunks and committed, homing, windows with their streamed
traces, playbacks, faults and their accounts, the device's clock — and each method is a
command sequence on the same link state, read best beside the others. What has a job of
its own lives beside it: the link (:mod:`.link`), the messages and framing (:mod:`.messages`,
:mod:`.framing`), the contract (:mod:`.contract`), the emulator backend (:mod:`.emulated`).
"""

from __future__ import annotations

import math
import threading
import time
import zlib
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from ..base import DeviceInfo, HapticDevice
from ..codes import Blend, SceneKind
from ..errors import DeviceError, DeviceFaultError, DeviceSpecError, SceneError
from ..events import ContactEvent, FaultEvent, HostClock, SaturationEvent, WindowResult
from ..registry import AvailableDevice
from ..scene import Material, Scene, TransientTable
from . import messages as M
from .contract import MAX_WINDOW_MS, PROTOCOL
from .link import (
    CRCStormError,
    DeviceGoneError,
    DeviceTimeoutError,
    Link,
    PortBusyError,
    ProtocolMismatchError,
)

__all__ = ["SerialDevice", "DeviceGoneError", "DeviceTimeoutError", "PortBusyError",
           "ProtocolMismatchError", "CRCStormError", "device_clock_on_host"]

_OPTIONAL = ("true_position", "true_velocity", "true_accel")
#: sensors a device may lack (the commercial devices' bridges have no accelerometer on the
#: stylus): left out of "every channel" when LIMITS says the device records none
_SENSORS = ("accel",)


#: how long a device may take to acknowledge SCENE_COMMIT [s] (docs/wire-protocol.md)
COMMIT_TIMEOUT_S = 2.0


def stream_decimation(lim: M.Limits, n_channels: int, servo_rate_hz: float,
                      share: float = 0.8) -> int:
    """The smallest trace decimation whose framed stream fits in ``share`` of the device's
    link (``LIMITS.link_bytes_s``; the rest is for control frames, STATUS and POSITION).

    Parameters
    ----------
    lim : Limits
        What the device advertised.
    n_channels : int
        Channels streamed per record.
    servo_rate_hz : float [Hz]
        Servo rate (one record per tick at decimation 1).

    Raises
    ------
    DeviceError
        Even ``LIMITS.max_decimation`` does not fit the link.
    """
    if lim.link_bytes_s <= 0:
        return 1
    per = M.TRACE_ITEMS // n_channels  # records in a full chunk, as the device fills them
    full = M.TraceChunk(0, 0, 0, per, (0.0,) * (per * n_channels))
    bytes_per_record = len(M.encode(full, 0, 2)) / per
    for d in range(1, max(1, lim.max_decimation) + 1):
        if servo_rate_hz / d * bytes_per_record <= share * lim.link_bytes_s:
            return d
    raise DeviceError(f"the device's link carries {lim.link_bytes_s} B/s: too little for "
                      f"{n_channels} trace channels even at its largest decimation "
                      f"({lim.max_decimation})")


#: the frames that bound a window's first tick from above come within this of it [s]
_NEAR_S = 0.25


def _lower_hull(t: np.ndarray, h: np.ndarray) -> list[int]:
    """Indices of the lower convex hull of the points (t, h), ``t`` ascending."""
    hull: list[int] = []
    for i in range(len(t)):
        while len(hull) >= 2:
            a, b = hull[-2], hull[-1]
            if (h[b] - h[a]) * (t[i] - t[a]) >= (h[i] - h[a]) * (t[b] - t[a]):
                hull.pop()  # b lies on or above the chord a–i
            else:
                break
        hull.append(i)
    return hull


def device_clock_on_host(pairs, round_trip_s: float | None = None, *,
                         earliest: tuple[float, float] | None = None,
                         rate: float | None = None) -> HostClock:
    """Device time → host perf time, from STATUS frames' (host receipt, device time) pairs.

    Every frame reaches the host after it was stamped, so the device's clock lies below
    every pair. The rate (``rate``, or fitted here) is that of the edge of the pairs' lower
    convex hull above their mean device time: the line under all of them that is highest
    there (the least total delay, as clock synchronisation over one-way messages estimates
    it). It follows a device clock at any rate (a device simulated on a busy computer slips;
    QEMU's ran at 0.71×); a least-squares fit would be tilted by the delays' spread.

    With that rate, the line lowered to the fastest frame is a latest bound: device time
    ``t`` happened no later than it. ``earliest`` = (device time [s], host time [s]) gives
    the other side at that device time: a window's first tick comes after the host sent
    the command that started it. The mapping is centred between the two and half their
    distance is the uncertainty, which then holds at that device time up to the rate's
    error over the time to the frames that bound it from above (those within 0.25 s after
    it, or the first), and later in the span up to the rate's error over the time since. Without
    ``earliest`` the delay of the fastest frame is taken as half the link's fastest round
    trip ``round_trip_s`` [s], an estimate (a frame queued behind others waits longer),
    infinite without one. A clock that is not a
    line over the pairs (one that stepped) leaves a quarter of them far above the line:
    the largest of the quarters' lowest gaps is added to the uncertainty.
    """
    p = np.asarray(list(pairs), float)
    if len(p) < 2:
        raise ValueError("need two STATUS frames or more to put the device's clock on the "
                         "host's")
    p = p[np.lexsort((p[:, 0], p[:, 1]))]  # by device time, the earliest receipt first
    h, t = p[:, 0], p[:, 1]
    if rate is None:
        rate = _hull_rate(t, h)
    lag = h - rate * t
    latest = float(np.min(lag))  # the latest-bound line's offset
    bend = max(float(np.min(q)) for q in np.array_split(lag, 4) if q.size) - latest
    if earliest is not None:
        te, he = earliest
        # the latest bound at te from the frames soon after it, so the rate's error over
        # the whole span does not enter it
        soon = t <= max(te + _NEAR_S, float(t[0]))  # at least the first frame
        upper = float(np.min(lag[soon])) + rate * te
        lo, hi = min(he, upper), max(he, upper)  # crossed: the rate's error, or a step
        return HostClock((lo + hi) / 2 - rate * te, rate, (hi - lo) / 2 + bend, round_trip_s,
                         len(p))
    if round_trip_s is None:
        return HostClock(latest, rate, math.inf, None, len(p))
    return HostClock(latest - round_trip_s / 2, rate, round_trip_s / 2 + bend, round_trip_s,
                     len(p))


def _hull_rate(t: np.ndarray, h: np.ndarray) -> float:
    """Slope of the lower convex hull's edge above the mean of ``t`` (ascending) [1]."""
    if np.ptp(t) <= 0:
        return 1.0
    hull = _lower_hull(t, h)
    mean = float(np.mean(t))
    k = next((j for j in range(len(hull) - 1) if t[hull[j + 1]] >= mean), len(hull) - 2)
    a, b = hull[k], hull[k + 1]
    return float((h[b] - h[a]) / (t[b] - t[a])) if t[b] > t[a] else 1.0


#: the largest force a table item carries [N] (``i16``, 1 mN per LSB)
TABLE_FORCE_MAX = 32.767


def _sample_on_wire(material: Material | None) -> Material | None:
    """A real sample as the device's simulated plant takes it.

    A block that rings as measured goes as the passive block that rings so: its contact's
    stiffness and damping, its mass and the support it rests on
    (:func:`device.sim.plant.block_model`, derived here because a device's firmware has no
    eigensolver; the same block whichever device simulates it). A ringing no passive block
    reproduces goes as described, for a device to refuse if it simulates it; a device with
    a real sample under its stylus ignores all of it.
    """
    if material is None or material.ringing is None or not material.is_block \
            or material.support is not None:
        return material
    from ..sim.plant import block_model

    try:
        b = block_model(material)
    except SceneError:
        return material
    return Material(b.contact_stiffness, b.contact_damping, mass=b.mass, support=b.support)


def _wire_table(table: TransientTable, where: str) -> tuple[np.ndarray, np.ndarray]:
    """The rows of ``table`` as the wire carries them: reference speeds [m/s] and forces
    [mN, ``int16``, shape (rows, row_len)].

    A ``scale`` table plays row 0 × v/v₀ and nothing else, so only row 0 is sent, and at
    the reference speed that makes its largest force fill the item range: the product is
    unchanged, and a row that would not fit (a 200 N·s/m pulse tabulated per 1 m/s is
    200 N) fits, with the finest steps the items allow. In ``nearest`` and ``linear``
    tables the speeds choose the rows, so they go as they are, and a force out of range is
    refused, never clipped.

    Raises
    ------
    SceneError
        A ``nearest`` or ``linear`` table with a force beyond ±32.767 N.
    """
    v = np.asarray(table.velocities, dtype=float)
    f = np.asarray(table.forces, dtype=float)
    if table.blend == Blend.SCALE:
        peak = float(np.max(np.abs(f[0])))
        k = TABLE_FORCE_MAX / peak if peak > 0 else 1.0
        v, f = v[:1] * k, f[:1] * k
    else:
        peak = float(np.max(np.abs(f)))
        if peak > TABLE_FORCE_MAX:
            row, tick = np.unravel_index(int(np.argmax(np.abs(f))), f.shape)
            raise SceneError(f"its transient table has {peak:.6g} N (row {row}, tick {tick}); a "
                             f"{table.blend.label} table carries at most ±{TABLE_FORCE_MAX} N "
                             "per item", "transient", ("transient",), where=where)
    q = np.round(f * 1000.0)
    return v, np.clip(q, -32767, 32767).astype("<i2")



#: what each fault means to the operator (contract.FAULTS); 5–9 are a commercial device's own
#: safety cutting its forces, as its bridge reads it from the vendor's SDK
_FAULT_WHY = {
    "watchdog": "the device heard nothing from this computer for {wd} and zeroed its output "
                "(the computer was held up, or the cable is loose)",
    "nonfinite": "the device computed a current that is not a finite number (a simulated "
                 "device: its stylus left every physical bound) and zeroed its output",
    "device": "the device's own I/O failed (a bridge's SDK refused a position reading or a "
              "force, or its servo loop was held up past its bound) and it zeroed its output; "
              "check the device's cable and power, then clear the fault",
    "force_button": "the device's own force button (or dead-man switch) turned its forces "
                    "off: output zeroed; clear the fault, then home again to turn them on",
    "velocity_limit": "the device's own velocity limit turned its forces off (the stylus moved "
                      "faster than the device allows): output zeroed",
    "force_limit": "the device's own force or force-impulse limit turned its forces off: "
                   "output zeroed; check the ratings the bridge was built with",
    "motor_heat": "the device's motors are too warm and it turned its forces off: let it cool "
                  "before clearing the fault",
    "calibration": "the device is not calibrated (or lost its calibration), so its heights "
                   "are not absolute: output zeroed; calibrate it as its bridge says, then "
                   "clear the fault",
}

class SerialDevice(HapticDevice):
    """Driver for a device on a serial port (or any pyserial URL).

    Parameters
    ----------
    port : str
        Device path or pyserial URL.
    timeout : float [s]
        Wait for each acknowledgement.
    retries : int
        Re-sends of an unacknowledged command (at most 3).
    transport : object, optional
        A pyserial-like object (``read``, ``write``, ``close``) instead of opening ``port``.
    native : bool
        Read the port and heartbeat in a native thread where available (:mod:`.native`);
        False runs them in Python threads.
    """

    def __init__(self, port: str, timeout: float = 0.2, retries: int = 3, transport: Any = None,
                 baudrate: int = 1_000_000, native: bool = True):
        super().__init__()
        self.port = port
        self._fault: FaultEvent | None = None
        self._estop_sent = False  # this host's ESTOP since the last clear (else: the device's)
        self._fault_told = False  # a watchdog fault's account was given (_fault_account)
        self._output = 0.0
        self._scene_id = 0
        self._window_id = 0
        self._decimation = 1  # servo ticks per trace record
        self._status_seen = threading.Event()
        self._status_after_clear = True  # a FAULT state in STATUS is believed
        self._cleared_at = 0.0
        self.last_status: tuple[float, float] | None = None  # (host perf time, device time)
        self._dev_state: int | None = None  # the state the last STATUS reported (M.State)
        #: the last STATUS frames (host perf time [s] at receipt, device time [s]): the
        #: device's clock against the host's (:func:`device_clock_on_host`)
        self.status_log: deque[tuple[float, float]] = deque(maxlen=400)
        #: the last window's first tick [device s] and when its command left [host perf s]
        self._window_sent: tuple[float, float] | None = None
        self.link = Link(port, timeout, retries, transport, baudrate, handler=self._on_message,
                         native=native)
        try:
            self._info = self._identify(self.link.hello(), self.link.limits)
            self._stream = self._configure_traces()
            # the device reports its state at >= 20 Hz: wait for the first report, so a fault
            # it latched before this host connected is known as soon as the device is open
            self._status_seen.wait(timeout=max(0.2, 3 * self.link.timeout))
        except Exception:
            self.link.shutdown()
            raise
        self.link.start_heartbeats(self._info.watchdog_s)

    #: the name this backend is registered as, reported in :attr:`DeviceInfo.backend`
    BACKEND = "serial"

    @classmethod
    def from_spec(cls, arg: str | None = None, **options: Any) -> SerialDevice:
        """Open the device on port ``arg`` (``serial:/dev/ttyACM0``, or a pyserial URL);
        ``seed``, ``live`` and ``speed`` do not apply to a device on a port (its clock is
        its own, a simulated one was seeded when it started)."""
        for common in ("seed", "live", "speed"):
            options.pop(common, None)
        if not arg:
            raise DeviceSpecError("serial spec needs a port: 'serial:/dev/ttyACM0'")
        if arg == "emulator":
            raise DeviceSpecError("'serial:emulator' is now the emulator backend of its own: "
                                  "--device emulator (or emulator:BUILD, e.g. emulator:host)")
        return cls(arg, **options)

    @classmethod
    def available(cls) -> list[AvailableDevice]:
        """Every serial port this computer has (pyserial's list), sorted, none opened."""
        from serial.tools import list_ports

        return [AvailableDevice(f"serial:{p.device}", p.description or "",
                                p.hwid or "")
                for p in sorted(list_ports.comports(), key=lambda p: p.device)]

    @classmethod
    def none_found(cls) -> str:
        """No serial port: the device is unplugged, or this user may not see it."""
        return ("no serial port found: is the device plugged in, and may this user open it? "
                "On Linux a user opens serial ports as a member of the dialout group "
                "(sudo usermod -aG dialout $USER, then log in again)")

    @classmethod
    @contextmanager
    def conformance_opener(cls) -> Iterator[Callable[[], SerialDevice]]:
        """The Python emulator on a pseudo-terminal for the checks, each a new connection
        to it (stopped after)."""
        from .serving import start_emulator

        with start_emulator("python", seed=5) as emu:
            yield lambda: cls.from_spec(emu.port)

    # ------------------------------------------------------------------ state from the wire
    def _on_message(self, msg: M.Message) -> None:
        """Called by the link's reader under its lock for every device message."""
        if isinstance(msg, M.StatusReport):
            self._output = msg.output_mn / 1000.0
            self.last_status = (time.perf_counter(), msg.time_us * 1e-6)
            self.status_log.append(self.last_status)
            self._dev_state = msg.state
            if msg.state != M.State.FAULT:
                self._status_after_clear = True
            elif self._fault is None and (self._status_after_clear
                                          or time.monotonic() > self._cleared_at + 0.25):
                # e.g. latched before this host connected: a real device keeps it (a
                # report sent before a CLEAR_FAULT took effect is not believed: the device
                # reports a new fault with FAULT, and it has said it is clear)
                code = M.FaultCode.NAMES.get(msg.fault, "latched")
                self._fault = FaultEvent(msg.time_us * 1e-6, code,
                                         f"the device reports a latched {code} fault")
            self._status_seen.set()
        elif isinstance(msg, M.Fault):
            code = M.FaultCode.NAMES.get(msg.code, f"fault {msg.code}")
            wd = f"{self._info.watchdog_s * 1e3:g} ms" if hasattr(self, "_info") else "T_wd"
            why = _FAULT_WHY.get(code, f"the device reports a fault this host does not "
                                 f"know (code {msg.code}) and zeroed its output")
            if code == "watchdog":
                why = why.format(wd=wd)
            elif code == "estop":
                why = ("emergency stop (latched): output zeroed" if self._estop_sent else
                       "the device's own e-stop button was pressed: output zeroed")
            self._fault = FaultEvent(msg.time_us * 1e-6, code, why)
            self._fault_told = False
            self._output = 0.0

    @classmethod
    def _identify(cls, h: M.HelloAck, limits: M.Limits | None = None) -> DeviceInfo:
        """What HELLO_ACK and LIMITS say the device is and can do (a device that sends no
        capabilities is taken for a physical one, the safe reading)."""
        if not 1 <= h.protocol <= PROTOCOL:  # an older one is read by its own layouts
            raise ProtocolMismatchError(f"device speaks protocol {h.protocol}, this host "
                                        f"speaks 1 to {PROTOCOL}")
        model, serial_no, fw = h.strings
        return DeviceInfo(backend=cls.BACKEND, model=model, serial_number=serial_no, firmware=fw,
                          servo_rate_hz=float(h.servo_rate_hz),
                          current_limit=h.current_limit_ma / 1000, force_constant=h.force_constant
                          / 1000, effective_mass=h.effective_mass * 1e-6,
                          watchdog_s=h.watchdog_ms / 1000, encoder_resolution=h.encoder_nm * 1e-9,
                          accel_range=h.accel_range / 1000,
                          accelerometer=limits is None or bool(
                              limits.channels >> M.Channel.NAMES.index("accel") & 1),
                          tick_p99_s=limits.tick_p99_us * 1e-6
                          if limits is not None and limits.tick_p99_us else None,
                          tick_max_s=limits.tick_max_us * 1e-6
                          if limits is not None and limits.tick_max_us else None,
                          # a version-2 device states none (can: None): a physical one
                          simulated_contact=bool(limits is not None
                                                 and limits.can("simulated_contact")),
                          seeded=bool(limits is not None and limits.can("seeded")))

    def _configure_traces(self, names: tuple[str, ...] | None = None) -> tuple[str, ...]:
        """Stream ``names`` (None: every base channel the device records, the channels
        :class:`~device.events.WindowResult` carries, but ``accel`` on a device without an
        accelerometer, and the optional ones it has), one
        record per tick unless the device's link is too narrow for that
        (:func:`stream_decimation`). Returns the streamed channel names in order.

        Raises
        ------
        ProtocolMismatchError
            The device speaks version 1 (traces read after each window, retired: the
            emulator and the reference firmware speak 2 and 3), or sent no LIMITS.
        """
        if self.link.version < 2:
            raise ProtocolMismatchError(
                f"{self.port}: the device speaks wire protocol {self.link.version}; hapticlab "
                "needs version 2 (traces streamed during the window): update its firmware "
                "(docs/wire-protocol.md)")
        lim = self.link.limits
        if lim is None:
            raise ProtocolMismatchError(f"{self.port}: a version-2 device sent no LIMITS "
                                        "after HELLO_ACK")
        base = [ch for ch, name in enumerate(M.Channel.NAMES)
                if (name not in _OPTIONAL if names is None else name in names)
                and not (names is None and name in _SENSORS and not lim.channels >> ch & 1)]
        missing = [M.Channel.NAMES[ch] for ch in base if not lim.channels >> ch & 1]
        if missing:
            why = (" (it has no accelerometer on the stylus: acceleration matching, its "
                   "identification and the grasp model need one)" if "accel" in missing
                   else "")
            raise DeviceError(f"{self.port}: the device records no {', '.join(missing)} "
                              f"trace{why}")
        known = (1 << len(M.Channel.NAMES)) - 1  # a bit beyond them names no channel
        mask = sum(1 << ch for ch in base)
        if names is None:
            mask |= lim.channels & known & ~0x7F
        self._decimation = stream_decimation(lim, bin(mask).count("1"),
                                             self._info.servo_rate_hz)
        self._command(M.TraceConfig(mask, self._decimation))
        return tuple(name for ch, name in enumerate(M.Channel.NAMES) if mask >> ch & 1)

    def _command(self, msg: M.Message, timeout: float | None = None) -> None:
        status = self.link.request(msg, timeout)
        if status == M.Status.FAULT_LATCHED:
            code = self._fault.code if self._fault else "?"
            raise DeviceFaultError(f"fault latched ({code}): clear it first"
                                   + self._fault_account(code))
        if status != M.Status.OK:
            raise DeviceError(f"{self.port}: device refused {type(msg).__name__}: "
                              f"{M.Status.NAMES.get(status, status)}")

    # ------------------------------------------------------------------ interface
    @property
    def info(self) -> DeviceInfo:
        return self._info

    @property
    def fault(self) -> FaultEvent | None:
        return self._fault

    @property
    def output_force(self) -> float:
        return 0.0 if (self.closed or self.link.gone) else self._output

    def ping(self, timeout: float = 0.5) -> float:
        """One PING/PONG round trip [s] (also counted in the link statistics)."""
        return self.link.ping(timeout)

    def host_clock(self, span: tuple[float, float] | None = None) -> HostClock | None:
        """The device's clock on this computer's, from the last STATUS frames (up to 400:
        20 s at the 20-Hz floor) and the link's fastest round trip
        (:func:`device_clock_on_host`). Given a ``span`` (device times [s]: a window's),
        the frames within it when there are four (a device's clock may step between its
        windows: a simulated one slips, a board resets), else those within 1 s of it,
        else all; when the span starts at the last window's first
        tick, bounded from below by when the command that started it left; None before
        two frames arrived."""
        pairs = list(self.status_log)
        if len(pairs) < 2:
            return None
        rtt = self.link.fastest_round_trip()
        if span is None:
            return device_clock_on_host(pairs, rtt)
        # the span's own frames: a device's clock may step or change pace between windows
        # (a simulated one slips on a busy computer)
        for pad, least in ((0.0, 4), (1.0, 2)):
            near = [q for q in pairs if span[0] - pad <= q[1] <= span[1] + pad]
            if len(near) >= least:
                pairs = near
                break
        first = self._window_sent  # (t0 [device s], host perf time the command left)
        earliest = first if first is not None and abs(first[0] - span[0]) < 1e-9 else None
        return device_clock_on_host(pairs, rtt, earliest=earliest)

    def link_stats(self) -> dict:
        """The link's figures (:meth:`Link.link_stats`) and, when the device reports them
        (LINK_REPORT), the gaps between this host's frames as its watchdog saw them."""
        out = self.link.link_stats()
        if not self.closed and self.link.gone is None:
            try:
                out["device_saw"] = self.link.device_report()
            except DeviceError:
                out["device_saw"] = None
        return out

    def _fault_account(self, code: str) -> str:
        """For a watchdog fault, once: who fell silent, as this host's heartbeat thread and
        the device each counted it since the link opened (or was last reset). A host that
        wrote its frames on time while the device saw a long gap points at the path between
        them (the port's driver, a bridge's link thread); a late heartbeat or a lapsed
        lease points at this computer."""
        if code != "watchdog" or self._fault_told:
            return ""
        self._fault_told = True
        try:
            st = self.link_stats()
        except DeviceError:
            return ""
        hb, saw = st.get("heartbeats") or {}, st.get("device_saw") or {}
        parts = []
        if hb.get("native"):
            parts.append(f"while heartbeating, this host wrote its frames at most "
                         f"{hb['gap_max_ms']:.1f} ms apart "
                         f"(its heartbeat thread woke at most {hb['wake_late_max_ms']:.1f} ms "
                         f"late, {hb['lease_lapses']} lease lapse(s), longest write "
                         f"{hb['write_max_ms']:.1f} ms)")
        elif hb:
            parts.append(f"this host's heartbeats ran in Python threads "
                         f"({hb['lease_lapses']} lease lapse(s))")
        if saw.get("gap_max_ms") is not None:
            parts.append(f"the device saw them at most {saw['gap_max_ms']:.1f} ms apart")
        return f" [{'; '.join(parts)}]" if parts else ""

    def estop_bound_s(self) -> float | None:
        """The longest an ESTOP may take to zero this device's output, from the frame's
        arrival [s of device time], as its LINK_REPORT counts it (docs §3 and §6): the
        reference firmware looks at every byte as it arrives (the UART's interrupt) and
        an ESTOP's zeroes output at the next servo tick, so one tick and the frame's own
        time on the link, plus one tick because the device counts from when it last found
        its input empty. The Python emulator computes its servo in 1-ms blocks and runs on
        only while its port was found empty within
        :data:`~device.serial.emulator.INPUT_TURN_S`: that wait and two blocks, × its
        speed (in its HELLO_ACK firmware text). None for any other device: its LINK_REPORT
        figure is reported, not judged."""
        fw, model = self._info.firmware, self._info.model
        if model.startswith("hapticlab emulator") and fw.startswith("emulator-2"):
            from .emulator import INPUT_TURN_S

            speed = float(fw[len("emulator-2x"):]) if fw.startswith("emulator-2x") else 1.0
            return (INPUT_TURN_S + 2e-3) * speed
        if model != "hapticlab reference firmware":
            return None  # another maker's device states no bound that we know of
        lim = self.link.limits
        frame = len(M.encode(M.EStop(), 0, self.link.version))
        link = frame / lim.link_bytes_s if lim is not None and lim.link_bytes_s > 0 else 0.0
        return 2 / self._info.servo_rate_hz + link

    def device_link_report(self, reset: bool = False) -> dict | None:
        """The device's view of this host's frames (:meth:`Link.device_report`)."""
        self._check_open()
        return self.link.device_report(reset)

    @property
    def contact_rx(self) -> list[tuple[float, int]]:
        """(host perf time, tick) of every CONTACT frame received (latency measurements)."""
        return self.link.contact_rx

    def _check_open(self) -> None:
        super()._check_open()
        self.link.check()

    @property
    def table_capacity(self) -> int | None:
        lim = self.link.limits
        return None if lim is None else lim.table_items

    def _wire_scene(self, scene: Scene, table: TransientTable | None
                    ) -> tuple[np.ndarray, np.ndarray] | None:
        """``table`` as this device's wire carries it (:func:`_wire_table`), or None.

        Raises
        ------
        SceneError
            An item out of range, or more items than the device's table holds (its
            ``LIMITS.table_items``).
        """
        if table is None:
            return None
        where = f"{self.port}: scene '{scene.name}'"
        velocities, q = _wire_table(table, where)
        cap = self.table_capacity
        if cap is not None and q.size > cap:
            raise SceneError(f"its transient table has {q.size} items ({q.shape[0]} rows × "
                             f"{q.shape[1]} ticks); this device's table holds {cap} "
                             "(LIMITS.table_items)", "transient", ("transient",), where=where)
        return velocities, q

    def _check_scene(self, scene: Scene, table: TransientTable | None) -> None:
        self._wire_scene(scene, table)

    def _load_scene(self, scene: Scene, table: TransientTable | None) -> None:
        wire = self._wire_scene(scene, table)
        self._scene_id = (self._scene_id + 1) & 0xFFFF
        sid = self._scene_id
        ring = scene.material.ringing if scene.material is not None else None
        m = _sample_on_wire(scene.material)
        kind = (SceneKind.REAL if m is not None else
                SceneKind.TABLE if table is not None else SceneKind.SPRING)
        velocities, q = wire if wire is not None else (None, np.zeros((0, 0), "<i2"))
        rows, row_len = q.shape
        self._command(M.SceneBegin(
            sid, int(kind), int(round(scene.surface_height * 1e6)), float(scene.spring or 0.0),
            m.stiffness if m else 0.0, m.damping if m else 0.0, ring.slope if ring else 0.0,
            ring.decay if ring else 0.0, ring.frequency if ring else 0.0,
            (m.mass or 0.0) if m else 0.0, rows, row_len,
            int(table.blend) if table is not None else 0,
            table.attenuation if table is not None else 1.0))
        if m is not None and m.support is not None:
            self._command(M.SceneSupport(sid, m.support.stiffness, m.support.damping))
        crc = 0
        if velocities is not None:  # only what the scene requires: springs upload no table
            self._command(M.SceneVelocities(sid, tuple(float(v) for v in velocities)))
            q = q.reshape(-1)
            for a in range(0, q.size, M.CHUNK_ITEMS):
                part = q[a: a + M.CHUNK_ITEMS]
                self._command(M.SceneChunk(sid, a, part.size, tuple(int(x) for x in part)))
            crc = zlib.crc32(q.tobytes()) & 0xFFFFFFFF
        # a device may take a while to prepare a scene (it keeps sending STATUS meanwhile)
        self._command(M.SceneCommit(sid, crc), timeout=COMMIT_TIMEOUT_S)

    def _set_current_limit(self, amps: float) -> None:
        self._command(M.SetLimit(int(round(amps * 1000))))

    def _home(self, clearance: float | None) -> None:
        c = 0.02 if clearance is None else clearance
        self._command(M.Home(int(round(c * 1e6))))

    def heartbeat(self) -> None:
        self._check_open()
        self.link.heartbeat()

    def _set_trace_channels(self, channels: tuple[str, ...] | None) -> float:
        self._stream = self._configure_traces(channels)
        return self._info.servo_rate_hz / self._decimation

    def _estop(self) -> None:
        self._output = 0.0
        self._estop_sent = True
        if not self.link.gone and not self.closed:
            self._command(M.EStop())
        if self._fault is None:
            self._fault = FaultEvent(time.monotonic(), "estop", "emergency stop (latched)")

    def _clear_fault(self) -> None:
        # a device clears only a fault it has reported (docs §4): one that latched an
        # instant ago (an ESTOP just acknowledged) is told by the next STATUS at the latest
        for attempt in range(2):
            try:
                self._command(M.ClearFault())
                break
            except DeviceFaultError:
                if attempt:
                    raise DeviceFaultError(
                        f"{self.port}: the device keeps its fault: its e-stop button is "
                        "still pressed (or its wire is cut); release it, then clear the "
                        "fault") from None
                seen = self.last_status
                self.link.wait_for(lambda _ev, seen=seen: self.last_status is not seen, 0.5)
        self._fault = None
        self._estop_sent = False
        self._status_after_clear = False  # until a report says the device is clear (or
        self._cleared_at = time.monotonic()  # 0.25 s: ten reports at the slowest rate)

    def _zero(self) -> None:
        self._output = 0.0
        if not self.link.gone and not self.closed:
            self._command(M.Zero())

    @property
    def max_window_s(self) -> float:
        """Longest window [s] the device runs, its wait for a first contact included: its
        ``LIMITS.max_window_ms``, or the protocol's own where it states none."""
        lim = self.link.limits
        stated = lim.max_window_ms if lim is not None else None
        return (stated or MAX_WINDOW_MS) / 1000

    def _max_window_why(self) -> str:
        return "as its LIMITS.max_window_ms states" if self.link.limits is not None and \
            self.link.limits.max_window_ms else "the protocol's longest"

    def _run_window(self, duration: float, from_first_contact: bool, timeout: float,
                    on_progress: Callable[[float, WindowResult], None] | None,
                    heartbeats: bool) -> WindowResult:
        self._window_id = (self._window_id + 1) & 0xFFFF
        wid = self._window_id
        self.link.clear_events()
        sent = time.perf_counter()  # the window's first tick comes after this
        self._command(M.StartWindow(wid, int(round(duration * 1000)), int(round(timeout * 1000)),
                                    int(from_first_contact)))
        limit = (timeout + duration if from_first_contact else duration) + 2.0
        res = self._collect(wid, limit, on_progress, heartbeats)
        if len(res.traces.get("t", ())):
            self._window_sent = (float(res.traces["t"][0]), sent)
        return res

    def _play_force(self, f: np.ndarray, heartbeats: bool,
                    on_progress: Callable[[float, WindowResult], None] | None = None
                    ) -> WindowResult:
        q = np.clip(np.round(f * 1000), -32768, 32767).astype("<i2")
        lim = self.link.limits
        if lim is not None and q.size > lim.play_items:
            secs = lim.play_items / self._info.servo_rate_hz
            raise DeviceError(f"{self.port}: a playback of {q.size} samples; this device "
                              f"holds {lim.play_items} ({secs:.2f} s)")
        for a in range(0, q.size, M.CHUNK_ITEMS):
            part = q[a: a + M.CHUNK_ITEMS]
            self._command(M.PlayChunk(a, part.size, tuple(int(x) for x in part)))
        self._window_id = (self._window_id + 1) & 0xFFFF
        wid = self._window_id
        self.link.clear_events()
        self._command(M.PlayStart(wid, q.size))
        return self._collect(wid, q.size / self._info.servo_rate_hz + 2.0, on_progress,
                             heartbeats)

    def _collect(self, wid: int, limit: float, on_progress, heartbeats: bool) -> WindowResult:
        rate = self._info.servo_rate_hz
        contacts: list[ContactEvent] = []
        sats: list[SaturationEvent] = []
        height: float | None = None  # the stylus above the surface [m], from POSITION frames
        done: M.WindowDone | None = None
        faults: list[FaultEvent] = []
        chunks: list[M.TraceChunk] = []  # the trace, streamed during the window
        lost: list[M.TraceLost] = []
        self.link.pause_heartbeats(not heartbeats)
        start = time.monotonic()
        deadline = start + limit
        next_progress = start + 0.1
        # the device's clock when the window began: a device simulated on a busy computer
        # (QEMU) runs slower than this one's, so the limit is judged in its time
        dev_start = self.last_status[1] if self.last_status is not None else None
        try:
            while done is None:
                items, gone = self.link.take_events()
                for e in items:
                    if isinstance(e, M.Contact) and e.window_id == wid:
                        contacts.append(ContactEvent(e.tick / rate, e.velocity_nm_s * 1e-9))
                    elif isinstance(e, M.Saturation) and e.window_id == wid:
                        sats.append(SaturationEvent(e.tick / rate, e.peak_ma / 1000,
                                                    e.duration / rate))
                    elif isinstance(e, M.Fault):
                        faults.append(self._fault)
                    elif isinstance(e, M.WindowDone) and e.window_id == wid:
                        done = e
                    elif isinstance(e, M.Position) and e.window_id == wid:
                        height = e.height_um * 1e-6
                    elif isinstance(e, M.TraceChunk) and e.window_id == wid:
                        chunks.append(e)
                    elif isinstance(e, M.TraceLost) and e.window_id == wid:
                        lost.append(e)
                if gone is not None:
                    err = type(gone)(f"{gone}; the window was aborted after {len(contacts)} "
                                     "contacts")
                    err.partial = WindowResult(rate, None, list(contacts), list(sats),
                                               [f for f in faults if f is not None][:1])
                    raise err
                now = time.monotonic()
                if now > deadline and self._overdue(dev_start, limit, now - start):
                    why = self._why_overdue(dev_start, now - start)
                    self._stop_window()
                    raise DeviceTimeoutError(f"{self.port}: window {wid} did not end in time "
                                             f"({limit:g} s of the device's time); {why}")
                if on_progress is not None and time.monotonic() >= next_progress:
                    next_progress = time.monotonic() + 0.1
                    partial = WindowResult(rate, None, list(contacts))
                    partial.live_height = height
                    on_progress(time.monotonic() - start, partial)
        except BaseException:
            if self.link.gone is None:
                self._stop_window()  # an exception in the caller's callback, an interrupt…
            raise
        finally:
            self.link.pause_heartbeats(False)
        t0 = done.t0_us * 1e-6
        d = self._decimation
        n_rec = -(-done.n_ticks // d)  # record i is the window's tick i·d
        traces = self._assemble(wid, n_rec, chunks, lost)
        traces["t"] = t0 + np.arange(n_rec) * d / rate
        first = None if done.first_contact < 0 else t0 + done.first_contact / rate
        res = WindowResult(rate / d, first,
                           [ContactEvent(t0 + c.t, c.velocity) for c in contacts],
                           [SaturationEvent(t0 + s.t, s.peak_current, s.duration) for s in sats],
                           [f for f in faults if f is not None][:1], traces,
                           timed_out=bool(done.timed_out))
        if res.faults:
            # the device reports its own time; express it on the window's clock, within the
            # window's ticks (its last tick may lie after the last record when decimated)
            f = res.faults[0]
            t_last = t0 + max(done.n_ticks - 1, 0) / rate
            res.faults = [FaultEvent(max(t0, min(f.t, t_last)), f.code, f.message)]
            self._fault = res.faults[0]
        return res

    def _overdue(self, dev_start: float | None, limit: float, wall: float) -> bool:
        """Past a window's ``limit`` [s]: in the device's own time (its STATUS frames), or,
        for a device whose clock has not moved that far, after ten times the limit of
        this computer's (a device that reports but whose clock stands still)."""
        if self.last_status is None or dev_start is None:
            return True
        return self.last_status[1] - dev_start >= limit or wall >= 10 * limit

    def _why_overdue(self, dev_start: float | None, wall: float) -> str:
        """What the link knew when a window was given up on: the device's last reported
        state and clock, and the frames that went missing on the way (by the device's
        sequence numbers) or failed their check."""
        names = {v: k.lower() for k, v in vars(M.State).items() if isinstance(v, int)}
        state = names.get(self._dev_state, "unknown") if self._dev_state is not None else "unknown"
        dev = ("no report of its clock" if self.last_status is None or dev_start is None else
               f"{self.last_status[1] - dev_start:.2f} s of its clock")
        st = self.link.stats
        ended = ("no STATUS said whether the device had left the window"
                 if self._dev_state is None else
                 "the device was still in it"
                 if self._dev_state in (M.State.WINDOW, M.State.PLAYING) else
                 "the device had left the window, so its WINDOW_DONE frame was lost")
        return (f"{ended} (last STATUS: {state}; {dev} and {wall:.2f} s of this computer's "
                f"passed; link: {st['lost']} frames missing, {st['crc_errors']} failed their "
                f"CRC, {st['other_errors']} other errors)")

    def _end_window(self) -> None:
        """STOP_WINDOW with the link's usual tries (OK in every state; the window's
        WINDOW_DONE follows). Unanswered, the window runs its time, as it would have without
        the request; the session is not given up for it."""
        self._stop_window(timeout=None)

    def _stop_window(self, timeout: float | None = 0.05) -> None:
        """Best effort: end a window (one the host gave up on: one short try, so the device
        is free again)."""
        try:
            self.link.request(M.StopWindow(), timeout=timeout)
        except DeviceError:
            pass

    def _assemble(self, wid: int, n: int, chunks: list, lost: list) -> dict[str, np.ndarray]:
        """The window's traces from the chunks streamed during it. Every record
        must be covered exactly once; a gap the device reported (TRACE_LOST) or one it did
        not is a DeviceError naming the records, never a silent hole."""
        names = self._stream
        data = np.full((n, len(names)), np.nan, dtype=np.float32)
        seen = np.zeros(n, np.int16)
        for c in chunks:
            if c.channels != sum(1 << M.Channel.NAMES.index(x) for x in names):
                raise DeviceError(f"{self.port}: window {wid} streamed channels "
                                  f"0x{c.channels:x}, not the configured ones")
            if not 0 <= c.start <= c.start + c.n <= n:
                raise DeviceError(f"{self.port}: trace records {c.start}–{c.start + c.n - 1} "
                                  f"lie outside window {wid}'s {n} records")
            data[c.start:c.start + c.n] = np.asarray(c.items, np.float32).reshape(c.n, -1)
            seen[c.start:c.start + c.n] += 1
        if lost:
            said = ", ".join(f"{x.start}–{x.start + x.n - 1}" for x in lost[:3])
            raise DeviceError(f"{self.port}: the device dropped trace records {said} of window "
                              f"{wid} ({sum(x.n for x in lost)} of {n}; its ring buffer "
                              "overflowed: the link is too slow for the channels asked)")
        if (seen != 1).any():
            bad = np.flatnonzero(seen != 1)
            what = "missing" if seen[bad[0]] == 0 else "sent twice"
            raise DeviceError(f"{self.port}: window {wid}'s trace record {bad[0]} is {what} "
                              f"({bad.size} of {n} records not covered exactly once)")
        out = {name: data[:, k].astype(float) for k, name in enumerate(names)}
        if "flags" in out:
            out["flags"] = out["flags"].astype(np.uint16)
        return out

    # ------------------------------------------------------------------ exits
    def _close(self) -> None:
        """Zero output (best effort), stop the threads, release the port."""
        try:
            if not self.link.gone:
                self.link.request(M.Zero(), timeout=0.05)
        except DeviceError:
            pass
        self._output = 0.0
        self.link.shutdown()

    def reconnect(self) -> None:
        """Reopen the port after the device was gone (explicit, never automatic)."""
        self.link.shutdown()
        self.__init__(self.port, self.link.timeout, self.link.retries, None, self.link.baudrate,
                      self.link.native)
