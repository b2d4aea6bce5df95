"""The link layer of the serial backend: port, reader thread, sequencing, retries, heartbeats.

:class:`Link` knows frames and messages but nothing of scenes or windows. It opens the port
exclusively, decodes frames in a background thread, numbers commands and waits for their
acknowledgements (retrying at most three times), sends heartbeats every T_wd/4, counts
what the link does (:meth:`Link.stats`), and declares the device gone when the port fails,
the device falls silent for a watchdog period, or corrupt frames arrive in a storm.
Messages that are not acknowledgements go to a handler (the device layer's view of state)
and into an event queue the device layer takes from.

While heartbeats run, the process's automatic full garbage collections are held off, and
the held pass runs when the last link closes (:func:`hold_full_collections`): a full pass
over a host that has imported scipy and statsmodels stops every thread for 90–110 ms on a
loaded 2-core machine (measured), long enough to starve the device's 100-ms watchdog.
"""

from __future__ import annotations

import gc
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np

from ..errors import DeviceError
from . import messages as M
from .framing import PROTOCOL_VERSION, FrameDecoder

__all__ = ["Link", "DeviceGoneError", "DeviceTimeoutError", "PortBusyError",
           "ProtocolMismatchError", "CRCStormError", "SILENCE_MIN_S", "hold_full_collections"]

#: how long a host offers HELLO before it gives up [s]. A device may not listen at once
#: when its port opens: a board that resets on DTR boots first, and QEMU's pty serial
#: notices a reopened port only at its next once-a-second poll (HELLO_ACK came 0.81 s
#: after the open, measured), which a 1-s wait missed under load
HELLO_WAIT_S = 3.0
#: the device counts as gone after T_wd without a frame, and never sooner than this [s]:
#: two of the slowest STATUS intervals a device may keep (20 Hz; docs §3)
SILENCE_MIN_S = 0.1


_gc_lock = threading.Lock()
_gc_holds = 0
_gc_threshold: tuple[int, int, int] | None = None


def hold_full_collections(hold: bool) -> None:
    """Hold off (``True``) or give back (``False``) the interpreter's automatic full
    (generation-2) garbage collections, counted across callers.

    A held process still frees everything by reference counting and still collects young
    objects (passes over only what was allocated lately, well under a millisecond); only
    cycles that outlived two young passes wait. The last release runs the held full pass
    at once, when no device is being fed.
    """
    global _gc_holds, _gc_threshold
    with _gc_lock:
        if hold:
            _gc_holds += 1
            if _gc_holds == 1:
                _gc_threshold = gc.get_threshold()
                gc.set_threshold(_gc_threshold[0], _gc_threshold[1], 2**31 - 1)
            return
        if _gc_holds == 0:
            return
        _gc_holds -= 1
        if _gc_holds or _gc_threshold is None:
            return
        gc.set_threshold(*_gc_threshold)
    gc.collect()


class DeviceGoneError(DeviceError):
    """The device was unplugged or stopped talking; the current trial is aborted (what the
    window had delivered is in :attr:`partial`)."""


class CRCStormError(DeviceGoneError):
    """Too many corrupt frames in a short time (20 within 1 s): the link is unusable."""


class DeviceTimeoutError(DeviceError):
    """A command got no acknowledgement after all retries."""


class PortBusyError(DeviceError):
    """The port is open elsewhere (exclusive access refused)."""


class ProtocolMismatchError(DeviceError):
    """The other end does not speak this protocol version (or at all)."""


