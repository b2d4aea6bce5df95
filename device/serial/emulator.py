"""A device emulator: protocol version 2 served on a pseudo-terminal, the simulator as plant.

``hapticlab device emulate`` prints the pty's path as the first line of stdout and runs
until stopped. It follows docs/wire-protocol.md as the reference firmware does (the state
× command table, field ranges, the watchdog fed by every frame, a free-running device
clock, traces streamed during the window through a bounded ring) with the richer plant of
:class:`~device.sim.backend.SimDevice`: blocks that ring, supports derived from the
ringing, the simulated person's hand. Windows and playbacks run live (paced to the wall
clock, ``speed`` × real time) in a worker thread while the main loop keeps reading
commands, so heartbeats, e-stop and STOP_WINDOW act during a window.

Size: over 700 lines on purpose. The emulator is the device's side of the whole wire
protocol in one class, as the firmware's ``src/device.c`` is: the state × command table,
every command's checks and effects, the window worker and the trace ring share one state,
and a reader follows a command from its frame to its answer in one place. The plant is
:mod:`device.sim`; serving it as a process is :mod:`.serving`.
"""

from __future__ import annotations

import gc
import os
import select
import sys
import threading
import time
import tty
import zlib
from collections import deque
from dataclasses import replace

import numpy as np

from ..base import MAX_WINDOW_TICKS
from ..codes import Blend, SceneKind
from ..scene import Material, Ringing, Scene, Support, TableTransient, TransientTable
from ..sim.backend import SimDevice
from . import contract
from . import messages as M
from .contract import RangeError
from .framing import FrameDecoder

__all__ = ["Emulator", "open_pty"]

#: the simulator's fault names as the wire's codes: a simulated stylus that left every
#: physical bound commands, like a non-finite number, a current no servo should send
_FAULT = {name: code for code, name in M.FaultCode.NAMES.items()} | {
    "nan_command": M.FaultCode.NONFINITE, "diverged": M.FaultCode.NONFINITE}
#: field ranges the device enforces (docs/wire-protocol.md §4): HOME's clearance [µm],
#: a window's duration and first-contact timeout [ms]
#: the resources LIMITS advertises: table and playback [i16 items], the trace ring
#: [records], the channels recorded (all ten, the simulator's true_* included); a
#: simulated plant drawing its randomness from the seed it was started with
LIMITS = M.Limits(table_items=1_000_000, play_items=4_194_304, ring_records=65_536,
                  channels=(1 << len(M.Channel.NAMES)) - 1, max_decimation=100,
                  link_bytes_s=0,
                  capabilities=sum(1 << b for b, n in contract.CAPABILITIES.items()
                                   if n in ("simulated_contact", "seeded")))
#: frames from the outbox (trace chunks, the WINDOW_DONE behind them) per turn of the
#: serve loop, so that a command arriving during a stream is read between frames
OUTBOX_PER_TURN = 16
#: the outbox feeds the link only while fewer bytes than this wait to be written: a host
#: that does not read fills the ring (records dropped, said with TRACE_LOST), never the
#: transmit buffer, so ACKs and events are never queued behind the stream
TX_ROOM = 8192
#: bytes of control frames kept for a host that does not read (a dead one); beyond, the
#: oldest are dropped and counted
TX_MAX = 1 << 20
#: the servo's device time runs on only while the serve loop has found the port empty
#: within this long [s of wall time at ×1; × speed of device time]: the loop turns every
#: 2 ms when idle, so a longer wait means the emulator's own process was held up (its
#: other thread, a loaded machine), and the host's frames wait unread in the port. An
#: ESTOP is so acted on within this, the block being computed and the next one (1 ms each
#: at ×1): 7 ms × speed of device time from its arrival, however busy the computer
INPUT_TURN_S = 0.005


