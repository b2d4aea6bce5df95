"""A device emulator: the wire protocol served on a pseudo-terminal, the simulator as plant.

``hapticlab device emulate`` prints the pty's path as the first line of stdout and runs
until stopped. Windows and playbacks run live (paced to the wall clock, ``speed`` × real
time) in a worker thread while the main loop keeps reading commands, so heartbeats,
e-stop and STOP_WINDOW act during a window. The watchdog is the simulator's own inside a
window and the emulator's between windows (no heartbeat for the device's T_wd → output
latched off, FAULT sent).
"""

from __future__ import annotations

import math
import os
import select
import sys
import threading
import time
import tty
import zlib
from collections import deque

import numpy as np

from ..codes import Blend, SceneKind
from ..scene import Material, Ringing, Scene, Support, TableTransient, TransientTable
from ..sim.backend import SimDevice
from . import messages as M
from .framing import FrameDecoder

__all__ = ["Emulator", "open_pty"]

_FAULT = {name: code for code, name in M.FaultCode.NAMES.items()}
#: field ranges the device enforces (docs/wire-protocol.md §5): HOME's clearance [µm],
#: a window's duration and first-contact timeout [ms], a scene's table [items]
MAX_CLEARANCE_UM = 500_000
MAX_WINDOW_MS = 600_000
MAX_TABLE_ITEMS = 1_000_000
#: trace blocks sent per turn of the serve loop (each ~1 KB)
OUTBOX_PER_TURN = 2