class Link:
    """One host session with a device on a serial port.

    Parameters
    ----------
    port : str
        Device path or pyserial URL (used to open the port and in every message).
    timeout : float [s]
        Wait for each acknowledgement.
    retries : int
        Re-sends of an unacknowledged command (0–3).
    transport : object, optional
        A pyserial-like object (``read``, ``write``, ``close``) instead of opening ``port``.
    baudrate : int
    handler : callable, optional
        Called with every decoded device message that is not an ACK, in the reader thread
        and under the link's lock, before the message is queued as an event.
    """

    def __init__(self, port: str, timeout: float = 0.2, retries: int = 3, transport: Any = None,
                 baudrate: int = 1_000_000, handler: Callable[[M.Message], None] | None = None):
        if not 0 <= retries <= 3:
            raise ValueError(f"retries must be 0–3, got {retries!r}")
        self.port = port
        self.timeout = float(timeout)
        self.retries = int(retries)
        self.baudrate = baudrate
        #: the protocol version negotiated by :meth:`hello` (1 until then)
        self.version = 1
        #: a version-2 device's resources (LIMITS), None before HELLO or from a version-1 device
        self.limits: M.Limits | None = None
        self._handler = handler
        self._ser = transport if transport is not None else self._open(port)
        self._decoder = FrameDecoder()
        self._wlock = threading.Lock()
        self.cv = threading.Condition()
        self._seq = 0
        self._acks: dict[int, int] = {}
        self._events: deque = deque()
        self._gone: DeviceGoneError | None = None
        self.closed = False
        self._last_rx = time.monotonic()
        self._dev_seq: int | None = None
        self._hb_pause = threading.Event()
        self._hb: threading.Thread | None = None
        self._gc_held = False  # this link holds full collections off (see module docs)
        self.contact_rx: list[tuple[float, int]] = []  # (host perf time, tick) per CONTACT
        self.stats = {"frames_sent": 0, "frames_ok": 0, "crc_errors": 0, "other_errors": 0,
                      "timeouts": 0, "retries": 0, "lost": 0, "duplicates": 0,
                      "out_of_order": 0}
        self._rtt: deque[float] = deque(maxlen=4096)
        self._crc_times: deque[float] = deque(maxlen=50)
        self._reader = threading.Thread(target=self._read_loop, name="serial-reader", daemon=True)
        self._reader.start()

    # ------------------------------------------------------------------ port
    def _open(self, port: str):
        import serial

        try:
            return serial.serial_for_url(port, baudrate=self.baudrate, timeout=0.01,
                                         write_timeout=0.5, exclusive=True)
        except serial.SerialException as exc:
            msg = str(exc)
            if "lock" in msg.lower() or "busy" in msg.lower():
                raise PortBusyError(f"{port}: port is in use by another program ({msg})") from None
            raise DeviceGoneError(f"{port}: cannot open ({msg})") from None
        except OSError as exc:
            raise DeviceGoneError(f"{port}: cannot open ({exc})") from None

    @property
    def gone(self) -> DeviceGoneError | None:
        """Why the device is gone (an error to raise), or None while it talks."""
        return self._gone

    def check(self) -> None:
        """Raise if the link is closed or the device gone."""
        if self.closed:
            raise DeviceError("device is closed")
        if self._gone is not None:
            raise type(self._gone)(str(self._gone))

    def mark_gone(self, why: str, cls: type[DeviceGoneError] = DeviceGoneError) -> None:
        with self.cv:
            if self._gone is None:
                self._gone = cls(why)
            self.cv.notify_all()

    def write(self, data: bytes) -> None:
        """Send encoded bytes; a failing port marks the device gone and raises."""
        self.check()
        try:
            with self._wlock:
                self._ser.write(data)
            self.stats["frames_sent"] += 1
        except Exception as exc:  # SerialException, SerialTimeoutException or OSError
            self.mark_gone(f"{self.port}: write failed ({exc})")
            raise DeviceGoneError(str(self._gone)) from None

    # ------------------------------------------------------------------ reader
    def _read_loop(self) -> None:
        while not self.closed and self._gone is None:
            try:
                # pyserial's read(n) waits for n bytes or its timeout: ask for one byte (returns
                # as soon as it arrives), then for whatever else is already waiting
                data = self._ser.read(1)
                if data:
                    waiting = getattr(self._ser, "in_waiting", 0)
                    if waiting:
                        data += self._ser.read(waiting)
            except Exception as exc:  # SerialException or OSError: unplugged
                self.mark_gone(f"{self.port}: device gone ({type(exc).__name__}: {exc})")
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
                    self._decoder.errors["body"] += 1
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
                self.mark_gone(f"{self.port}: CRC storm (20 corrupt frames within 1 s): the "
                               "link is unusable; check the cable and the port", CRCStormError)
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
        with self.cv:
            if isinstance(msg, M.Ack):
                self._acks[msg.ack_seq] = msg.status
            else:
                if self._handler is not None:
                    self._handler(msg)
                if not isinstance(msg, M.StatusReport):
                    self._events.append(msg)
            self.cv.notify_all()

    # ------------------------------------------------------------------ events
    def take_events(self, timeout: float = 0.05) -> tuple[list, DeviceGoneError | None]:
        """Wait up to ``timeout`` [s] for events; take them all, with the gone error."""
        with self.cv:
            self.cv.wait_for(lambda: self._events or self._gone is not None, timeout=timeout)
            items = list(self._events)
            self._events.clear()
            return items, self._gone

    def put_back(self, items: list) -> None:
        """Return events taken but not consumed to the front of the queue, in order."""
        with self.cv:
            self._events.extendleft(reversed(items))

    def clear_events(self) -> None:
        with self.cv:
            self._events.clear()

    def wait_for(self, predicate: Callable[[deque], bool], timeout: float) -> bool:
        """Wait until ``predicate(events)`` holds (True) or ``timeout`` [s] passes (False)."""
        with self.cv:
            ok = self.cv.wait_for(lambda: predicate(self._events) or self._gone is not None,
                                  timeout=timeout)
            self.check()
            return bool(ok)

    def remove(self, predicate: Callable[[Any], bool]) -> list:
        """Take the queued events for which ``predicate`` holds."""
        with self.cv:
            hit = [e for e in self._events if predicate(e)]
            self._events = deque(e for e in self._events if not predicate(e))
            return hit

    # ------------------------------------------------------------------ requests
    def next_seq(self) -> int:
        with self.cv:
            self._seq = (self._seq + 1) & 0xFFFF
            return self._seq

    def request(self, msg: M.Message, timeout: float | None = None) -> int:
        """Send a command and wait for its ACK; retries, then DeviceTimeoutError."""
        timeout = self.timeout if timeout is None else timeout
        seq = self.next_seq()
        data = M.encode(msg, seq, self.version)
        for attempt in range(self.retries + 1):
            if attempt:
                self.stats["retries"] += 1
            t0 = time.perf_counter()
            self.write(data)
            deadline = time.monotonic() + timeout
            with self.cv:
                while seq not in self._acks and self._gone is None:
                    left = deadline - time.monotonic()
                    if left <= 0:
                        break
                    self.cv.wait(left)
                self.check()
                if seq in self._acks:
                    self._rtt.append(time.perf_counter() - t0)
                    return self._acks.pop(seq)
            self.stats["timeouts"] += 1
        raise DeviceTimeoutError(f"{self.port}: no acknowledgement of {type(msg).__name__} "
                                 f"after {self.retries + 1} tries of {timeout * 1e3:.0f} ms")

    def hello(self, protocol: int = PROTOCOL_VERSION) -> M.HelloAck:
        """Open a host session: HELLO until HELLO_ACK (ProtocolMismatchError if none).

        The HELLO offers ``protocol`` (the newest version this host speaks) in a version-1
        frame, which every device reads; the device answers in the version it chose, and
        the link speaks that from then on. A version-2 device follows with LIMITS
        (:attr:`limits`)."""
        deadline = time.monotonic() + max(HELLO_WAIT_S, 4 * self.timeout)
        seq = self.next_seq()
        while time.monotonic() < deadline:
            self.write(M.encode(M.Hello(protocol), seq, 1))
            if self.wait_for(lambda ev: any(isinstance(e, M.HelloAck) for e in ev),
                             self.timeout):
                acks = self.remove(lambda e: isinstance(e, M.HelloAck))
                self.version = acks[-1].protocol
                if self.version >= 2:
                    self.wait_for(lambda ev: any(isinstance(e, M.Limits) for e in ev),
                                  self.timeout)
                    limits = self.remove(lambda e: isinstance(e, M.Limits))
                    self.limits = limits[-1] if limits else None
                self.clear_events()
                # what came before the session opened (a stream joined in the middle of a
                # frame) is not the link's fault: count from here
                with self.cv:
                    for k in self._decoder.errors:
                        self._decoder.errors[k] = 0
                    self._crc_times.clear()
                    for k in ("crc_errors", "other_errors", "lost", "duplicates",
                              "out_of_order"):
                        self.stats[k] = 0
                return acks[-1]
        raise ProtocolMismatchError(f"{self.port}: no HELLO answer in protocol version 1 or 2 "
                                    f"(frames ok {self._decoder.frames_ok}, corrupt "
                                    f"{sum(self._decoder.errors.values())})")

    def ping(self, timeout: float = 0.5) -> float:
        """One PING/PONG round trip [s] (also counted in the statistics)."""
        self.check()
        stamp = int(time.monotonic() * 1e6) & 0xFFFFFFFF
        t0 = time.perf_counter()
        self.write(M.encode(M.Ping(stamp), 0, self.version))
        ok = self.wait_for(lambda ev: any(isinstance(e, M.Pong) and e.stamp == stamp
                                          for e in ev), timeout)
        if not ok:
            self.stats["timeouts"] += 1
            raise DeviceTimeoutError(f"{self.port}: no PONG within {timeout * 1e3:.0f} ms")
        self.remove(lambda e: isinstance(e, M.Pong) and e.stamp == stamp)
        rtt = time.perf_counter() - t0
        self._rtt.append(rtt)
        return rtt

    # ------------------------------------------------------------------ heartbeats
    def start_heartbeats(self, watchdog_s: float) -> None:
        """Heartbeat every T_wd/4; silence for T_wd (at least ``SILENCE_MIN_S``), timed
        while this host was listening, marks the device gone."""
        period = max(0.005, watchdog_s / 4)
        limit = max(watchdog_s, SILENCE_MIN_S)
        if not self._gc_held:
            self._gc_held = True
            hold_full_collections(True)

        def loop() -> None:
            slept = time.monotonic() - period  # when the last sleep began
            while not self.closed and self._gone is None:
                if not self._hb_pause.is_set():
                    try:
                        self.write(M.encode(M.Heartbeat(), 0, self.version))
                    except DeviceError:
                        return
                now = time.monotonic()
                silent = now - self._last_rx
                # a host that was itself stalled (a garbage collection, a loaded machine)
                # was not listening: what the device sent meanwhile waits unread. Silence
                # is judged only on a turn that came on time, after the reader had its
                # turn, and never while bytes wait in the port
                on_time = now - slept < 2 * period
                if (silent > limit and (on_time or silent > 4 * limit)
                        and not self._bytes_waiting()):
                    self.mark_gone(f"{self.port}: device silent for {silent:.2f} s")
                    return
                slept = time.monotonic()
                time.sleep(period)

        self._hb = threading.Thread(target=loop, name="serial-heartbeat", daemon=True)
        self._hb.start()

    def _bytes_waiting(self) -> bool:
        """Whether received bytes wait unread in the port (the reader is behind)."""
        try:
            return bool(self._ser.in_waiting)
        except Exception:  # noqa: BLE001 - a port that cannot say: judge by the clock alone
            return False

    def pause_heartbeats(self, paused: bool) -> None:
        """Stop (True) or restart (False) the heartbeats: the watchdog test."""
        if paused:
            self._hb_pause.set()
        else:
            self._hb_pause.clear()

    def heartbeat(self) -> None:
        self.write(M.encode(M.Heartbeat(), 0, self.version))

    # ------------------------------------------------------------------ statistics
    def link_stats(self) -> dict:
        """Frames sent/ok, CRC and other errors, timeouts, retries, lost/duplicate/out-of-order
        frames, and acknowledgement round-trip p50/p95/p99 [ms]."""
        rtt = np.array(self._rtt) * 1e3
        out = dict(self.stats)
        for q in (50, 95, 99):
            out[f"rtt_p{q}_ms"] = float(np.percentile(rtt, q)) if rtt.size else None
        return out

    # ------------------------------------------------------------------ shutdown
    def shutdown(self) -> None:
        """Stop the threads, then release the port.

        The reader must have left its read first: a read in progress in another thread keeps
        the port's file open (and its exclusive lock held) after close() returns.
        """
        self.closed = True
        cancel = getattr(self._ser, "cancel_read", None)
        if cancel is not None:
            try:
                cancel()
            except Exception:  # the port may already be gone
                pass
        me = threading.current_thread()
        for t in (self._reader, self._hb):
            if t is not None and t is not me and t.is_alive():
                t.join(timeout=1.0)
        try:
            self._ser.close()
        except Exception:  # closing a port that is already gone
            pass
        if self._gc_held:
            self._gc_held = False
            hold_full_collections(False)
