"""The state × command table of docs/wire-protocol.md §4, read from the document and
checked pair by pair, over raw frames on the pty, against every device that speaks
version 2: the Python emulator and the reference firmware built for this machine (as is,
with the board's resources, and under ASan and UBSan).

For each state (IDLE, HOMED, WINDOW, PLAYING, FAULT) the device is brought there from a
reset, sent one valid command, and its ACK status (HELLO_ACK, PONG) and the state its next
STATUS reports are compared with the table's cell.
"""

from __future__ import annotations

import re
import time
from pathlib import Path

import pytest
import serial

from device.serial import contract as C
from device.serial import messages as M
from device.serial.contract import FAULTS
from device.serial.firmware import CONFORMANCE_TARGETS
from device.serial.framing import FrameDecoder

from ..conftest import start_emulator, stop_emulator

DOC = Path(__file__).resolve().parents[2] / "docs" / "wire-protocol.md"
STATES = ("IDLE", "HOMED", "WINDOW", "PLAYING", "FAULT")
ANSWERS = {name: getattr(M.Status, name) for name in ("OK", "BAD_MESSAGE", "BAD_STATE",
                                                       "FAULT_LATCHED", "BUSY")}
ANSWERS |= {"HELLO_ACK": "hello", "PONG": "pong"}
SPRING = M.SceneBegin(1, 1, 0, 680.0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1.0)
WATCHDOG = next(code for code, name in FAULTS.items() if name == "watchdog")
#: attempts at one cell when this host's own heartbeat came late (a watchdog fault is the
#: loaded host's timing, not the table's answer)
ATTEMPTS = 6
#: the longest this host waits for an answer or a STATUS [s]: no deadline the document
#: sets, only a bound for a dead device; generous, as the Python emulator beside two
#: CPU-bound processes once sent nothing for over 2 s (a loaded run of the suite)
ANSWER_S = 10.0

#: one valid instance of the command each row names (the first name of a row that names
#: several: the others share its column of statuses)
COMMANDS = {
    "HELLO": M.Hello(C.PROTOCOL),
    "HEARTBEAT, PING": M.Ping(7),
    "SCENE_BEGIN, _VELOCITIES, _CHUNK, _SUPPORT, _COMMIT": SPRING,
    "HOME": M.Home(20_000),
    "START_WINDOW": M.StartWindow(5, 60_000, 1_000, 0),
    "STOP_WINDOW": M.StopWindow(),
    "PLAY_CHUNK": M.PlayChunk(0, 3, (0, 0, 0)),
    "PLAY_START": M.PlayStart(6, 200_000),
    "SET_LIMIT, TRACE_CONFIG": M.SetLimit(1000),
    "ESTOP": M.EStop(),
    "CLEAR_FAULT": M.ClearFault(),
    "ZERO": M.Zero(),
    "LINK_QUERY": M.LinkQuery(0),
    "a device → host type, TRACE_REQUEST (v2)": M.TraceRequest(5, 0, 0, 10),
}


def table() -> dict[str, dict[str, tuple[object, str | None]]]:
    """{row: {state: (expected answer, state after or None for unchanged)}} from the doc."""
    text = DOC.read_text()
    body = text[text.index("| command | IDLE | HOMED | WINDOW | PLAYING | FAULT |"):]
    rows: dict[str, dict] = {}
    for line in body.splitlines()[2:]:
        if not line.startswith("|"):
            break
        name, *cells = [c.strip() for c in line.strip("|").split("|")]
        row, prev = {}, None
        for state, cell in zip(STATES, cells, strict=True):
            if cell == "same":
                row[state] = prev
                continue
            if cell.startswith("— / PONG"):
                row[state] = prev = ("pong", None)
                continue
            cell = re.sub(r"\(BAD_STATE without a committed scene\)", "", cell)
            answer = next(w for w in re.findall(r"[A-Z_]+", cell) if w in ANSWERS)
            after = re.search(r"→ (\w+)", cell)
            row[state] = prev = (ANSWERS[answer], after.group(1) if after else None)
        rows[name] = row
    return rows