def _log(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def open_pty() -> tuple[int, int, str]:
    """A raw pseudo-terminal: (master fd, slave fd, slave path)."""
    master, slave = os.openpty()
    tty.setraw(slave)
    tty.setraw(master)
    return master, slave, os.ttyname(slave)


class Emulator:
    """Serve the protocol on ``fd`` (a pty master) with ``sim`` as the plant.

    Parameters
    ----------
    sim : SimDevice
        Run in live mode by the emulator.
    fd : int
        File descriptor to read commands from and write replies to.
    status_hz : float [Hz]
        STATUS rate.
    """

    def __init__(self, sim: SimDevice, fd: int, status_hz: float = 40.0):
        sim.live = True
        self.sim = sim
        self.fd = fd
        self.status_period = 1.0 / status_hz
        self.decoder = FrameDecoder()
        self._wlock = threading.Lock()
        self._seq = 0
        self._last: tuple[int, int, bytes, int] | None = None  # seq, type, body, status
        self._scenes: dict[int, dict] = {}
        self._play = np.zeros(0)
        self._traces: dict[int, dict] = {}
        self._worker: threading.Thread | None = None
        self._committing: tuple | None = None  # the SCENE_COMMIT being prepared
        self._prepared: int | None = None  # its verdict, once prepared
        self._last_heartbeat = time.monotonic()
        self._stop = threading.Event()
        self._fault_sent = False
        self.frames_in = 0
        #: trace blocks waiting to be sent: a few per loop turn, so a command that arrives
        #: during an upload (ESTOP) is served between blocks, not after the whole trace
        self._outbox: deque[M.Message] = deque()

    # ------------------------------------------------------------------ io
    def send(self, msg: M.Message) -> None:
        with self._wlock:
            self._seq = (self._seq + 1) & 0xFFFF
            data = M.encode(msg, self._seq)
            try:
                os.write(self.fd, data)
            except OSError:
                self._stop.set()  # the host side is gone

    def _device_time_us(self) -> int:
        return int(self.sim.time * 1e6)

    # ------------------------------------------------------------------ loop
    def serve_forever(self) -> None:
        next_status = time.monotonic()
        while not self._stop.is_set():
            r, _, _ = select.select([self.fd], [], [], 0.0 if self._outbox else 0.002)
            if r:
                try:
                    data = os.read(self.fd, 65536)
                except OSError:
                    data = b""
                if data:
                    for frame in self.decoder.feed(data):
                        self.frames_in += 1
                        self._handle(frame)
            self._commit_done()
            for _ in range(OUTBOX_PER_TURN):
                if not self._outbox:
                    break
                self.send(self._outbox.popleft())
            now = time.monotonic()
            busy = self._worker is not None and self._worker.is_alive()
            wd = self.sim.info.watchdog_s
            silent = now - self._last_heartbeat > wd
            if silent and not busy and select.select([self.fd], [], [], 0)[0]:
                # bytes are waiting: we were busy writing (a long trace upload) and the
                # host's heartbeats queued up unread; read them before judging the host
                continue
            if not busy and self.sim.fault is None and self.sim.enabled and silent:
                self.sim.trip_watchdog()
                self._report_fault()
            if now >= next_status:
                self._status()
                next_status = now + self.status_period

    def stop(self) -> None:
        self._stop.set()
        self.sim.request_stop()

    def _status(self) -> None:
        busy = self._worker is not None and self._worker.is_alive()
        state = (M.State.FAULT if self.sim.fault else M.State.WINDOW if busy
                 else M.State.HOMED if self.sim.enabled else M.State.IDLE)
        f = self.sim.fault
        self.send(M.StatusReport(self._device_time_us(), state,
                                 int(round(self.sim.output_force * 1000)),
                                 _FAULT.get(f.code, 0) if f is not None else 0))

    def _report_fault(self) -> None:
        f = self.sim.fault
        if f is not None and not self._fault_sent:
            self._fault_sent = True
            self.send(M.Fault(_FAULT.get(f.code, 0), int(f.t * 1e6)))
            # for people and tests: how long after the host's last heartbeat output went off
            since = f.t - self.sim.last_heartbeat
            _log(f"FAULT {f.code} at device time {f.t:.4f} s, {since * 1e3:.1f} ms after the "
                 "last heartbeat")

    # ------------------------------------------------------------------ commands
    def _handle(self, frame) -> None:
        try:
            msg = M.decode(frame)
        except M.MessageError:
            self.send(M.Ack(frame.seq, M.Status.BAD_MESSAGE))
            return
        if isinstance(msg, M.Heartbeat):
            self._last_heartbeat = time.monotonic()
            self.sim.heartbeat()
            return
        if isinstance(msg, M.Ping):
            self.send(M.Pong(msg.stamp))
            return
        last = self._last
        if last is not None and last[:3] == (frame.seq, frame.type, frame.body):
            # the host did not hear our ACK and sent the same command again: answer, don't redo
            self.send(M.Ack(frame.seq, last[3]))
            return
        self._last_heartbeat = time.monotonic()
        self.sim.heartbeat()
        if isinstance(msg, M.SceneCommit):
            self._commit(frame, msg)
            return
        if isinstance(msg, M.Hello):
            self._last = None  # a new host session starts its sequence numbers again
            self._outbox.clear()  # the old session's trace upload is nobody's now
            if self._busy():  # a window left running by a host that went away
                self.sim.request_stop()
                self._worker.join(timeout=2.0)
        status = self._execute(msg)
        if status is not None:
            self._last = (frame.seq, frame.type, frame.body, status)
            self.send(M.Ack(frame.seq, status))
            if isinstance(msg, M.TraceRequest) and status == M.Status.OK:
                self._send_trace(msg)

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

        def prepare(_msg) -> None:
            try:
                self.sim.load_scene(scene)
                self._prepared = M.Status.OK
            except (ValueError, TypeError):  # SceneError is a ValueError
                self._prepared = M.Status.BAD_MESSAGE

        self._prepared = None
        self._start(prepare, msg)

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
        crc = zlib.crc32(sc["table"].astype("<i2").tobytes()) & 0xFFFFFFFF
        if sc["begin"].rows and crc != msg.crc32:
            return S.TABLE_CRC, None
        try:
            sc["scene"] = self._build_scene(sc)
        except (ValueError, TypeError):
            return S.BAD_MESSAGE, None
        return S.OK, sc["scene"]

    def _execute(self, msg: M.Message) -> int | None:
        S = M.Status
        sim = self.sim
        if isinstance(msg, M.Hello):
            i = sim.info
            sim.set_current_limit(i.current_limit)  # a new host session: the rating again
            self.send(M.HelloAck(
                1, int(i.servo_rate_hz), int(round(i.current_limit * 1000)),
                int(round(i.force_constant * 1000)), int(round(i.effective_mass * 1e6)),
                int(round(i.watchdog_s * 1000)), int(round(i.encoder_resolution * 1e9)),
                int(round(i.accel_range * 1000)), b"hapticlab emulator (sim plant)",
                i.serial_number.encode(), b"emulator-1"))
            return None
        if isinstance(msg, M.EStop):
            sim.estop()
            if not self._busy():  # in a window the loop reports it, timed at the zeroing tick
                self._report_fault()
            _log("host: ESTOP")
            return S.OK
        if isinstance(msg, M.ClearFault):
            sim.clear_fault()
            self._fault_sent = False
            return S.OK
        if isinstance(msg, M.Zero):
            sim.zero()
            sim.request_stop()
            _log("host: ZERO")
            return S.OK
        if isinstance(msg, M.StopWindow):
            sim.request_stop()
            return S.OK
        if isinstance(msg, M.TraceRequest):
            tr = self._traces.get(msg.window_id)
            if tr is None or msg.channel >= len(M.Channel.NAMES):
                return S.BAD_MESSAGE
            name = M.Channel.NAMES[msg.channel]
            if name not in tr or msg.start + msg.count > len(tr[name]):
                return S.BAD_MESSAGE
            return S.OK
        if self._busy():
            return S.BUSY
        if isinstance(msg, M.SceneBegin):
            if msg.kind not in tuple(SceneKind) or msg.blend not in tuple(Blend):
                return S.BAD_MESSAGE
            floats = (msg.spring, msg.stiffness, msg.damping, msg.ring_slope, msg.ring_decay,
                      msg.ring_freq, msg.block_mass, msg.attenuation)
            if not all(math.isfinite(x) for x in floats) or not 0 <= msg.attenuation <= 1:
                return S.BAD_MESSAGE  # NaN/inf never reach the servo (docs §5 ranges)
            if msg.rows * msg.row_len > MAX_TABLE_ITEMS:
                return S.BAD_MESSAGE
            self._scenes[msg.scene_id] = {"begin": msg, "v": None,
                                          "table": np.zeros(msg.rows * msg.row_len, np.int16),
                                          "scene": None}
            return S.OK
        if isinstance(msg, (M.SceneVelocities, M.SceneChunk, M.SceneSupport)):
            sc = self._scenes.get(msg.scene_id)
            if sc is None:
                return S.UNKNOWN_SCENE
            floats = (msg.items if isinstance(msg, M.SceneVelocities) else
                      (msg.stiffness, msg.damping) if isinstance(msg, M.SceneSupport) else ())
            if not all(math.isfinite(x) for x in floats):
                return S.BAD_MESSAGE
            if isinstance(msg, M.SceneSupport):
                if sc["begin"].kind != SceneKind.REAL:
                    return S.BAD_MESSAGE
                sc["support"] = msg
                return S.OK
            if isinstance(msg, M.SceneVelocities):
                if len(msg.items) != sc["begin"].rows:
                    return S.BAD_MESSAGE
                sc["v"] = np.array(msg.items, float)
                return S.OK
            if msg.offset + msg.n > sc["table"].size:
                return S.BAD_MESSAGE
            sc["table"][msg.offset: msg.offset + msg.n] = msg.items
            return S.OK
        if sim.fault is not None and isinstance(msg, (M.Home, M.StartWindow, M.PlayStart)):
            return S.FAULT_LATCHED
        if isinstance(msg, M.SetLimit):
            if not 0 < msg.current_ma <= int(round(sim.info.current_limit * 1000)):
                return S.BAD_MESSAGE
            sim.set_current_limit(msg.current_ma / 1000)
            _log(f"host: current limit {msg.current_ma} mA")
            return S.OK
        if isinstance(msg, M.Home):
            if not 0 < msg.clearance_um <= MAX_CLEARANCE_UM:
                return S.BAD_MESSAGE  # 0 once killed the emulator
            if sim.scene is None:
                return S.BAD_STATE
            sim.home(msg.clearance_um * 1e-6)
            return S.OK
        if isinstance(msg, M.StartWindow):
            if not (0 < msg.duration_ms <= MAX_WINDOW_MS and 0 < msg.timeout_ms <= MAX_WINDOW_MS
                    and msg.from_contact in (0, 1)):
                return S.BAD_MESSAGE  # 0 killed the emulator; 2³²−1 kept it busy forever
            if sim.scene is None or not sim.enabled:
                return S.BAD_STATE
            self._start(self._run_window, msg)
            return S.OK
        if isinstance(msg, M.PlayChunk):
            end = msg.offset + msg.n
            if end > 10_000_000:
                return S.BAD_MESSAGE
            if end > self._play.size:
                self._play = np.concatenate([self._play, np.zeros(end - self._play.size)])
            self._play[msg.offset:end] = np.array(msg.items, float) * 1e-3
            return S.OK
        if isinstance(msg, M.PlayStart):
            if msg.n_samples == 0 or msg.n_samples > self._play.size:
                return S.BAD_MESSAGE
            self._start(self._run_play, msg)
            return S.OK
        return S.BAD_MESSAGE  # a device → host message sent to the device

    def _build_scene(self, sc: dict) -> Scene:
        b: M.SceneBegin = sc["begin"]
        h = b.surface_um * 1e-6
        name = f"scene-{b.scene_id}"
        if b.kind == SceneKind.REAL:
            ring = (Ringing(b.ring_slope, b.ring_decay, b.ring_freq) if b.ring_freq > 0 else None)
            sup = sc.get("support")
            return Scene(name, surface_height=h, material=Material(
                b.stiffness, b.damping, ring, mass=b.block_mass if b.block_mass > 0 else None,
                support=Support(sup.stiffness, sup.damping) if sup is not None else None))
        if b.kind == SceneKind.SPRING:
            return Scene(name, surface_height=h, spring=b.spring)
        forces = sc["table"].reshape(b.rows, b.row_len).astype(float) * 1e-3
        table = TransientTable(sc["v"], forces, Blend(b.blend), b.attenuation)
        return Scene(name, surface_height=h, spring=b.spring, transient=TableTransient(table))

    def _start(self, target, msg) -> None:
        def run() -> None:
            try:
                target(msg)
            except Exception as exc:  # an emulator bug: stop, as a device that resets would
                print(f"emulator: {type(exc).__name__} in {target.__name__}: {exc}; stopping",
                      file=sys.stderr, flush=True)
                self.stop()

        self._worker = threading.Thread(target=run, daemon=True)
        self._worker.start()

    def _finish(self, window_id: int, res, t0_us: int) -> None:
        rate = self.sim.info.servo_rate_hz
        t0 = res.traces["t"][0] if len(res.traces["t"]) else 0.0
        for s in res.saturations:
            self.send(M.Saturation(window_id, int(round((s.t - t0) * rate)),
                                   int(round(s.duration * rate)),
                                   int(round(s.peak_current * 1000))))
        if res.faults:
            self._report_fault()
        first = -1 if res.t_first_contact is None else int(round((res.t_first_contact - t0)
                                                                  * rate))
        self._traces = {window_id: res.traces}
        self.send(M.WindowDone(window_id, t0_us, len(res.traces["t"]), first, len(res.contacts),
                               len(res.saturations), int(res.timed_out), int(bool(res.faults))))

    def _run_window(self, msg: M.StartWindow) -> None:
        sent = 0
        t0_us = self._device_time_us()
        rate = self.sim.info.servo_rate_hz
        tick0 = self.sim.time

        last_pos = [0.0]

        def progress(_t, partial) -> None:
            nonlocal sent
            now = time.monotonic()
            if partial.live_height is not None and now - last_pos[0] >= 0.025:
                last_pos[0] = now  # the cursor's stream, ~40 Hz
                tick = int(round((self.sim.time - tick0) * rate))
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
        t0_us = self._device_time_us()
        res = self.sim.play_force(self._play[: msg.n_samples], heartbeats=False)
        self._play = np.zeros(0)
        self._finish(msg.window_id, res, t0_us)

    def _send_trace(self, req: M.TraceRequest) -> None:
        arr = np.asarray(self._traces[req.window_id][M.Channel.NAMES[req.channel]], dtype=float)
        end = req.start + req.count
        for a in range(req.start, end, M.TRACE_ITEMS):
            b = min(end, a + M.TRACE_ITEMS)
            self._outbox.append(M.TraceBlock(req.window_id, req.channel, a, b - a,
                                             tuple(np.float32(arr[a:b]).tolist())))


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

    warm_up(rate_hz)
    master, slave, path = open_pty()
    sim = SimDevice(rate_hz=rate_hz, seed=seed, live=True, speed=speed)
    emu = Emulator(sim, master)
    stop = lambda *_: emu.stop()  # noqa: E731
    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    print(path, flush=True)
    print(f"emulating a {rate_hz:g}-Hz device (sim plant, seed {seed}, speed ×{speed:g}); "
          "stop with Ctrl-C", file=sys.stderr, flush=True)
    try:
        emu.serve_forever()
    finally:
        os.close(master)
        os.close(slave)
    return 0

