"""The link layer of the serial backend: port, reader thread, sequencing, retries, heartbeats.

:class:`Link` knows frames and messages but nothing of scenes or windows. It opens the port
exclusively, decodes frames in a background thread, numbers commands and waits for their
acknowledgements (retrying at most three times), keeps the device's watchdog fed, counts
what the link does (:meth:`Link.stats`), and declares the device gone when the port fails,
the device falls silent for a watchdog period, or corrupt frames arrive in a storm.
Messages that are not acknowledgements go to a handler (the device layer's view of state)
and into an event queue the device layer takes from.

**What a busy host cannot hold up.** On a port it opened itself, the link hands reading
and heartbeats to a native thread (:mod:`device.serial.native`): bytes leave the port as
they arrive and a HEARTBEAT goes out whenever no frame went for T_wd/4, whatever the
interpreter is doing, for as long as the thread that drives the device renews its lease
(``LEASE_S``): every command and every wait for the device's events renews it
(:meth:`Link.renew`), and the reader thread never does, so a main loop that hangs (a
deadlock, a wait that never ends, even one that holds no interpreter lock) stops the
heartbeats and trips the device's watchdog. A program that keeps the output on while it
does something else for longer than the lease must zero it first (the session runner
does, as each window ends). Where the native library is missing, both run in Python
threads under the same lease, and while heartbeats run the process's automatic full
garbage collections are held off (:func:`hold_full_collections`): a full pass over a
host that has imported scipy and statsmodels stops every thread for 90–110 ms on a loaded
2-core machine (measured), long enough to starve the device's 100-ms watchdog.
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
from .contract import RangeError
from .framing import PROTOCOL_VERSION, FrameDecoder
from .native import NativeLink

__all__ = ["Link", "gap_percentiles", "DeviceGoneError", "DeviceTimeoutError", "PortBusyError",
           "ProtocolMismatchError", "CRCStormError", "SILENCE_S", "hold_full_collections"]

#: how long a host offers HELLO before it gives up [s]. A device may not listen at once
#: when its port opens: a board that resets on DTR boots first, and QEMU's pty serial
#: notices a reopened port only at its next once-a-second poll (HELLO_ACK came 0.81 s
#: after the open, measured), which a 1-s wait missed under load
HELLO_WAIT_S = 3.0
#: the device counts as gone after this long without a byte, timed while this host was
#: listening [s]: twenty of the slowest STATUS intervals a device may keep (20 Hz; docs
#: §3). A device's silence is not a safety matter (its own watchdog and its hardware
#: watchdog are), so the host waits long enough for a device simulated on the same busy
#: computer (an emulator, QEMU) that the operating system held up for a moment
SILENCE_S = 1.0
#: how long the heartbeats go on for a host that stopped driving the device [s]: a host
#: whose main loop hangs (a deadlock, a call that never returns, with or without the
#: interpreter lock, a stopped process) stops feeding the device this long after its last
#: command or wait for events, and the device's watchdog trips T_wd later. Ten times the
#: longest stall of a Python thread measured under load (`hapticlab bench link --load 4`:
#: README)
LEASE_S = 1.0
#: how much longer than its timeout a try waits for an ACK while the device's clock (its
#: STATUS) has not moved the timeout's length [s]: a device held up as a whole on a busy
#: computer (QEMU) reports nothing meanwhile; one second, the same as :data:`SILENCE_S`
CLOCK_GRACE_S = 1.0
#: a write the port does not take within this long marks the device gone [s]
WRITE_TIMEOUT_S = 0.5
#: commands that make the output safe: their ACK is awaited in this computer's time alone
_PROMPT = (M.EStop, M.Zero, M.StopWindow)


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


def gap_percentiles(counts, bin_ms: float, max_ms: float | None = None) -> dict:
    """p50, p99 and p99.9 [ms] of gaps counted in bins of ``bin_ms`` (the last bin open):
    each the upper edge of the bin it falls in (an upper bound), or the exact largest gap
    ``max_ms`` where that is smaller (a percentile is never above the maximum); None with
    no gaps."""
    c = np.asarray(counts, float)
    total = c.sum()
    out = {}
    for name, q in (("p50", 0.5), ("p99", 0.99), ("p999", 0.999)):
        k = int(np.searchsorted(np.cumsum(c), q * total)) if total else None
        edge = None if k is None else (k + 1) * bin_ms
        out[f"gap_{name}_ms"] = edge if edge is None or max_ms is None else min(edge, max_ms)
    out["gaps"] = int(total)
    return out


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
    native : bool
        Serve the port with the native thread when it is available (False: Python threads,
        as a baseline to measure it against).
    """

    def __init__(self, port: str, timeout: float = 0.2, retries: int = 3, transport: Any = None,
                 baudrate: int = 1_000_000, handler: Callable[[M.Message], None] | None = None,
                 native: bool = True):
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
        self.rating_ma: int | None = None  # HELLO_ACK's current limit [mA]
        self._handler = handler
        self._ser = transport if transport is not None else self._open(port)
        #: the native thread serving the port, or None (then :attr:`native_why` says why)
        self._native: NativeLink | None = None
        self.native_why: str | None = ("a transport object was given" if transport is not None
                                       else "Python threads were asked for (native=False)")
        if transport is None and native:
            self._native, self.native_why = self._start_native()
        #: host perf time [s] at which the last frame of each message type was written
        self.last_sent: dict[int, float] = {}
        self._watch: threading.Thread | None = None
        self._final_report: dict | None = None  # the native thread's figures at shutdown
        self._stalls: deque[float] = deque(maxlen=65536)  # the watcher's own lateness [s]
        self._decoder = FrameDecoder()
        self._wlock = threading.Lock()
        self.cv = threading.Condition()
        self._seq = 0
        self._acks: dict[int, int] = {}
        #: the device's clock in its last STATUS [s]: an ACK's wait is judged in it
        self._dev_clock: float | None = None
        self._events: deque = deque()
        self._gone: DeviceGoneError | None = None
        self.closed = False
        self._last_rx = time.monotonic()
        self._lease_until = time.monotonic() + LEASE_S  # the Python heartbeats' lease
        self.lease_lapses = 0  # turns the Python heartbeat skipped for a lapsed lease
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

    def _start_native(self) -> tuple[NativeLink | None, str | None]:
        try:
            fd = self._ser.fileno()
        except Exception as exc:  # noqa: BLE001 - a URL transport (loop://, socket://)
            return None, f"the port has no file descriptor ({exc})"
        try:
            return NativeLink(fd), None
        except OSError as exc:
            return None, exc.strerror or str(exc)

    @property
    def native(self) -> bool:
        """Whether a native thread reads the port and heartbeats (see module docs)."""
        return self._native is not None

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

    def renew(self) -> None:
        """Renew the heartbeats' lease for :data:`LEASE_S`: the thread that drives the
        device is alive. Every command and every wait for events calls it; the reader
        thread never does."""
        self._lease_until = time.monotonic() + LEASE_S
        if self._native is not None and not self._native.closed:
            self._native.renew()

    def write(self, data: bytes) -> None:
        """Send encoded bytes (renewing the lease: see :meth:`renew`); a failing port marks
        the device gone and raises."""
        self._lease_until = time.monotonic() + LEASE_S
        self._send(data)

    def _send(self, data: bytes) -> None:
        self.check()
        try:
            if self._native is not None:
                self._native.write(data, WRITE_TIMEOUT_S)
            else:
                with self._wlock:
                    self._ser.write(data)
            self.stats["frames_sent"] += 1
        except Exception as exc:  # SerialException, SerialTimeoutException or OSError
            self.mark_gone(f"{self.port}: write failed ({exc})")
            raise DeviceGoneError(str(self._gone)) from None

    # ------------------------------------------------------------------ reader
    def _read(self) -> bytes:
        if self._native is not None:
            return self._native.read(0.05)  # a read renews no lease (see :meth:`renew`)
        # pyserial's read(n) waits for n bytes or its timeout: ask for one byte (returns as
        # soon as it arrives), then for whatever else is already waiting
        data = self._ser.read(1)
        if data:
            waiting = getattr(self._ser, "in_waiting", 0)
            if waiting:
                data += self._ser.read(waiting)
        return data

    def _read_loop(self) -> None:
        while not self.closed and self._gone is None:
            try:
                data = self._read()
            except Exception as exc:  # SerialException or OSError: unplugged
                if not self.closed:
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
                if isinstance(msg, M.StatusReport):
                    self._dev_clock = msg.time_us * 1e-6
                else:
                    self._events.append(msg)
            self.cv.notify_all()

    # ------------------------------------------------------------------ events
    def take_events(self, timeout: float = 0.05) -> tuple[list, DeviceGoneError | None]:
        """Wait up to ``timeout`` [s] for events; take them all, with the gone error."""
        self.renew()
        with self.cv:
            self.cv.wait_for(lambda: self._events or self._gone is not None, timeout=timeout)
            items = list(self._events)
            self._events.clear()
            return items, self._gone

    def clear_events(self) -> None:
        with self.cv:
            self._events.clear()

    def wait_for(self, predicate: Callable[[deque], bool], timeout: float) -> bool:
        """Wait until ``predicate(events)`` holds (True) or ``timeout`` [s] passes (False)."""
        self.renew()
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
        """Send a command and wait for its ACK; retries, then DeviceTimeoutError. A command
        with a field outside the contract's range for this device is not sent
        (:class:`~device.serial.contract.RangeError`, naming the field).

        A try lasts ``timeout`` [s] of this computer's time and of the device's (its STATUS
        clock), at most :data:`CLOCK_GRACE_S` longer: a device simulated on a busy computer
        (QEMU beside two CPU-bound processes) once took longer than four 200-ms tries to
        acknowledge a playback chunk, held up with its clock. A real device's clock keeps
        pace with this one's, and one that stops reporting is gone after
        :data:`SILENCE_S`. ESTOP, ZERO and STOP_WINDOW are judged in this computer's time
        alone: whoever asked for a safe output learns at once that it is not confirmed."""
        try:
            msg.check(M.limit_values(self.limits, self.rating_ma))
        except RangeError as exc:
            raise RangeError(f"{self.port}: not sent: {exc}") from None
        timeout = self.timeout if timeout is None else timeout
        seq = self.next_seq()
        data = M.encode(msg, seq, self.version)
        for attempt in range(self.retries + 1):
            if attempt:
                self.stats["retries"] += 1
            t0 = time.perf_counter()
            self.write(data)
            self.last_sent[msg.TYPE] = time.perf_counter()
            start = time.monotonic()
            deadline = start + timeout
            cap = deadline + (0.0 if isinstance(msg, _PROMPT) else CLOCK_GRACE_S)
            with self.cv:
                dev0 = self._dev_clock
                while seq not in self._acks and self._gone is None and not self.closed:
                    now = time.monotonic()
                    if now >= deadline:
                        moved = (self._dev_clock - dev0 if dev0 is not None
                                 and self._dev_clock is not None else timeout)
                        if not 0 <= moved < timeout or now >= cap:
                            break  # its clock has run a try's length (or went back: reset)
                    self.renew()  # waiting for an answer is driving the device
                    # a STATUS wakes this wait: its clock is looked at again
                    self.cv.wait((deadline if now < deadline else cap) - now)
                self.check()
                if seq in self._acks:
                    if not attempt:  # a retry's ACK may answer an earlier try
                        self._rtt.append(time.perf_counter() - t0)
                    return self._acks.pop(seq)
            self.stats["timeouts"] += 1
        raise DeviceTimeoutError(f"{self.port}: no acknowledgement of {type(msg).__name__} "
                                 f"after {self.retries + 1} tries of {timeout * 1e3:.0f} ms "
                                 f"({self._listening()})")

    def _listening(self) -> str:
        """What this host heard lately, to tell a silent device from a host that was not
        listening (a busy computer holding this process up): when the last frame was
        handled, when the native reader last took bytes, how late the watcher ran."""
        now = time.monotonic()
        parts = [f"the last frame handled {now - self._last_rx:.2f} s ago"]
        if self._native is not None:
            ns = self._native.stats().get("last_rx_ns") or 0
            if ns:
                parts.append(f"bytes last read by the native reader "
                             f"{(time.monotonic_ns() - ns) / 1e9:.2f} s ago")
        recent = list(self._stalls)[-64:]
        if recent:
            parts.append(f"this host's watcher up to {max(recent) * 1e3:.0f} ms late")
        return "; ".join(parts)

    def hello(self, protocol: int = PROTOCOL_VERSION) -> M.HelloAck:
        """Open a host session: HELLO until HELLO_ACK (ProtocolMismatchError if none).

        The HELLO offers ``protocol`` (the newest version this host speaks) in a version-1
        frame, which every device reads; the device answers in the version it chose, and
        the link speaks that from then on. A version-2 device follows with LIMITS
        (:attr:`limits`)."""
        deadline = time.monotonic() + max(HELLO_WAIT_S, 4 * self.timeout)
        seq = self.next_seq()
        # a lone delimiter first: it ends a half frame a previous host left in the device's
        # receiver, which would otherwise swallow this HELLO (docs §7)
        self.write(b"\x00")
        while time.monotonic() < deadline:
            self.write(M.encode(M.Hello(protocol), seq, 1))
            if self.wait_for(lambda ev: any(isinstance(e, M.HelloAck) for e in ev),
                             self.timeout):
                acks = self.remove(lambda e: isinstance(e, M.HelloAck))
                self.version = acks[-1].protocol
                self.rating_ma = acks[-1].current_limit_ma
                if self.version >= 2:
                    # a device may time its link before it answers LIMITS (the QEMU build
                    # sends 3 × 2 KiB: 0.26 s at the 24 kB/s measured on a busy host)
                    self.wait_for(lambda ev: any(isinstance(e, M.Limits) for e in ev),
                                  max(HELLO_WAIT_S, 4 * self.timeout))
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
        raise ProtocolMismatchError(f"{self.port}: no HELLO answer in protocol version 1 to "
                                    f"{PROTOCOL_VERSION} "
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

    def fastest_round_trip(self) -> float | None:
        """The fastest command or PING round trip of the last 4,096 [s], or None."""
        rtt = list(self._rtt)
        return min(rtt) if rtt else None

    # ------------------------------------------------------------------ heartbeats
    def start_heartbeats(self, watchdog_s: float) -> None:
        """Keep the device's watchdog fed: a HEARTBEAT after T_wd/4 without a frame.
        Silence for ``SILENCE_S`` (or T_wd, if longer), timed while this host was
        listening, marks the device gone."""
        period = max(0.005, watchdog_s / 4)
        limit = max(watchdog_s, SILENCE_S)
        if self._native is not None:
            self._native.heartbeat(M.encode(M.Heartbeat(), 0, self.version), period, LEASE_S,
                                   limit)
            self._watch = threading.Thread(target=self._watch_native, args=(period,),
                                           name="serial-watch", daemon=True)
            self._watch.start()
            return
        if not self._gc_held:
            self._gc_held = True
            hold_full_collections(True)

        def loop() -> None:
            slept = time.monotonic() - period  # when the last sleep began
            while not self.closed and self._gone is None:
                leased = time.monotonic() < self._lease_until
                self.lease_lapses += not leased
                if leased and not self._hb_pause.is_set():
                    try:
                        self._send(M.encode(M.Heartbeat(), 0, self.version))
                    except DeviceError:
                        return
                now = time.monotonic()
                silent = now - self._last_rx
                # a host that was itself stalled (a garbage collection, a loaded machine)
                # was not listening: what the device sent meanwhile waits unread. Silence
                # is judged only on a turn that came on time, after the reader had its
                # turn, and never while bytes wait in the port
                on_time = now - slept < 2 * period
                self._stalls.append(max(0.0, now - slept - period))
                if (silent > limit and (on_time or silent > 4 * limit)
                        and not self._bytes_waiting()):
                    self.mark_gone(f"{self.port}: device silent for {silent:.2f} s")
                    return
                slept = time.monotonic()
                time.sleep(period)

        self._hb = threading.Thread(target=loop, name="serial-heartbeat", daemon=True)
        self._hb.start()

    def _watch_native(self, period: float) -> None:
        """The native thread judges the device's silence on time; this thread passes its
        verdict on (and notes how late the interpreter let it run: the host's stalls)."""
        slept = time.monotonic()
        while not self.closed and self._gone is None:
            time.sleep(period)
            now = time.monotonic()
            self._stalls.append(max(0.0, now - slept - period))
            slept = now
            if self.closed or self._native is None:
                return
            st = self._native.stats()
            if st["silent_ms"] > 0:
                self.mark_gone(f"{self.port}: device silent for {st['silent_ms'] / 1000:.2f} s")
                return

    def _bytes_waiting(self) -> bool:
        """Whether received bytes wait unread in the port (the reader is behind)."""
        try:
            return bool(self._ser.in_waiting)
        except Exception:  # noqa: BLE001 - a port that cannot say: judge by the clock alone
            return False

    def pause_heartbeats(self, paused: bool) -> None:
        """Stop (True) or restart (False) the heartbeats: the watchdog test."""
        if self._native is not None:
            self._native.pause(paused)
        elif paused:
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
        stalls = np.array(self._stalls) * 1e3
        out["host_stall_max_ms"] = float(stalls.max()) if stalls.size else None
        out["heartbeats"] = self.heartbeat_report()
        return out

    def heartbeat_report(self, reset: bool = False) -> dict:
        """Who feeds the device's watchdog and how evenly: ``native`` (a native thread) or
        why not, what it was granted (real-time priority, locked memory), and the gaps
        between frames written while heartbeating (p50, p99, p99.9, max [ms], from 1-ms
        bins: a percentile is its bin's upper edge), lease lapses and ring waits."""
        if self._native is None:
            return {"native": False, "why_not": self.native_why,
                    "lease_lapses": self.lease_lapses}
        if self._native.closed:
            return dict(self._final_report or {"native": True})
        st = self._native.stats(reset)
        out = {"native": True, "rt_priority": st["rt_priority"], "rt_refused": st["rt_refused"],
               "memory_locked": st["memory_locked"], "gap_max_ms": st["gap_max_ms"],
               "lease_lapses": st["lease_lapses"], "ring_waits": st["rx_waits"],
               "wake_late_max_ms": st["wake_late_max_ms"], "tx_timeouts": st["tx_timeouts"],
               "write_max_ms": st["write_max_ms"]}
        out.update(gap_percentiles(st["gap_hist"], 1.0, st["gap_max_ms"]))
        return out

    def device_report(self, reset: bool = False, timeout: float = 0.5) -> dict | None:
        """What the device saw of this host (LINK_QUERY → LINK_REPORT): intact frames and
        frames that failed a check since ``since_s`` [s, device clock], the gaps between
        intact frames its watchdog judged (p50, p99, p99.9 from 2-ms bins, and the exact
        max [ms of device time]) and the longest an ESTOP took from its arrival to the
        zeroing tick (``estop_max_ms``, counted from when the device last found its input
        empty before it: an upper bound; None: none since); ``reset`` starts afresh. None
        when the device does not know LINK_QUERY (it answers BAD_MESSAGE).

        Raises
        ------
        DeviceTimeoutError
            The ACK came but the report did not within ``timeout`` [s].
        """
        self.remove(lambda e: isinstance(e, M.LinkReport))
        if self.request(M.LinkQuery(int(bool(reset)))) != M.Status.OK:
            return None
        if not self.wait_for(lambda ev: any(isinstance(e, M.LinkReport) for e in ev), timeout):
            raise DeviceTimeoutError(f"{self.port}: LINK_QUERY acknowledged but no LINK_REPORT "
                                     f"within {timeout * 1e3:.0f} ms")
        r = self.remove(lambda e: isinstance(e, M.LinkReport))[-1]
        out = {"since_s": r.since_us * 1e-6, "frames": r.frames, "bad_frames": r.bad_frames,
               "gap_max_ms": r.max_gap_us * 1e-3, "gap_hist_2ms": list(r.items),
               "estop_max_ms": None if r.estop_max_us in (None, 0xFFFFFFFF)
               else r.estop_max_us * 1e-3}
        out.update(gap_percentiles(r.items, M.LINK_GAP_BIN_US * 1e-3, r.max_gap_us * 1e-3))
        return out

    # ------------------------------------------------------------------ shutdown
    def shutdown(self) -> None:
        """Stop the threads, then release the port.

        The reader must have left its read first: a read in progress in another thread keeps
        the port's file open (and its exclusive lock held) after close() returns.
        """
        self.closed = True
        with self.cv:
            self.cv.notify_all()  # a request waiting for its ACK stops waiting
        if self._native is not None and not self._native.closed:
            self._final_report = self.heartbeat_report()
            self._native.close()  # a read waiting in the reader returns at once
        cancel = getattr(self._ser, "cancel_read", None)
        if cancel is not None:
            try:
                cancel()
            except Exception:  # the port may already be gone
                pass
        me = threading.current_thread()
        for t in (self._reader, self._hb, self._watch):
            if t is not None and t is not me and t.is_alive():
                t.join(timeout=1.0)
        try:
            self._ser.close()
        except Exception:  # closing a port that is already gone
            pass
        if self._gc_held:
            self._gc_held = False
            hold_full_collections(False)