class Host:
    """Raw frames over pyserial, written against the document."""

    def __init__(self, port: str):
        self.port = serial.Serial(port, timeout=0.01)
        self.dec = FrameDecoder()
        self.seq = 0
        self.pending: list[M.Message] = []  # decoded, not yet looked at
        self.backlog: list[M.Message] = []  # what came (but STATUS) while the last ask waited
        self.state: int | None = None  # the last STATUS
        self.status_count = 0
        self.sent = time.monotonic()  # when the host last wrote a frame
        self.quiet = 0.0  # [s] the longest this host wrote nothing, since the attempt began
        self.limits: M.Limits | None = None  # from the last HELLO
        self.rating_ma: int | None = None
        self.watchdog_ms: int | None = None  # from the last HELLO_ACK
        self.servo_hz: int | None = None
        self.link_report: M.LinkReport | None = None  # the last LINK_REPORT
        self.watchdog = False  # a watchdog fault was reported since it was last reset
        self.version = C.PROTOCOL  # the session's protocol version, from HELLO_ACK
        self.rx_bytes = 0  # bytes read from the device so far
        self.read_size = 4096  # bytes a read takes at most: less, with a pause after each
        self.read_pause = 0.0  # [s], is a host slower than the device's stream

    def _pump(self, pred, limit: float, keep: list | None = None):
        """The first message ``pred`` accepts; those passed over on the way go to ``keep``
        (STATUS aside), or are dropped."""
        end = time.monotonic() + limit
        while time.monotonic() < end:
            if time.monotonic() - self.sent > 0.025:  # a host heartbeats while it waits
                self.write(M.encode(M.Heartbeat(), 0, self.version))
            if not self.pending:
                # what has come, or the first byte to come within the port's timeout (as
                # device/serial/link.py reads): read(n) alone waits for all n bytes or 10 ms
                data = self.port.read(min(self.read_size, max(1, self.port.in_waiting)))
                self.rx_bytes += len(data)
                if self.read_pause:
                    time.sleep(self.read_pause)
                self.pending = [M.decode(f) for f in self.dec.feed(data)]
            while self.pending:  # frames read with the one awaited wait for the next ask
                m = self.pending.pop(0)
                if isinstance(m, M.StatusReport):
                    self.state, self.status_count = m.state, self.status_count + 1
                    self.watchdog |= m.fault == WATCHDOG
                # the FAULT frame and the run's WINDOW_DONE come before the next STATUS:
                # a test that fails on them has met the watchdog too
                self.watchdog |= (isinstance(m, M.Fault) and m.code == WATCHDOG
                                  or isinstance(m, M.WindowDone) and m.fault == WATCHDOG)
                if pred(m):
                    return m
                if keep is not None and not isinstance(m, M.StatusReport):
                    keep.append(m)
        raise AssertionError("the device did not answer")

    def write(self, data: bytes) -> None:
        now = time.monotonic()
        self.quiet = max(self.quiet, now - self.sent)
        self.port.write(data)
        self.sent = now

    def ask(self, msg: M.Message):
        self.seq = (self.seq + 1) & 0xFFFF
        hello = isinstance(msg, M.Hello)
        if hello:
            # repeated, as a host does for 3 s: a device may start listening only after
            # its port opens (QEMU boots the board), and first ends a run a previous host
            # left (the emulator: up to 2 s)
            for _ in range(10):
                self.write(M.encode(msg, self.seq, 1))
                try:
                    ack = self._pump(lambda m: isinstance(m, M.HelloAck), 0.5)
                    break
                except AssertionError:
                    continue
            else:
                raise AssertionError("no HELLO_ACK in 5 s")
            self.rating_ma, self.watchdog_ms = ack.current_limit_ma, ack.watchdog_ms
            self.version = ack.protocol
            self.servo_hz = ack.servo_rate_hz
            self.limits = self._pump(lambda m: isinstance(m, M.Limits), ANSWER_S)
            return "hello"
        self.write(M.encode(msg, self.seq, self.version))
        if isinstance(msg, M.Ping):
            self._pump(lambda m: isinstance(m, M.Pong), ANSWER_S)
            return "pong"
        seq = self.seq
        # a device may send what the command set off (a FAULT after ESTOP) before its ACK:
        # kept for the next collect
        self.backlog = []
        status = self._pump(lambda m: isinstance(m, M.Ack) and m.ack_seq == seq, ANSWER_S,
                            self.backlog).status
        if isinstance(msg, M.LinkQuery) and status == M.Status.OK:  # the report follows
            report = self._pump(lambda m: isinstance(m, M.LinkReport), ANSWER_S)
            assert report.frames >= 1 and len(report.items) == M.LINK_GAP_BINS
            self.link_report = report
        return status

    def clear(self) -> object:
        """CLEAR_FAULT, asked again after the next STATUS while the device answers
        FAULT_LATCHED for a fault it has not reported since it latched or since the last
        ESTOP (docs §4), as a host that clears what it was told does; the last status."""
        for _ in range(3):
            status = self.ask(M.ClearFault())
            if status != M.Status.FAULT_LATCHED:
                return status
            n = self.status_count
            self._pump(lambda m, n=n: isinstance(m, M.StatusReport) and self.status_count > n,
                       ANSWER_S)
        return status

    def settled_state(self) -> str:
        """The state a STATUS sent after now reports (two reports on: one may be in flight)."""
        n = self.status_count
        self._pump(lambda m: isinstance(m, M.StatusReport) and self.status_count >= n + 2,
                   ANSWER_S)
        return STATES[self.state]

    def reset(self) -> None:
        """To IDLE with a committed spring, whatever ran before (a fault the device has not
        reported yet is not cleared: asked again once a STATUS has said it, docs §4)."""
        end = time.monotonic() + 5
        while True:
            self.clear()
            self.ask(M.Zero())
            if self.settled_state() == "IDLE" or time.monotonic() > end:
                break
        self.watchdog = False  # what was latched before the reset is cleared
        # a stream the narrowest link carries (position, every 10th tick): at the default
        # (every channel, every tick) a board's line is full, and the reports a stalled
        # host's watchdog set off reach it only after the next attempt has begun
        assert self.ask(M.TraceConfig(1, 10)) == M.Status.OK
        assert self.ask(SPRING) == M.Status.OK
        assert self.ask(M.SceneCommit(1, 0)) == M.Status.OK

    def enter(self, state: str) -> None:
        self.reset()
        if state in ("HOMED", "WINDOW"):
            assert self.ask(M.Home(20_000)) == M.Status.OK
        if state == "WINDOW":
            assert self.ask(M.StartWindow(4, 60_000, 1_000, 0)) == M.Status.OK
        if state == "PLAYING":
            assert self.ask(M.PlayChunk(0, 3, (0, 0, 0))) == M.Status.OK
            # 20 s, or all a board's buffer holds (3.8 s): long enough to be met playing
            assert self.ask(M.PlayStart(3, min(200_000, self.limits.play_items))) == M.Status.OK
        if state == "FAULT":
            assert self.ask(M.EStop()) == M.Status.OK
        assert self.settled_state() == state

    def attempts(self, body, restart=None):
        """``body()`` and what it returns, done again (after ``restart()``) when this host
        fell silent: a STATUS reported a watchdog fault and the device's LINK_REPORT says
        no frame of this host reached it for its watchdog period (the pytest process, or the
        device's reader, stalled on a busy machine), so the device ended what it did on a
        deadline it did not get to see kept, and the attempt says nothing about it. A
        watchdog fault while this host's frames came in time fails; so does whatever fails
        without one."""
        for attempt in range(1, ATTEMPTS + 1):
            if attempt > 1 and restart is not None:
                restart()
            self.watchdog = False
            assert self.ask(M.LinkQuery(1)) == M.Status.OK  # the gaps from now on
            self.quiet = 0.0
            try:
                got = body()
            except AssertionError:
                if self._silent() and attempt < ATTEMPTS:
                    continue
                raise
            if not self.watchdog:
                return got
            if not self._silent():
                raise AssertionError("the device latched its watchdog although this host's "
                                     "frames came within its period (longest gap "
                                     f"{self.link_report.max_gap_us / 1e3:.1f} ms as the "
                                     "device saw them, "
                                     f"{self.quiet * 1e3:.1f} ms as this host wrote them, "
                                     f"of its {self.watchdog_ms} ms)")
        raise AssertionError(f"this host fell silent past the device's watchdog on all "
                             f"{ATTEMPTS} attempts (its heartbeats came late every time)")

    def _silent(self) -> bool:
        """A watchdog fault came, and no frame of this host reached the device for its
        period: by the device's LINK_REPORT, or by this host's own record of its writes,
        since a HELLO starts the device's count afresh (docs §6) and so erases a silence
        that came before it (the state table's HELLO row, sent after a host stall)."""
        if not self.watchdog:
            return False
        self.ask(M.LinkQuery(0))
        gap_ms = max(self.link_report.max_gap_us / 1e3, self.quiet * 1e3)
        return gap_ms >= self.watchdog_ms - 1

    def observe(self, state: str, cmd: M.Message) -> tuple[object, str]:
        """``cmd`` sent in ``state``: its answer and the state after. The table never calls
        for a watchdog fault, so a cell where one came is observed again."""

        def once():
            self.enter(state)
            got = self.ask(cmd)
            return got, self.settled_state()

        return self.attempts(once)

    def close(self) -> None:
        self.ask(M.Zero())
        self.port.close()