def _log(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def open_pty() -> tuple[int, int, str]:
    """A raw pseudo-terminal: (master fd, slave fd, slave path)."""
    master, slave = os.openpty()
    tty.setraw(slave)
    tty.setraw(master)
    return master, slave, os.ttyname(slave)


class Emulator:
    """Serve protocol version 2 on ``fd`` (a pty master) with ``sim`` as the plant.

    Parameters
    ----------
    sim : SimDevice
        Run in live mode by the emulator.
    fd : int
        File descriptor to read commands from and write replies to.
    status_hz : float [Hz]
        STATUS rate, in device time.
    limits : Limits
        The resources advertised and enforced (default :data:`LIMITS`).
    """

    def __init__(self, sim: SimDevice, fd: int, status_hz: float = 40.0,
                 limits: M.Limits = LIMITS):
        #: the longest window it records, its wait for a first contact included: what the
        #: simulator keeps in memory (MAX_WINDOW_TICKS) at its rate, or the protocol's own
        self.limits = limits = replace(limits, max_window_ms=min(
            contract.MAX_WINDOW_MS, int(MAX_WINDOW_TICKS / sim.info.servo_rate_hz * 1000)))
        #: the host session's protocol version, chosen at its HELLO (the newest before one)
        self.proto = contract.PROTOCOL
        #: HELLO_ACK's firmware text (16 bytes at most): the emulator's version, and its
        #: speed when not ×1, as "emulator-2x3" (a host scales the emulator's e-stop bound
        #: by it: SerialDevice.estop_bound_s)
        self.firmware = b"emulator-2" + (f"x{sim.speed:.3g}".encode() if sim.speed != 1 else b"")
        self._limit_values = M.limit_values(limits, int(round(sim.info.current_limit * 1000)))
        sim.live = True
        sim.trace_sink = self._stream
        sim.input_gate = self._input_read
        self.sim = sim
        self.fd = fd
        os.set_blocking(fd, False)
        self._tx = bytearray()  # frames not yet taken by the pty
        self.tx_dropped = 0  # bytes of control frames dropped for a host that does not read
        self.status_period = 1.0 / status_hz
        self.decoder = FrameDecoder()
        self._wlock = threading.Lock()
        self._seq = 0
        self._last: tuple[int, int, bytes, int] | None = None  # seq, type, body, status
        self._scenes: dict[int, dict] = {}
        self._play = np.zeros(0)
        self._worker: threading.Thread | None = None
        self._running: str | None = None  # what the worker runs: window, play, commit
        self._stop_asked = False  # the host ended the run (ZERO, STOP_WINDOW, HELLO)
        self._scene_ready = False  # a scene committed since the last upload command
        self._committing: tuple | None = None  # the SCENE_COMMIT being prepared
        self._prepared: int | None = None  # its verdict, once prepared
        self._homed_um: int | None = None  # HOME's clearance while homed (a playback
        self._rehome = False               # started homed returns to HOMED)
        self._stop = threading.Event()
        self._fault_sent = False
        self._fault_due = False  # a FAULT to tell once this turn's frames are handled
        self._fault_told = False  # the latched fault was sent in a FAULT or a STATUS
        self._told_at = 0.0  # device time [s] of that report's first
        self._estop_pending = False  # an ESTOP whose FAULT is not told yet
        self._clock0 = time.monotonic()  # power-up: the device clock counts from here
        self._ran = False  # a window or playback ran at the last clock sync
        self._synced = self._clock0  # when the device clock was last brought up [wall s]
        self._estop_rx: float | None = None  # the pending ESTOP arrived after this [s]
        # device time [s] the port was last seen empty: whatever is read later arrived after
        # it, so an ESTOP's wait is counted from there (an upper bound from its arrival)
        self._rx_empty_at = 0.0
        self.frames_in = 0
        # for the account at exit: the longest wall time [s] between two turns of the serve
        # loop, and between two writes to the pty (what a host sees as the device's silence)
        self.longest_turn = self.longest_write_gap = 0.0
        self._wrote_at = self._clock0
        self._link_reset(None)
        self._trace_config(limits.channels, 1)
        #: the trace ring: chunks (and the WINDOW_DONE behind them) waiting for the link,
        #: a few per loop turn, so a command arriving meanwhile (ESTOP) is served between
        self._outbox: deque[M.Message] = deque()
        self._olock = threading.Lock()
        self._queued = 0  # records in the outbox
        self.records_lost = 0

    # ------------------------------------------------------------------ clock, io
    def _sync(self) -> None:
        """Between windows the device clock runs on: bring the simulator's up to it (a
        window or playback advances it itself; a scene being prepared does not). It runs
        only while this process runs: a wait between two calls longer than
        :data:`INPUT_TURN_S` is this process held up (a loaded machine, its other thread),
        and a board is never held up, so the clock slips by the excess instead of jumping
        past frames that arrived meanwhile unread (it had tripped the watchdog while the
        host's frames came every 32 ms)."""
        now = time.monotonic()
        held, self._synced = now - self._synced, now
        if self._busy() and self._running in ("window", "play"):
            self._ran = True
            return
        if self._ran:
            # a window or playback just ended: the device clock goes on from its last
            # tick. The wall time its worker spent behind (packing 200,000 samples of a
            # 20-s window on a loaded machine) is the emulator held up, not time the host
            # let pass; jumping over it tripped the watchdog between two heartbeats
            self._ran = False
            self.sim.slipped_s = now - self._clock0 - self.sim.time / self.sim.speed
        elif held > INPUT_TURN_S:
            self.sim.slipped_s += held - INPUT_TURN_S
        self.sim.idle_until((now - self._clock0 - self.sim.slipped_s) * self.sim.speed)

    def _now_us(self) -> int:
        self._sync()
        return int(round(self.sim.time * 1e6))

    def send(self, msg: M.Message, flush: bool = True) -> None:
        """Queue a frame for the link and write what the pty takes now (never blocks;
        ``flush=False`` leaves the write to the caller, to batch frames in one)."""
        with self._wlock:
            self._seq = (self._seq + 1) & 0xFFFF
            self._tx += M.encode(msg, self._seq, self.proto)
            if len(self._tx) > TX_MAX:
                cut = len(self._tx) - TX_MAX
                self.tx_dropped += cut
                del self._tx[:cut]  # a partial frame left at the front is resynchronised
            if flush:
                self._flush()

    def _link_has_room(self) -> bool:
        """Whether the ring may feed the link now (few bytes wait to be written)."""
        return len(self._tx) < TX_ROOM

    def _flush(self) -> None:
        """Write queued bytes until the pty takes no more (under the write lock)."""
        while self._tx:
            try:
                n = os.write(self.fd, self._tx)
            except BlockingIOError:
                return
            except OSError:
                self._stop.set()  # the host side is gone
                self._tx.clear()
                return
            if n:
                now = time.monotonic()
                self.longest_write_gap = max(self.longest_write_gap, now - self._wrote_at)
                self._wrote_at = now
            del self._tx[:n]

    # ------------------------------------------------------------------ loop
    def serve_forever(self) -> None:
        next_status = 0.0  # device time [s]
        turn = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            self.longest_turn, turn = max(self.longest_turn, now - turn), now
            wait = 0.0 if self._outbox else 0.002
            r, _, _ = select.select([self.fd], [], [], wait)
            if r:
                try:
                    data = os.read(self.fd, 65536)
                except OSError:  # nothing after all (non-blocking), or the host side is gone
                    data = b""
                if data:
                    for frame in self.decoder.feed(data):
                        self.frames_in += 1
                        self._handle(frame)
                    if self._fault_due:  # an ESTOP outside a run: told after the frames
                        self._fault_due = False  # read with it (a CLEAR_FAULT among them
                        self._report_fault()  # finds it not yet told: docs §4)
            # the device time before a look that finds the port empty: whatever comes
            # later arrived after it (the servo worker may move the clock meanwhile;
            # between runs the clock is brought up to now first)
            self._sync()
            t = self.sim.time
            if not select.select([self.fd], [], [], 0)[0]:
                self._rx_empty_at = t
            self._commit_done()
            for _ in range(OUTBOX_PER_TURN):
                with self._olock:
                    if not self._outbox or not self._link_has_room():
                        break
                    msg = self._outbox.popleft()
                    if isinstance(msg, M.TraceChunk):
                        self._queued -= msg.n
                self.send(msg, flush=False)
            with self._wlock:  # one write for the turn's frames
                self._flush()
            self._sync()
            sim = self.sim
            # the host is judged on a silence this loop saw: at its last look that found
            # the port empty, the host's last frame was older than the period (a frame
            # waiting unread while this process was busy is no silence), as the firmware
            # judges it
            if (not self._busy() and sim.enabled and sim.fault is None
                    and self._rx_empty_at - sim.last_heartbeat > sim.watchdog_span):
                sim.trip_watchdog()  # armed while output is enabled (in a window the
                self._report_fault()  # servo loop trips it itself)
            if sim.time >= next_status:
                self._status()
                next_status = sim.time + self.status_period

    def stop(self) -> None:
        self._stop.set()
        self.sim.request_stop()

    def _stop_run(self) -> None:
        """End the running window or playback at the next block, even one whose worker has
        not reached the servo loop yet (the loop clears stale requests when it starts, so
        the worker asks again before each block: :meth:`_input_read`)."""
        self._stop_asked = True
        self.sim.request_stop()

    def _input_read(self) -> None:
        """From the servo worker before each block: wait until the serve loop has found
        the port empty within :data:`INPUT_TURN_S` of device time (× speed), so device
        time never runs far past frames that arrived but were not read, however late
        either thread runs (the worker's clock slips meanwhile); a stop asked before the
        block is passed on."""
        if self._stop_asked:
            self.sim.request_stop()
        turn = INPUT_TURN_S * self.sim.speed
        while (self.sim.time - self._rx_empty_at >= turn and not self._stop.is_set()
               and not self._stop_asked):
            time.sleep(0.0005)

    def _state(self) -> int:
        if self.sim.fault is not None:
            return M.State.FAULT
        if self._busy() and self._running == "window":
            return M.State.WINDOW
        if self._busy() and self._running == "play":
            return M.State.PLAYING
        return M.State.HOMED if self.sim.enabled else M.State.IDLE

    def _status(self) -> None:
        f, state = self.sim.fault, self._state()
        # output off (IDLE, FAULT) delivers nothing, whatever the last run ended on
        out = 0 if state in (M.State.IDLE, M.State.FAULT) else self.sim.output_force
        out_mn = max(-2**31, min(2**31 - 1, int(round(out * 1000))))
        self.send(M.StatusReport(self._now_us(), state, out_mn,
                                 _FAULT[f.code] if f is not None else 0))
        if f is not None:  # the fault told, an ESTOP read before this with it
            self._told()

    def _told(self) -> None:
        """A FAULT or a STATUS with the fault just went: the first since it latched or since
        the last ESTOP is when a host could first know of it."""
        if not self._fault_told or self._estop_pending:
            self._told_at = self.sim.time
        self._fault_told = True
        self._estop_pending = False

    def _report_fault(self) -> None:
        f = self.sim.fault
        if f is not None and not self._fault_sent:
            self._fault_sent = True
            self._told()
            if f.code == "estop" and self._estop_rx is not None:
                lat = max(0.0, f.t - self._estop_rx)
                self._estop_max = lat if self._estop_max is None else max(self._estop_max, lat)
                self._estop_rx = None
            self.send(M.Fault(_FAULT[f.code], int(round(f.t * 1e6))))
            # for people and tests: how long after the host's last frame output went off
            since = f.t - self.sim.last_heartbeat
            _log(f"FAULT {f.code} at device time {f.t:.4f} s, {since * 1e3:.1f} ms after the "
                 "last heartbeat")

    # ------------------------------------------------------------------ commands
    # ------------------------------------------------------------------ LINK_REPORT
    def _link_reset(self, now: float | None) -> None:
        """Count the host's frames afresh; a frame at ``now`` [s, device time] (None: no
        frame yet) is the first of the next gap."""
        self._gaps = [0] * M.LINK_GAP_BINS
        self._gap_max = 0.0
        self._gap_prev = now
        self._gap_frames = 0 if now is None else 1
        self._gap_bad0 = sum(self.decoder.errors.values())
        self._gap_since = 0.0 if now is None else now
        self._estop_max: float | None = None  # ESTOP arrival → zeroing tick [device s]

    def _link_note(self, now: float) -> None:
        """An intact host frame at device time ``now`` [s]: the gap since the last one."""
        if self._gap_prev is not None:
            gap = now - self._gap_prev
            # binned from the whole µs the report gives its longest in, so that the longest
            # lies in the highest bin (13.9999996 ms once fell in bin 6 and read 14.000)
            us = int(round(gap * 1e6))
            k = min(us // M.LINK_GAP_BIN_US, M.LINK_GAP_BINS - 1)
            self._gaps[k] = min(self._gaps[k] + 1, 0xFFFF)
            self._gap_max = max(self._gap_max, gap)
        self._gap_prev = now
        self._gap_frames += 1

    def _link_report(self) -> M.LinkReport:
        bad = sum(self.decoder.errors.values()) - self._gap_bad0
        estop = (0xFFFFFFFF if self._estop_max is None
                 else min(int(round(self._estop_max * 1e6)), 0xFFFFFFFE))
        return M.LinkReport(int(round(self._gap_since * 1e6)), self._gap_frames, bad,
                            min(int(round(self._gap_max * 1e6)), 0xFFFFFFFF), estop,
                            tuple(self._gaps))

    # ------------------------------------------------------------------ commands
    def _handle(self, frame) -> None:
        self._sync()
        self._link_note(self.sim.time)
        self.sim.heartbeat()  # every intact frame feeds the watchdog
        if frame.type == M.EStop.TYPE:  # acted on whatever its body and frame version: a
            msg: M.Message = M.EStop()  # stray byte must not keep the output on (docs §3)
        else:
            try:
                msg = M.decode(frame)
            except M.MessageError:
                self.send(M.Ack(frame.seq, M.Status.BAD_MESSAGE))
                return
        if isinstance(msg, M.Hello):
            self._link_reset(self.sim.time)  # a new host session
            self._hello(msg.host_protocol)
            return
        if frame.version != self.proto and not isinstance(msg, M.EStop):
            # the session's version, from HELLO_ACK on
            self.send(M.Ack(frame.seq, M.Status.BAD_MESSAGE))
            return
        if isinstance(msg, M.Heartbeat):
            return
        if isinstance(msg, M.Ping):
            self.send(M.Pong(msg.stamp))
            return
        last = self._last
        if last is not None and last[:3] == (frame.seq, frame.type, frame.body):
            # the host did not hear our ACK and sent the same command again: answer, don't redo
            self.send(M.Ack(frame.seq, last[3]))
            return
        if isinstance(msg, M.SceneCommit):
            self._commit(frame, msg)
            return
        status = self._execute(msg)
        self._last = (frame.seq, frame.type, frame.body, status)
        self.send(M.Ack(frame.seq, status))
        if isinstance(msg, M.LinkQuery) and status == M.Status.OK:  # the report follows
            self.send(self._link_report())
            if msg.reset:
                self._link_reset(self.sim.time)

    def _hello(self, host_protocol: int) -> None:
        """HELLO, from a frame of any version: a new host session. A window or playback left
        running ends; output goes off (IDLE) unless a fault is latched; the rating and the
        default trace configuration come back. Answered in the newest version it speaks
        that the host's is not below (its oldest, 2, for an older host), then LIMITS, each
        laid out as that version lays it out (docs §1a, §1b)."""
        self.proto = max(contract.OLDEST, min(contract.PROTOCOL, host_protocol))
        self._last = None  # a new host session starts its sequence numbers again
        if self._busy() and self._running != "commit":
            self._rehome = False
            self._stop_run()
            self._worker.join(timeout=2.0)
        with self._olock:
            self._outbox.clear()  # the old session's stream is nobody's now
            self._queued = 0
        sim, i = self.sim, self.sim.info
        if sim.fault is None:
            sim.zero()
        sim.set_current_limit(i.current_limit)
        self._trace_config(self.limits.channels, 1)
        self.send(M.HelloAck(
            self.proto, int(i.servo_rate_hz), int(round(i.current_limit * 1000)),
            int(round(i.force_constant * 1000)), int(round(i.effective_mass * 1e6)),
            int(round(i.watchdog_s * 1000)), int(round(i.encoder_resolution * 1e9)),
            int(round(i.accel_range * 1000)), b"hapticlab emulator (sim plant)",
            i.serial_number.encode(), self.firmware))
        self.send(self.limits)

    def _busy(self) -> bool:
        return self._worker is not None and self._worker.is_alive()

    def _commit(self, frame, msg: M.SceneCommit) -> None:
        """SCENE_COMMIT: the scene is prepared (the simulator models it: a block's support
        is derived, propagators computed) off the serve loop, so STATUS frames keep coming;
        the ACK follows when it is ready. A repeat of the same frame meanwhile waits for it."""
        key = (frame.seq, frame.type, frame.body)
        if self._busy():
            if self._committing == key:
                return  # the host resent it: the ACK is on its way
            self.send(M.Ack(frame.seq, M.Status.BUSY))
            return
        status, scene = self._check_commit(msg)
        if status != M.Status.OK:
            self._last = (*key, status)
            self.send(M.Ack(frame.seq, status))
            return
        self._committing = key
        self._scene_upload()

        def prepare(_msg) -> None:
            try:
                self.sim.load_scene(scene)
                self._prepared = M.Status.OK
                self._scene_ready = True
            except (ValueError, TypeError):  # SceneError is a ValueError
                self._prepared = M.Status.BAD_MESSAGE

        self._prepared = None
        self._start("commit", prepare, msg)

    def _commit_done(self) -> None:
        """From the serve loop: once the scene is prepared (its thread ended, so the next
        command does not find the emulator busy), the SCENE_COMMIT's ACK."""
        if self._committing is None or self._busy():
            return
        seq, status = self._committing[0], self._prepared
        if status is None:  # the thread died without a verdict (the emulator stops)
            status = M.Status.BAD_MESSAGE
        self._last = (*self._committing, status)
        self._committing = None
        self.send(M.Ack(seq, status))

    def _check_commit(self, msg: M.SceneCommit):
        """(status, scene) of a commit: the upload complete and intact, the scene built."""
        S = M.Status
        sc = self._scenes.get(msg.scene_id)
        if sc is None:
            return S.UNKNOWN_SCENE, None
        if sc["begin"].kind == SceneKind.TABLE and sc["v"] is None:
            return S.BAD_MESSAGE, None  # a table scene needs its velocities
        table = sc["table"]
        crc = zlib.crc32(table.astype("<i2").tobytes()) & 0xFFFFFFFF if table.size else 0
        if crc != msg.crc32:
            return S.TABLE_CRC, None
        try:
            sc["scene"] = self._build_scene(sc)
        except (ValueError, TypeError):
            return S.BAD_MESSAGE, None
        return S.OK, sc["scene"]

    def _scene_upload(self) -> None:
        """A scene command accepted: output goes off (HOMED → IDLE; a fault stays) and the
        scene is withdrawn until its SCENE_COMMIT (HOME is BAD_STATE meanwhile)."""
        if self.sim.enabled:
            self.sim.zero()
        self._homed_um = None
        self._scene_ready = False

    def _fields_fit(self, msg: M.Message) -> bool:
        """The ranges of docs/wire-protocol.md §5a (the contract's, against this device's
        limits) and the rules between fields, checked before the state (a misfit is
        BAD_MESSAGE in every state, and changes nothing)."""
        try:
            msg.check(self._limit_values)
        except RangeError:
            return False
        if isinstance(msg, M.SceneBegin):
            if msg.kind == SceneKind.TABLE:
                return msg.rows > 0 and msg.row_len > 0 and (
                    msg.rows * msg.row_len <= self.limits.table_items)
            return msg.rows == msg.row_len == 0
        if isinstance(msg, M.SceneVelocities):
            return bool((np.diff(np.asarray(msg.items, np.float32)) > 0).all())
        if isinstance(msg, M.PlayChunk):
            return msg.offset + msg.n <= self.limits.play_items
        if isinstance(msg, M.StartWindow):  # refused by name, before anything acts
            span = msg.duration_ms + (msg.timeout_ms if msg.from_contact else 0)
            return span <= self.limits.max_window_ms
        return True

    def _execute(self, msg: M.Message) -> int:
        """The ACK status of a command, per the state × command table (docs §4)."""
        S = M.Status
        sim = self.sim
        if not self._fields_fit(msg) or contract.gate(msg.NAME, 0) == S.BAD_MESSAGE:
            return S.BAD_MESSAGE  # out of range, or a device → host type (any state)
        running = self._busy() and self._running in ("window", "play")
        if isinstance(msg, M.EStop):
            if sim.fault is None:
                self._estop_rx = self._rx_empty_at  # it arrived after: to the zeroing tick
            sim.estop()  # the servo loop zeroes output at its next tick
            self._rehome = False
            self._estop_pending = True
            if not running:  # in a window the loop reports it, timed at the zeroing tick
                self._fault_due = True
            _log("host: ESTOP")
            return S.OK
        if isinstance(msg, M.ClearFault):
            # a fault the host cannot have seen reported (this frame was read after a look
            # that found the port empty before the report went) stays: docs §4
            if self._estop_pending or (sim.fault is not None and (
                    not self._fault_told or self._rx_empty_at < self._told_at)):
                return S.FAULT_LATCHED
            if sim.fault is not None:
                sim.clear_fault()
                self._homed_um = None
            self._fault_sent = self._fault_told = False
            return S.OK
        if isinstance(msg, M.Zero):
            self._rehome = False
            self._homed_um = None
            sim.zero()
            if running:
                self._stop_run()
            _log("host: ZERO")
            return S.OK
        if isinstance(msg, M.StopWindow):
            if running:
                self._stop_run()
            return S.OK
        if isinstance(msg, M.LinkQuery):
            return S.OK  # in every state; the report follows the ACK
        if self._busy():
            return S.BUSY  # running, or a scene being prepared
        if isinstance(msg, (M.SceneBegin, M.SceneVelocities, M.SceneChunk, M.SceneSupport)):
            return self._scene_part(msg)
        if isinstance(msg, (M.Home, M.StartWindow, M.PlayStart)) and sim.fault is not None:
            return S.FAULT_LATCHED
        if isinstance(msg, M.SetLimit):
            sim.set_current_limit(msg.current_ma / 1000)
            _log(f"host: current limit {msg.current_ma} mA")
            return S.OK
        if isinstance(msg, M.TraceConfig):
            self._trace_config(msg.channels, msg.decimation)
            return S.OK
        if isinstance(msg, M.Home):
            if sim.scene is None or not self._scene_ready:
                return S.BAD_STATE
            sim.home(msg.clearance_um * 1e-6)
            self._homed_um = msg.clearance_um
            return S.OK
        if isinstance(msg, M.StartWindow):
            if sim.scene is None or not sim.enabled:
                return S.BAD_STATE
            self._start("window", self._run_window, msg)
            return S.OK
        if isinstance(msg, M.PlayChunk):
            end = msg.offset + msg.n
            if end > self._play.size:
                self._play = np.concatenate([self._play, np.zeros(end - self._play.size)])
            self._play[msg.offset:end] = np.array(msg.items, float) * 1e-3
            return S.OK
        if isinstance(msg, M.PlayStart):
            if msg.n_samples > self._play.size:
                self._play = np.concatenate([self._play,
                                             np.zeros(msg.n_samples - self._play.size)])
            self._rehome = sim.enabled and self._homed_um is not None
            self._start("play", self._run_play, msg)
            return S.OK
        return S.BAD_MESSAGE  # a type no table row names

    def _scene_part(self, msg: M.Message) -> int:
        """SCENE_BEGIN, _VELOCITIES, _CHUNK, _SUPPORT (not running)."""
        S = M.Status
        if isinstance(msg, M.SceneBegin):
            self._scene_upload()
            # one upload at a time: a scene begun before this one is withdrawn, and a
            # command naming it is UNKNOWN_SCENE (docs §4), as on a device that has room
            # for one table
            self._scenes = {msg.scene_id: {"begin": msg, "v": None,
                                           "table": np.zeros(msg.rows * msg.row_len, np.int16),
                                           "scene": None}}
            return S.OK
        sc = self._scenes.get(msg.scene_id)
        if sc is None:
            return S.UNKNOWN_SCENE
        if isinstance(msg, M.SceneSupport):
            if sc["begin"].kind != SceneKind.REAL:
                return S.BAD_MESSAGE
            sc["support"] = msg
        elif isinstance(msg, M.SceneVelocities):
            if len(msg.items) != sc["begin"].rows:
                return S.BAD_MESSAGE
            sc["v"] = np.array(msg.items, float)
        else:
            if msg.offset + msg.n > sc["table"].size:
                return S.BAD_MESSAGE
            sc["table"][msg.offset: msg.offset + msg.n] = msg.items
        self._scene_upload()
        return S.OK

    def _build_scene(self, sc: dict) -> Scene:
        b: M.SceneBegin = sc["begin"]
        h = b.surface_um * 1e-6
        name = f"scene-{b.scene_id}"
        if b.kind == SceneKind.REAL:
            sup = sc.get("support")
            # a block on a given support is simulated on it; its ringing only describes it
            ring = (Ringing(b.ring_slope, b.ring_decay, b.ring_freq)
                    if b.ring_freq > 0 and sup is None else None)
            return Scene(name, surface_height=h, material=Material(
                b.stiffness, b.damping, ring, mass=b.block_mass if b.block_mass > 0 else None,
                support=Support(sup.stiffness, sup.damping) if sup is not None else None))
        if b.kind == SceneKind.SPRING:
            return Scene(name, surface_height=h, spring=b.spring)
        forces = sc["table"].reshape(b.rows, b.row_len).astype(float) * 1e-3
        table = TransientTable(sc["v"], forces, Blend(b.blend), b.attenuation)
        return Scene(name, surface_height=h, spring=b.spring, transient=TableTransient(table))

    def _start(self, what: str, target, msg) -> None:
        def run() -> None:
            try:
                target(msg)
            except Exception as exc:  # an emulator bug: stop, as a device that resets would
                print(f"emulator: {type(exc).__name__} in {target.__name__}: {exc}; stopping",
                      file=sys.stderr, flush=True)
                self.stop()

        self._running = what
        self._stop_asked = False
        self._worker = threading.Thread(target=run, daemon=True)
        self._worker.start()

    # ------------------------------------------------------------------ windows, traces
    def _trace_config(self, channels: int, decimation: int) -> None:
        self._mask, self._decim = channels, decimation
        self._names = [n for ch, n in enumerate(M.Channel.NAMES) if channels >> ch & 1]
        self._per_chunk = M.TRACE_ITEMS // len(self._names)

    def _open_stream(self, window_id: int) -> None:
        self._wid = window_id
        self._records: list[np.ndarray] = []  # recorded, not yet a full chunk
        self._n_pending = 0
        self._next_record = 0  # the window's record index the next chunk starts at

    def _stream(self, tick: int, piece: dict[str, np.ndarray]) -> None:
        """The simulator's new ticks [tick, tick + n) of the running window: keep every
        decimation-th as a record, send full chunks through the ring."""
        d = self._decim
        first = -tick % d  # the first tick of the piece that is a record
        rows = np.column_stack([piece[name][first::d] for name in self._names])
        if len(rows):
            self._records.append(rows.astype(np.float32))
            self._n_pending += len(rows)
        while self._n_pending >= self._per_chunk:
            self._emit(self._per_chunk)

    def _emit(self, n: int) -> None:
        """Queue the next ``n`` pending records as a chunk, or as TRACE_LOST when the ring
        has no room for them (the newest records are the ones dropped)."""
        block = np.concatenate(self._records) if len(self._records) > 1 else self._records[0]
        take, rest = block[:n], block[n:]
        self._records = [rest] if len(rest) else []
        self._n_pending -= n
        start = self._next_record
        self._next_record += n
        with self._olock:
            if self._queued + n > self.limits.ring_records:
                self.records_lost += n
                last = self._outbox[-1] if self._outbox else None
                if (isinstance(last, M.TraceLost) and last.window_id == self._wid
                        and last.start + last.n == start):
                    self._outbox[-1] = M.TraceLost(self._wid, last.start, last.n + n)
                else:
                    self._outbox.append(M.TraceLost(self._wid, start, n))
                return
            self._queued += n
            self._outbox.append(M.TraceChunk(self._wid, self._mask, start, n,
                                             tuple(take.ravel().tolist())))

    def _finish(self, window_id: int, res, t0_us: int) -> None:
        if self._stop.is_set():
            return  # switched off mid-window: a device losing power reports nothing more
        rate = self.sim.info.servo_rate_hz
        t0 = t0_us * 1e-6
        for s in res.saturations:
            self.send(M.Saturation(window_id, int(round((s.t - t0) * rate)),
                                   int(round(s.duration * rate)),
                                   min(2**31 - 1, int(round(abs(s.peak_current) * 1000)))))
        if res.faults:
            self._report_fault()
        if self._n_pending:
            self._emit(self._n_pending)  # the last chunk may be short
        first = -1 if res.t_first_contact is None else int(round((res.t_first_contact - t0)
                                                                  * rate))
        with self._olock:  # after the window's last chunk
            fault = _FAULT[res.faults[0].code] if res.faults else 0
            self._outbox.append(M.WindowDone(window_id, t0_us, len(res.traces["t"]), first,
                                             min(len(res.contacts), 0xFFFF),  # saturated
                                             min(len(res.saturations), 0xFFFF),
                                             int(res.timed_out), fault))

    def _run_window(self, msg: M.StartWindow) -> None:
        sent = 0
        self._open_stream(msg.window_id)
        tick0 = self.sim.time
        t0_us = int(round(tick0 * 1e6))
        rate = self.sim.info.servo_rate_hz
        last_pos = [0.0]

        def progress(_t, partial) -> None:
            nonlocal sent
            now = time.monotonic()
            if partial.live_height is not None and now - last_pos[0] >= 0.025:
                last_pos[0] = now  # the cursor's stream, ~40 Hz
                # the tick that read this height: the last one run
                tick = max(0, int(round((self.sim.time - tick0) * rate)) - 1)
                height = max(-2**31, min(2**31 - 1, int(round(partial.live_height * 1e6))))
                self.send(M.Position(msg.window_id, tick, height))
            for c in partial.contacts[sent:]:
                self.send(M.Contact(msg.window_id, int(round((c.t - tick0) * rate)),
                                    M.contact_velocity_nm_s(c.velocity)))
            sent = len(partial.contacts)
            if self.sim.fault is not None and self.sim.output_latched_off:
                self._report_fault()  # output is latched off: the window is over
                self.sim.request_stop()

        res = self.sim.run_window(msg.duration_ms / 1000,
                                  from_first_contact=bool(msg.from_contact),
                                  timeout=msg.timeout_ms / 1000, on_progress=progress,
                                  heartbeats=False)
        for c in res.contacts[sent:]:
            self.send(M.Contact(msg.window_id, int(round((c.t - tick0) * rate)),
                                M.contact_velocity_nm_s(c.velocity)))
        self._finish(msg.window_id, res, t0_us)

    def _run_play(self, msg: M.PlayStart) -> None:
        """A playback in free air, output enabled (ramped) for it alone; started homed, the
        device is homed again afterwards (a playback returns to the state it started from)."""
        self._open_stream(msg.window_id)
        t0_us = int(round(self.sim.time * 1e6))
        # the buffer keeps its contents: a second PLAY_START plays it again (docs §5)
        res = self.sim.play_force(self._play[: msg.n_samples], heartbeats=False)
        if self._rehome and self.sim.fault is None and self._homed_um is not None:
            self.sim.home(self._homed_um * 1e-6)
        self._finish(msg.window_id, res, t0_us)


def warm_up(rate_hz: float) -> None:
    """Load the compiled servo loop once (virtual time), so the first window on the wire
    does not stall the emulator for the time it takes to load machine code."""
    dev = SimDevice(rate_hz=rate_hz)
    from ..suite import SUITE_SCENES

    for scene in (SUITE_SCENES["wood"], Scene("s", spring=680.0)):
        dev.load_scene(scene)
        dev.home()
        dev.run_window(0.05, from_first_contact=False)
    dev.play_force(np.zeros(10))


def main(rate_hz: float = 10_000.0, seed: int = 0, speed: float = 1.0) -> int:
    """Serve on a new pty until SIGTERM/SIGINT; the first stdout line is the port."""
    import signal

    # the worker computing the servo holds the interpreter between its sleeps (all the time
    # when it runs faster than real time): hand it over every 0.5 ms, not every 5, so the
    # loop serving the link reads heartbeats and ESTOP promptly
    sys.setswitchinterval(0.0005)
    warm_up(rate_hz)
    master, slave, path = open_pty()
    sim = SimDevice(rate_hz=rate_hz, seed=seed, live=True, speed=speed)
    # what is loaded now lives as long as the device: spare it the collector's full passes,
    # which on a loaded machine stop both threads for ~0.1 s
    gc.freeze()
    emu = Emulator(sim, master)
    stop = lambda *_: emu.stop()  # noqa: E731
    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    print(path, flush=True)
    print(f"emulating a {rate_hz:g}-Hz device (protocol {contract.PROTOCOL}, sim plant, seed "
          f"{seed}, speed ×{speed:g}); stop with Ctrl-C", file=sys.stderr, flush=True)
    try:
        emu.serve_forever()
    finally:
        os.close(master)
        os.close(slave)
        print(f"emulator: {emu.frames_in} frames in, {emu.tx_dropped} bytes dropped for a host "
              f"that did not read, {emu.records_lost} trace records lost; its serve loop's "
              f"longest turn {emu.longest_turn * 1e3:.0f} ms, longest between two writes "
              f"{emu.longest_write_gap * 1e3:.0f} ms", file=sys.stderr, flush=True)
    return 0

