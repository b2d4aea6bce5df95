"""The ``serial:`` backend: a device speaking the hapticlab wire protocol over USB serial.

``open_device("serial:/dev/ttyACM0")``. The port is opened exclusively; a background
thread reads and decodes frames; another sends heartbeats every T_wd/4. Every command
waits for its ACK (same sequence number) with a timeout and is retried at most three
times before the device is declared faulty. An unplugged device (pyserial raises
``SerialException`` or a plain ``OSError``, depending on the call) or a silent one (no
frame for two heartbeat periods while a status stream is due) ends the current window
with :class:`DeviceGoneError`; nothing already received is lost, and reconnecting is
only done by :meth:`SerialDevice.reconnect`.
"""

from __future__ import annotations

import atexit
import math
import signal
import threading
import time
import weakref
import zlib
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np

from ..base import DeviceInfo, HapticDevice
from ..errors import DeviceError, DeviceFaultError
from ..events import ContactEvent, FaultEvent, SaturationEvent, WindowResult
from ..scene import LibraryTransient, Scene, TransientTable
from . import messages as M
from .framing import FrameDecoder

__all__ = ["SerialDevice", "DeviceGoneError", "DeviceTimeoutError", "PortBusyError",
           "ProtocolMismatchError", "CRCStormError"]


class DeviceGoneError(DeviceError):
    """The device was unplugged or stopped talking; the current trial is aborted.

    Attributes
    ----------
    partial : WindowResult or None
        What the window had delivered before the device went (contacts, saturations), so
        nothing received is lost.
    """

    partial: WindowResult | None = None


class DeviceTimeoutError(DeviceError):
    """A command got no acknowledgement after all retries."""


class PortBusyError(DeviceError):
    """The port is open elsewhere (exclusive access refused)."""


class ProtocolMismatchError(DeviceError):
    """The other end does not speak this protocol version (or at all)."""


class CRCStormError(DeviceError):
    """Too many corrupt frames in a short time: the link is unusable."""