def test_the_document_table_is_read_whole():
    rows = table()
    assert set(rows) == set(COMMANDS)
    assert rows["PLAY_START"]["IDLE"] == (M.Status.OK, "PLAYING")
    assert rows["HELLO"]["FAULT"] == ("hello", None)
    assert rows["ZERO"]["PLAYING"] == (M.Status.OK, "IDLE")


@pytest.mark.realtime
@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.slow
@pytest.mark.parametrize("firmware", CONFORMANCE_TARGETS)
def test_every_state_answers_every_command_as_the_document_says(firmware):
    emu = start_emulator("--firmware", firmware, "--seed", "2")
    host = Host(emu.port)
    wrong = []
    try:
        assert host.ask(M.Hello(C.PROTOCOL)) == "hello"
        for row, cells in table().items():
            for state, (answer, after) in cells.items():
                cmd = COMMANDS[row]
                if isinstance(cmd, M.PlayStart):  # within this device's buffer
                    cmd = M.PlayStart(cmd.window_id, min(cmd.n_samples, host.limits.play_items))
                got, now = host.observe(state, cmd)
                expect_after = {"previous": "IDLE"}.get(after, after) or state
                if (got, now) != (answer, expect_after):
                    wrong.append(f"{row} in {state}: {got}, then {now}; the document says "
                                 f"{answer}, then {expect_after}")
    finally:
        host.close()
        stop_emulator(emu)
        print(f"the device's stderr:\n{emu.stderr()}")  # shown when the test failed
    assert not wrong, "\n".join(wrong)


@pytest.mark.realtime
@pytest.mark.integration
@pytest.mark.firmware
def test_a_host_silent_before_hello_is_not_taken_for_the_devices_fault():
    """A HELLO starts the device's LINK_REPORT afresh, so a host that stalled past the
    watchdog just before one (as the state table's HELLO row does on a loaded machine) left
    no gap in the report: the attempt is told apart by the host's own record of its writes
    and observed again, where it once failed as a device that latched its watchdog with
    this host's frames 30 ms apart."""
    emu = start_emulator("--firmware", "host", "--seed", "2")
    host = Host(emu.port)
    stalls = [0.3]  # [s], three watchdog periods without a frame, on the first attempt

    def once():
        host.enter("HOMED")
        if stalls:
            time.sleep(stalls.pop())
        return host.ask(M.Hello(C.PROTOCOL)), host.settled_state()

    try:
        assert host.ask(M.Hello(C.PROTOCOL)) == "hello"
        assert host.attempts(once) == ("hello", "IDLE")
        assert not stalls
    finally:
        host.close()
        stop_emulator(emu)