_BLEND = {"scale": 0, "nearest": 1, "linear": 2}
_CHANNELS = ("position", "velocity", "force_cmd", "force_out", "current", "accel", "flags")
_OPTIONAL = ("true_position", "true_velocity", "true_accel")


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
    """

    def __init__(self, port: str, timeout: float = 0.2, retries: int = 3, transport: Any = None,
                 baudrate: int = 1_000_000):
        if not 0 <= retries <= 3:
            raise ValueError(f"retries must be 0–3, got {retries!r}")
        self.port = port
        self.timeout = float(timeout)
        self.retries = int(retries)
        self._baud = baudrate
        self._ser = transport if transport is not None else self._open(port)
        self._decoder = FrameDecoder()
        self._wlock = threading.Lock()
        self._cv = threading.Condition()
        self._seq = 0
        self._acks: dict[int, int] = {}
        self._events: deque = deque()
        self._gone: str | None = None
        self._closed = False
        self._last_rx = time.monotonic()
        self._dev_seq: int | None = None
        self._fault: FaultEvent | None = None
        self._output = 0.0
        self._scene_id = 0
        self._window_id = 0
        self._loaded: Scene | None = None
        self._hb_pause = threading.Event()
        self.last_status: tuple[float, float] | None = None  # (host perf time, device time)
        self.contact_rx: list[tuple[float, int]] = []  # (host perf time, tick) per CONTACT
        self.stats = {"frames_sent": 0, "frames_ok": 0, "crc_errors": 0, "other_errors": 0,
                      "timeouts": 0, "retries": 0, "lost": 0, "duplicates": 0,
                      "out_of_order": 0}
        self._rtt: deque[float] = deque(maxlen=4096)
        self._crc_times: deque[float] = deque(maxlen=50)
        self._reader = threading.Thread(target=self._read_loop, name="serial-reader", daemon=True)
        self._reader.start()
        try:
            self._info = self._handshake()
        except Exception:
            self._shutdown_io()
            raise
        self._hb = threading.Thread(target=self._heartbeat_loop, name="serial-heartbeat",
                                    daemon=True)
        self._hb.start()
        self._install_exit_guards()

    @classmethod
    def from_spec(cls, arg: str | None = None, **options: Any) -> SerialDevice:
        if not arg:
            raise DeviceError("serial spec needs a port: 'serial:/dev/ttyACM0'")
        return cls(arg, **options)

    # ------------------------------------------------------------------ port
    def _open(self, port: str):
        import serial

        try:
            return serial.serial_for_url(port, baudrate=self._baud, timeout=0.01,
                                         write_timeout=0.5, exclusive=True)
        except serial.SerialException as exc:
            msg = str(exc)
            if "lock" in msg.lower() or "busy" in msg.lower():
                raise PortBusyError(f"{port}: port is in use by another program ({msg})") from None
            raise DeviceGoneError(f"{port}: cannot open ({msg})") from None
        except OSError as exc:
            raise DeviceGoneError(f"{port}: cannot open ({exc})") from None

    def _write(self, data: bytes) -> None:
        if self._gone:
            raise DeviceGoneError(self._gone)
        try:
            with self._wlock:
                self._ser.write(data)
            self.stats["frames_sent"] += 1
        except Exception as exc:  # SerialException, SerialTimeoutException or OSError
            self._mark_gone(f"{self.port}: write failed ({exc})")
            raise DeviceGoneError(self._gone) from None

    def _mark_gone(self, why: str) -> None:
        with self._cv:
            if self._gone is None:
                self._gone = why
            self._cv.notify_all()

    def _read_loop(self) -> None:
        while not self._closed and self._gone is None:
            try:
                # pyserial's read(n) waits for n bytes or its timeout: ask for one byte (returns
                # as soon as it arrives), then for whatever else is already waiting
                data = self._ser.read(1)
                if data:
                    waiting = getattr(self._ser, "in_waiting", 0)
                    if waiting:
                        data += self._ser.read(waiting)
            except Exception as exc:  # SerialException or OSError: unplugged
                self._mark_gone(f"{self.port}: device gone ({type(exc).__name__}: {exc})")
                return
            if not data:
                continue
            before_crc = self._decoder.errors["crc"]
            for frame in self._decoder.feed(data):
                self._last_rx = time.monotonic()
                self._account_seq(frame.seq)
                try:
                    msg = M.decode(frame)
                except M.MessageError:
                    self.stats["other_errors"] += 1
                    continue
                self._dispatch(msg)
            self.stats["frames_ok"] = self._decoder.frames_ok
            self.stats["crc_errors"] = self._decoder.errors["crc"]
            self.stats["other_errors"] = sum(v for k, v in self._decoder.errors.items()
                                             if k != "crc")
            now = time.monotonic()
            for _ in range(self._decoder.errors["crc"] - before_crc):
                self._crc_times.append(now)
            if len(self._crc_times) >= 20 and now - self._crc_times[-20] < 1.0:
                self._mark_gone(f"{self.port}: CRC storm (20 corrupt frames within 1 s)")
                return

    def _account_seq(self, seq: int) -> None:
        if self._dev_seq is not None:
            d = (seq - self._dev_seq) & 0xFFFF
            if d == 0:
                self.stats["duplicates"] += 1
                return
            if d > 0x8000:
                self.stats["out_of_order"] += 1
                return
            self.stats["lost"] += d - 1
        self._dev_seq = seq

    def _dispatch(self, msg: M.Message) -> None:
        if isinstance(msg, M.Contact):
            self.contact_rx.append((time.perf_counter(), msg.tick))
        with self._cv:
            if isinstance(msg, M.Ack):
                self._acks[msg.ack_seq] = msg.status
            elif isinstance(msg, M.StatusReport):
                self._output = msg.output_mn / 1000.0
                self.last_status = (time.perf_counter(), msg.time_us * 1e-6)
                if msg.state == M.State.FAULT and self._fault is None:
                    # e.g. latched before this host connected: a real device keeps it
                    code = M.FaultCode.NAMES.get(msg.fault, "latched")
                    self._fault = FaultEvent(msg.time_us * 1e-6, code,
                                             f"the device reports a latched {code} fault")
            else:
                if isinstance(msg, M.Fault):
                    code = M.FaultCode.NAMES.get(msg.code, f"fault {msg.code}")
                    self._fault = FaultEvent(msg.time_us * 1e-6, code,
                                             "emergency stop (latched): output zeroed"
                                             if code == "estop" else
                                             "no heartbeat: output zeroed by the device")
                    self._output = 0.0
                self._events.append(msg)
            self._cv.notify_all()

    # ------------------------------------------------------------------ requests
    def _request(self, msg: M.Message, timeout: float | None = None) -> int:
        """Send a command and wait for its ACK; retries, then DeviceTimeoutError."""
        timeout = self.timeout if timeout is None else timeout
        with self._cv:
            self._seq = (self._seq + 1) & 0xFFFF
            seq = self._seq
        data = M.encode(msg, seq)
        for attempt in range(self.retries + 1):
            if attempt:
                self.stats["retries"] += 1
            t0 = time.perf_counter()
            self._write(data)
            deadline = time.monotonic() + timeout
            with self._cv:
                while seq not in self._acks and self._gone is None:
                    left = deadline - time.monotonic()
                    if left <= 0:
                        break
                    self._cv.wait(left)
                if self._gone:
                    raise DeviceGoneError(self._gone)
                if seq in self._acks:
                    self._rtt.append(time.perf_counter() - t0)
                    return self._acks.pop(seq)
            self.stats["timeouts"] += 1
        raise DeviceTimeoutError(f"{self.port}: no acknowledgement of {type(msg).__name__} "
                                 f"after {self.retries + 1} tries of {timeout * 1e3:.0f} ms")

    def _command(self, msg: M.Message, timeout: float | None = None) -> None:
        status = self._request(msg, timeout)
        if status == M.Status.FAULT_LATCHED:
            raise DeviceFaultError(f"fault latched ({self._fault.code if self._fault else '?'}):"
                                   " clear it first")
        if status != M.Status.OK:
            raise DeviceError(f"{self.port}: device refused {type(msg).__name__}: "
                              f"{M.Status.NAMES.get(status, status)}")

    def _handshake(self) -> DeviceInfo:
        deadline = time.monotonic() + max(1.0, 4 * self.timeout)
        with self._cv:
            self._seq = (self._seq + 1) & 0xFFFF
            seq = self._seq
        while time.monotonic() < deadline:
            self._write(M.encode(M.Hello(1), seq))
            with self._cv:
                self._cv.wait_for(lambda: any(isinstance(e, M.HelloAck) for e in self._events)
                                  or self._gone is not None, timeout=self.timeout)
                if self._gone:
                    raise DeviceGoneError(self._gone)
                acks = [e for e in self._events if isinstance(e, M.HelloAck)]
                if acks:
                    self._events.clear()
                    h = acks[-1]
                    break
        else:
            raise ProtocolMismatchError(f"{self.port}: no HELLO answer in protocol version 1 "
                                        f"(frames ok {self._decoder.frames_ok}, corrupt "
                                        f"{sum(self._decoder.errors.values())})")
        if h.protocol != 1:
            raise ProtocolMismatchError(f"{self.port}: device speaks protocol {h.protocol}, "
                                        "this host speaks 1")
        model, serial_no, fw = h.strings
        return DeviceInfo(backend="serial", model=model, serial_number=serial_no, firmware=fw,
                          servo_rate_hz=float(h.servo_rate_hz),
                          current_limit=h.current_limit_ma / 1000, force_constant=h.force_constant
                          / 1000, effective_mass=h.effective_mass * 1e-6,
                          watchdog_s=h.watchdog_ms / 1000, encoder_resolution=h.encoder_nm * 1e-9,
                          accel_range=h.accel_range / 1000)

    def _heartbeat_loop(self) -> None:
        period = max(0.005, self._info.watchdog_s / 4)
        while not self._closed and self._gone is None:
            if not self._hb_pause.is_set():
                try:
                    self._write(M.encode(M.Heartbeat(), 0))
                except DeviceError:
                    return
            if time.monotonic() - self._last_rx > 2 * period + 0.05:
                self._mark_gone(f"{self.port}: device silent for "
                                f"{time.monotonic() - self._last_rx:.2f} s")
                return
            time.sleep(period)

    # ------------------------------------------------------------------ interface
    @property
    def info(self) -> DeviceInfo:
        return self._info

    @property
    def fault(self) -> FaultEvent | None:
        return self._fault

    @property
    def output_force(self) -> float:
        return 0.0 if (self._closed or self._gone) else self._output

    def ping(self, timeout: float = 0.5) -> float:
        """One PING/PONG round trip [s] (also counted in the link statistics)."""
        self._check()
        stamp = int(time.monotonic() * 1e6) & 0xFFFFFFFF
        t0 = time.perf_counter()
        self._write(M.encode(M.Ping(stamp), 0))
        with self._cv:
            ok = self._cv.wait_for(lambda: any(isinstance(e, M.Pong) and e.stamp == stamp
                                               for e in self._events) or self._gone is not None,
                                   timeout=timeout)
            if self._gone:
                raise DeviceGoneError(self._gone)
            if not ok:
                self.stats["timeouts"] += 1
                raise DeviceTimeoutError(f"{self.port}: no PONG within {timeout * 1e3:.0f} ms")
            self._events = deque(e for e in self._events
                                 if not (isinstance(e, M.Pong) and e.stamp == stamp))
        rtt = time.perf_counter() - t0
        self._rtt.append(rtt)
        return rtt

    def link_stats(self) -> dict:
        """Frames sent/ok, CRC and other errors, timeouts, retries, lost/duplicate/out-of-order
        frames, and acknowledgement round-trip p50/p95/p99 [ms]."""
        rtt = np.array(self._rtt) * 1e3
        out = dict(self.stats)
        for q in (50, 95, 99):
            out[f"rtt_p{q}_ms"] = float(np.percentile(rtt, q)) if rtt.size else float("nan")
        return out

    def _check(self) -> None:
        if self._closed:
            raise DeviceError("device is closed")
        if self._gone:
            raise DeviceGoneError(self._gone)

    def load_scene(self, scene: Scene) -> None:
        self._check()
        if not isinstance(scene, Scene):
            raise TypeError(f"load_scene expects a device.Scene, got {type(scene).__name__}")
        self._scene_id = (self._scene_id + 1) & 0xFFFF
        sid = self._scene_id
        table: TransientTable | None = None
        if scene.transient is not None:
            tr = scene.transient
            if isinstance(tr, LibraryTransient):
                from ..matching.library import TransientLibrary

                if tr.path is None:
                    raise DeviceError(f"scene '{scene.name}': a real device needs a library "
                                      f"file built on it for '{tr.source}' (hapticlab library "
                                      "build --device serial:PORT); none was given")
                table = TransientLibrary.load(tr.path, self._info).table(tr.attenuation, tr.blend)
            else:
                table = tr.table(self._info.servo_rate_hz, self._info.effective_mass)
        m = scene.material
        ring = m.ringing if m is not None else None
        kind = 0 if m is not None else (2 if table is not None else 1)
        rows, row_len = (table.forces.shape if table is not None else (0, 0))
        self._command(M.SceneBegin(
            sid, kind, int(round(scene.surface_height * 1e6)), float(scene.spring or 0.0),
            m.stiffness if m else 0.0, m.damping if m else 0.0, ring.slope if ring else 0.0,
            ring.decay if ring else 0.0, ring.frequency if ring else 0.0, 0.0, rows, row_len,
            _BLEND[table.blend] if table is not None else 0,
            table.attenuation if table is not None else 1.0))
        crc = 0
        if table is not None:  # only what the scene requires: springs upload no table
            self._command(M.SceneVelocities(sid, tuple(float(v) for v in table.velocities)))
            q = np.clip(np.round(table.forces.reshape(-1) * 1000), -32768, 32767).astype("<i2")
            for a in range(0, q.size, M.CHUNK_ITEMS):
                part = q[a: a + M.CHUNK_ITEMS]
                self._command(M.SceneChunk(sid, a, part.size, tuple(int(x) for x in part)))
            crc = zlib.crc32(q.tobytes()) & 0xFFFFFFFF
        self._command(M.SceneCommit(sid, crc))
        self._loaded = scene

    def home(self, clearance: float | None = None) -> None:
        self._check()
        if self._loaded is None:
            raise DeviceError("load a scene before homing")
        if self._fault is not None:
            raise DeviceFaultError(f"fault latched ({self._fault.code}): clear it first")
        c = 0.02 if clearance is None else float(clearance)
        if not (math.isfinite(c) and c > 0):
            raise ValueError(f"home clearance must be finite and > 0 m, got {clearance!r}")
        self._command(M.Home(int(round(c * 1e6))))

    def heartbeat(self) -> None:
        self._check()
        self._write(M.encode(M.Heartbeat(), 0))

    def estop(self) -> None:
        self._output = 0.0
        if not self._gone and not self._closed:
            self._command(M.EStop())
        if self._fault is None:
            self._fault = FaultEvent(time.monotonic(), "estop", "emergency stop (latched)")

    def clear_fault(self) -> None:
        self._check()
        self._command(M.ClearFault())
        self._fault = None

    def zero(self) -> None:
        self._output = 0.0
        if not self._gone and not self._closed:
            self._command(M.Zero())

    def run_window(self, duration: float = 5.0, *, from_first_contact: bool = True,
                   timeout: float = 30.0,
                   on_progress: Callable[[float, WindowResult], None] | None = None,
                   heartbeats: bool = True) -> WindowResult:
        self._check()
        if self._fault is not None:
            raise DeviceFaultError(f"fault latched ({self._fault.code}): clear it first")
        if not (duration > 0 and math.isfinite(duration)):
            raise ValueError(f"window duration must be finite and > 0 s, got {duration!r}")
        if self._loaded is None:
            raise DeviceError("load a scene and home the device before running a window")
        self._window_id = (self._window_id + 1) & 0xFFFF
        wid = self._window_id
        with self._cv:
            self._events.clear()
        self._command(M.StartWindow(wid, int(round(duration * 1000)), int(round(timeout * 1000)),
                                    int(from_first_contact)))
        limit = (timeout + duration if from_first_contact else duration) + 2.0
        return self._collect(wid, limit, on_progress, heartbeats)

    def play_force(self, force, *, heartbeats: bool = True) -> WindowResult:
        self._check()
        if self._fault is not None:
            raise DeviceFaultError(f"fault latched ({self._fault.code}): clear it first")
        f = np.ascontiguousarray(force, dtype=float).reshape(-1)
        if f.size == 0 or not np.all(np.isfinite(f)):
            raise ValueError("force command must be a non-empty array of finite values [N]")
        q = np.clip(np.round(f * 1000), -32768, 32767).astype("<i2")
        for a in range(0, q.size, M.CHUNK_ITEMS):
            part = q[a: a + M.CHUNK_ITEMS]
            self._command(M.PlayChunk(a, part.size, tuple(int(x) for x in part)))
        self._window_id = (self._window_id + 1) & 0xFFFF
        wid = self._window_id
        with self._cv:
            self._events.clear()
        self._command(M.PlayStart(wid, q.size))
        return self._collect(wid, q.size / self._info.servo_rate_hz + 2.0, None, heartbeats)

    def _take_events(self, timeout: float = 0.05) -> tuple[list, str | None]:
        """Wait up to ``timeout`` [s] for events; take them all, with the gone reason."""
        with self._cv:
            self._cv.wait_for(lambda: self._events or self._gone is not None, timeout=timeout)
            items = list(self._events)
            self._events.clear()
            return items, self._gone

    def _collect(self, wid: int, limit: float, on_progress, heartbeats: bool) -> WindowResult:
        rate = self._info.servo_rate_hz
        contacts: list[ContactEvent] = []
        sats: list[SaturationEvent] = []
        done: M.WindowDone | None = None
        faults: list[FaultEvent] = []
        if not heartbeats:
            self._hb_pause.set()
        start = time.monotonic()
        deadline = start + limit
        next_progress = start + 0.1
        try:
            while done is None:
                items, gone = self._take_events()
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
                if gone:
                    err = DeviceGoneError(f"{gone}; the window was aborted after "
                                          f"{len(contacts)} contacts")
                    err.partial = WindowResult(rate, None, list(contacts), list(sats),
                                               [f for f in faults if f is not None][:1])
                    raise err
                if time.monotonic() > deadline:
                    self._stop_window()
                    raise DeviceTimeoutError(f"{self.port}: window {wid} did not end in time")
                if on_progress is not None and time.monotonic() >= next_progress:
                    next_progress = time.monotonic() + 0.1
                    on_progress(time.monotonic() - start, WindowResult(rate, None, list(contacts)))
        except BaseException:
            if self._gone is None:
                self._stop_window()  # an exception in the caller's callback, an interrupt…
            raise
        finally:
            self._hb_pause.clear()
        t0 = done.t0_us * 1e-6
        traces = self._fetch_traces(wid, done.n_ticks)
        traces["t"] = t0 + np.arange(done.n_ticks) / rate
        res = WindowResult(rate, None if done.first_contact < 0 else t0 + done.first_contact / rate,
                           [ContactEvent(t0 + c.t, c.velocity) for c in contacts],
                           [SaturationEvent(t0 + s.t, s.peak_current, s.duration) for s in sats],
                           [f for f in faults if f is not None][:1], traces,
                           timed_out=bool(done.timed_out))
        if res.faults:
            # the device reports its own time; express it on the window's clock
            f = res.faults[0]
            res.faults = [FaultEvent(max(t0, min(f.t, traces["t"][-1] if done.n_ticks else t0)),
                                     f.code, f.message)]
            self._fault = res.faults[0]
        return res

    def _stop_window(self) -> None:
        """Best effort: end a window the host gave up on, so the device is free again."""
        try:
            self._request(M.StopWindow(), timeout=0.05)
        except DeviceError:
            pass

    def _fetch_traces(self, wid: int, n: int) -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = {}
        for ch, name in enumerate(M.Channel.NAMES):
            if n == 0:
                out[name] = np.zeros(0)
                continue
            buf = np.full(n, np.nan)
            status = self._request(M.TraceRequest(wid, ch, 0, n))
            if status != M.Status.OK:
                if name in _OPTIONAL:
                    continue
                raise DeviceError(f"{self.port}: device has no trace '{name}' for window {wid}")
            got = 0
            deadline = time.monotonic() + 2.0 + n * 1e-5
            while got < n:
                items, gone = self._take_events()
                for e in items:
                    if isinstance(e, M.TraceBlock) and e.window_id == wid and e.channel == ch:
                        buf[e.start: e.start + e.n] = e.items
                        got += e.n
                    elif not isinstance(e, M.TraceBlock):
                        with self._cv:
                            self._events.appendleft(e)
                if gone:
                    raise DeviceGoneError(f"{gone} while reading traces")
                if time.monotonic() > deadline:
                    raise DeviceTimeoutError(f"{self.port}: trace '{name}' incomplete "
                                             f"({got} of {n} samples)")
            out[name] = buf if name != "flags" else buf.astype(np.uint16)
        return out

    # ------------------------------------------------------------------ exits
    def _install_exit_guards(self) -> None:
        ref = weakref.ref(self)
        atexit.register(lambda: ref() is not None and ref().close())
        self._prev_term = None
        if threading.current_thread() is threading.main_thread():
            prev = signal.getsignal(signal.SIGTERM)

            def on_term(signum, frame):  # zero output, then let the process end as usual
                d = ref()
                if d is not None:
                    d.close()
                if callable(prev):
                    prev(signum, frame)
                raise SystemExit(128 + signum)

            try:
                signal.signal(signal.SIGTERM, on_term)
                self._prev_term = prev
            except ValueError:
                pass

    def _shutdown_io(self) -> None:
        """Stop the threads, then release the port.

        The reader must have left its read first: a read in progress in another thread keeps
        the port's file open (and its exclusive lock held) after close() returns.
        """
        self._closed = True
        cancel = getattr(self._ser, "cancel_read", None)
        if cancel is not None:
            try:
                cancel()
            except Exception:  # the port may already be gone
                pass
        me = threading.current_thread()
        for t in (getattr(self, "_reader", None), getattr(self, "_hb", None)):
            if t is not None and t is not me and t.is_alive():
                t.join(timeout=1.0)
        try:
            self._ser.close()
        except Exception:  # closing a port that is already gone
            pass

    def close(self) -> None:
        """Zero output (best effort), stop the threads, release the port. Idempotent."""
        if self._closed:
            return
        try:
            if not self._gone:
                self._request(M.Zero(), timeout=0.05)
        except DeviceError:
            pass
        self._output = 0.0
        self._shutdown_io()
        if self._prev_term is not None and threading.current_thread() is threading.main_thread():
            try:
                signal.signal(signal.SIGTERM, self._prev_term)
            except (ValueError, TypeError):
                pass

    def reconnect(self) -> None:
        """Reopen the port after the device was gone (explicit, never automatic)."""
        self._shutdown_io()
        self.__init__(self.port, self.timeout, self.retries, None, self._baud)



