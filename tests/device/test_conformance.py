"""One behaviour on every device target (issue 28's findings), checked over raw frames on
the pty against the Python emulator and the reference firmware built for this machine (as
is, with the board's resources, and under ASan and UBSan): the same test, the same verdict.

Each test names the finding it covers. The state × command table is
``test_state_table.py``; every field at and beyond its range ends is ``test_contract.py``;
the firmware's own unit tests (``firmware/tests/device_test.c``) cover the servo's
arithmetic at the encoder's extremes, which no pty can reach.
"""

from __future__ import annotations

import functools
import shutil
import time
import zlib

import numpy as np
import pytest

from device.serial import contract as C
from device.serial import messages as M
from device.serial.firmware import CONFORMANCE_TARGETS
from device.serial.framing import encode_frame

from ..conftest import start_emulator, stop_emulator
from .test_state_table import ANSWER_S, Host

pytestmark = [pytest.mark.integration, pytest.mark.firmware, pytest.mark.realtime]

TARGETS = CONFORMANCE_TARGETS  # every target, as device/serial/firmware.py lists them
#: the same with the Cortex-M build under QEMU (it boots for seconds: the qemu tier), for
#: the cases issue 53 added where the board's own loop and UART make the difference
WITH_QEMU = [*TARGETS, pytest.param("qemu", marks=[
    pytest.mark.qemu, pytest.mark.slow,
    pytest.mark.skipif(shutil.which("qemu-system-arm") is None,
                       reason="qemu-system-arm missing: `make test` installs it")])]
SPRING = M.SceneBegin(1, 1, 0, 680.0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1.0)
S = M.Status


@pytest.fixture(params=TARGETS)
def host(request):
    emu = start_emulator("--firmware", request.param, "--seed", "4")
    h = Host(emu.port)
    h.target = request.param
    h.emu = emu
    assert h.ask(M.Hello(C.PROTOCOL)) == "hello"
    yield h
    h.close()
    stop_emulator(emu)
    print(f"the device's stderr:\n{emu.stderr()}")  # shown when the test failed
    bad = [line for line in emu.stderr_lines if "runtime error" in line or "Sanitizer" in line]
    assert not bad, "".join(bad)


def deadline_kept(test):
    """Run ``test`` again, from a fresh HELLO, when this host's heartbeat came too late
    (``Host.attempts``): on a busy machine the pytest process can stall past the device's
    watchdog, which then ends a window or playback the test was about to stop itself."""

    @functools.wraps(test)
    def run(host):
        def restart():
            host.clear()
            assert host.ask(M.Hello(C.PROTOCOL)) == "hello"

        host.attempts(lambda: test(host), restart)

    return run


def wait(host: Host, seconds: float) -> None:
    """Let ``seconds`` of **device** time pass (read from STATUS, so a device held up by a
    busy computer, whose clock slips, is waited for), the host heartbeating meanwhile."""
    first = host._pump(lambda m: isinstance(m, M.StatusReport), 5.0).time_us
    host._pump(lambda m: isinstance(m, M.StatusReport) and m.time_us - first >= seconds * 1e6,
               20.0 + seconds)


def collect(host: Host, until, limit: float = 10.0) -> list[M.Message]:
    """Every message up to and including the first for which ``until`` is true, beginning
    with those that came while the last command awaited its ACK."""
    seen: list[M.Message] = []
    while host.backlog:
        seen.append(host.backlog.pop(0))
        if until(seen[-1]):
            return seen

    def pred(m):
        seen.append(m)
        return until(m)

    host._pump(pred, limit)
    return seen


def raw(host: Host, mtype: int, body: bytes) -> int:
    """Send a raw version-2 frame; its ACK's status."""
    host.seq = (host.seq + 1) & 0xFFFF
    seq = host.seq
    host.write(encode_frame(mtype, seq, body, host.version))
    return host._pump(lambda m: isinstance(m, M.Ack) and m.ack_seq == seq, 5.0).status


def spring_homed(host: Host) -> None:
    assert host.ask(SPRING) == S.OK
    assert host.ask(M.SceneCommit(1, 0)) == S.OK
    assert host.ask(M.Home(20_000)) == S.OK


@pytest.mark.integration
@pytest.mark.firmware
def test_limits_say_the_contact_is_simulated_and_seeded(host):
    """Issue 54, item 1: what a device is comes over the wire (LIMITS.capabilities), not
    from its name. Every target here is a simulated plant started from a seed."""
    assert host.limits.can("simulated_contact") and host.limits.can("seeded")
    assert host.limits.capabilities >> len(C.CAPABILITIES) == 0  # no bit it has no name for


@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.parametrize("host", WITH_QEMU, indirect=True)
@deadline_kept
def test_the_longest_window_it_states_runs_and_a_longer_one_is_refused_first(host):
    """Issue 53 item 2: START_WINDOW 600,000 ms from contact with a 600,000-ms wait (each in
    its range) was answered OK by the emulator, which then stopped serving. Every target
    states its longest window in LIMITS.max_window_ms and runs it; one beyond is
    BAD_MESSAGE before anything acts (the state stays HOMED, the device keeps serving)."""
    longest = host.limits.max_window_ms
    assert 0 < longest <= C.MAX_WINDOW_MS
    spring_homed(host)
    if longest < C.MAX_WINDOW_MS:
        assert host.ask(M.StartWindow(1, C.MAX_DURATION_MS, C.MAX_DURATION_MS, 1)) \
            == S.BAD_MESSAGE
        assert host.settled_state() == "HOMED"
    duration = min(longest, C.MAX_DURATION_MS)
    assert host.ask(M.StartWindow(2, duration, max(1, longest - duration), 1)) == S.OK
    wait(host, 0.3)  # STATUS comes in the window as before it
    assert host.settled_state() == "WINDOW"
    assert host.ask(M.StopWindow()) == S.OK
    done = collect(host, lambda m: isinstance(m, M.WindowDone), 20.0)[-1]
    assert done.window_id == 2 and done.fault == 0


@pytest.mark.slow  # a simulator and its scene, compiled: seconds on a busy machine
def test_a_window_computes_the_hand_as_it_goes_not_all_at_its_start():
    """Issue 53 item 2, the cause of the emulator's silence at a long window's start (1.1 s
    at 600 s, with nothing on the wire for its 20-Hz STATUS): the simulated hand's pull for
    the whole window was computed before its first tick, holding the interpreter the serve
    loop needs. Now the room is taken at once (zeros) and the pull a second at a time."""
    from dataclasses import replace

    from device.scene import Scene
    from device.sim._window import PULL_AHEAD, Buffers
    from device.sim.backend import SimDevice

    sim = SimDevice(seed=4)
    sim.load_scene(Scene("s", spring=680.0))
    sim.home(0.02)
    plan = replace(sim.tapper, top=0.02).plan(sim.rng_tapping, 5.0, 0.0)
    n = int(sim.max_window_s / sim.params.dt)  # the longest window it runs
    buf = Buffers(n, plan, sim._pull_gains, sim.params.dt)
    assert buf.n == n and buf.pulled == 0
    buf.ensure(25)  # the first chunk of ticks
    assert buf.pulled <= PULL_AHEAD + 1
    whole = Buffers(3 * PULL_AHEAD, plan, sim._pull_gains, sim.params.dt)
    for end in range(25, 3 * PULL_AHEAD, 25):
        buf.ensure(end)
    whole.ensure(3 * PULL_AHEAD - 1)
    k = 3 * PULL_AHEAD - 25
    assert np.array_equal(buf.u_hand[:k], whole.u_hand[:k])  # the same pull, piece by piece


@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.parametrize("host", [t for t in TARGETS if t != "python"], indirect=True)
def test_the_longest_tick_period_reads_a_hold_up_as_long_as_it_was(host):
    """Issue 53 item 3: after a 300-ms hold-up the host builds' LIMITS.tick_max_us read
    19,999 (the top of a histogram), though the stall the field exists to show was 15
    times that. Every build whose servo follows this computer's clock (the Python
    emulator measures none: 0) now reports at least the 300 ms it was stopped for."""
    import os
    import signal

    wait(host, 0.05)
    os.kill(host.emu.proc.pid, signal.SIGSTOP)
    time.sleep(0.3)
    os.kill(host.emu.proc.pid, signal.SIGCONT)
    wait(host, 0.05)  # ticks ran since: the one after the stop measured it
    assert host.ask(M.Hello(C.PROTOCOL)) == "hello"
    assert host.limits.tick_max_us >= 300_000, host.limits
    assert host.limits.tick_p99_us < host.limits.tick_max_us


# ---- issue 53 item 4: one answer where the document was silent (docs §3, §4, §6a)
def _estop_and_clear_together(host: Host) -> tuple[int, int, bool]:
    """ESTOP and CLEAR_FAULT in one write: their ACKs' statuses, and whether the device
    reported the fault (a FAULT frame, or a STATUS in FAULT) between the two ACKs."""
    host.seq += 2
    estop, clear = host.seq - 1, host.seq
    host.write(M.encode(M.EStop(), estop, host.version)
               + M.encode(M.ClearFault(), clear, host.version))
    acks: dict[int, int] = {}
    reported = []

    def both(m) -> bool:
        if isinstance(m, M.Ack):
            acks[m.ack_seq] = m.status
        elif estop in acks and clear not in acks and (
                isinstance(m, M.Fault) or isinstance(m, M.StatusReport) and m.fault):
            reported.append(m)
        return clear in acks and estop in acks

    host._pump(both, 5.0)
    return acks[estop], acks[clear], bool(reported)


def _sent_together(host: Host, prepare) -> tuple[int, int]:
    """The two ACKs of an ESTOP and a CLEAR_FAULT the device took as sent together.

    A CLEAR_FAULT that arrives after the device reported the fault may clear it (docs §4).
    Written in one write, the two frames reach every target at once except QEMU's board,
    whose emulated UART takes a byte only after the firmware read the one before: on a busy
    computer QEMU's I/O thread may deliver the CLEAR_FAULT after the report went. That
    attempt says nothing about the rule; it is made again (after ``prepare()``)."""
    for _ in range(5):
        prepare()
        e, c, reported = _estop_and_clear_together(host)
        if not reported:
            return e, c  # nothing reported between them: the device cannot have cleared
        if c == S.FAULT_LATCHED:
            return e, c  # reported between, and still judged sent with the ESTOP
        assert host.target == "qemu", (
            f"{host.target} cleared a fault it reported after the ESTOP and before the "
            "CLEAR_FAULT written with it: its link delivers one write at once")
    pytest.skip("QEMU delivered the CLEAR_FAULT after the device's report on 5 attempts "
                "(a busy computer): these attempts say nothing about the rule")


@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.parametrize("host", WITH_QEMU, indirect=True)
@deadline_kept
def test_an_estop_is_never_undone_by_a_clear_fault_sent_with_it(host):
    """The emulator ended IDLE with no fault, the firmware in FAULT. A CLEAR_FAULT that
    reaches the device before it has reported the fault (FAULT or STATUS) clears nothing:
    FAULT_LATCHED; one sent after the report clears it."""

    def homed():
        state = host.settled_state()
        if state != "HOMED":
            if state != "IDLE":
                host.reset()
            spring_homed(host)

    def fault_told():  # a fault latched and reported
        if host.settled_state() != "FAULT":
            assert host.ask(M.EStop()) == S.OK
            assert host.settled_state() == "FAULT"

    for state, prepare in (("HOMED", homed), ("FAULT", fault_told)):
        assert _sent_together(host, prepare) == (S.OK, S.FAULT_LATCHED), state
        assert host.settled_state() == "FAULT"
    assert host.ask(M.ClearFault()) == S.OK  # the fault told: now it clears
    assert host.settled_state() == "IDLE"


@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.parametrize("host", WITH_QEMU, indirect=True)
@deadline_kept
def test_a_scene_begun_before_another_scenes_begin_is_unknown(host):
    """The emulator answered OK, the firmware UNKNOWN_SCENE. One upload at a time: a
    SCENE_BEGIN withdraws every scene begun before it."""
    assert host.ask(M.SceneBegin(3, 2, 0, 680.0, 0, 0, 0, 0, 0, 0, 1, 4, 0, 1.0)) == S.OK
    assert host.ask(SPRING) == S.OK  # scene 1
    assert host.ask(M.SceneVelocities(3, (0.1,))) == S.UNKNOWN_SCENE
    assert host.ask(M.SceneChunk(3, 0, 4, (1, 2, 3, 4))) == S.UNKNOWN_SCENE
    assert host.ask(M.SceneCommit(3, 0)) == S.UNKNOWN_SCENE
    assert host.ask(M.SceneCommit(1, 0)) == S.OK
    assert host.ask(M.Home(20_000)) == S.OK


@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.parametrize("host", WITH_QEMU, indirect=True)
@deadline_kept
def test_an_estop_in_a_frame_of_a_version_nobody_speaks_stops(host):
    """§1a discarded a frame of an unknown version whatever it carried, §3 acted on an
    ESTOP whatever its frame version. An intact ESTOP frame stops in any version."""
    spring_homed(host)
    host.seq += 1
    host.write(encode_frame(M.EStop.TYPE, host.seq, b"", 9))
    seq = host.seq
    assert host._pump(lambda m: isinstance(m, M.Ack) and m.ack_seq == seq, 5.0).status == S.OK
    assert host.settled_state() == "FAULT"
    assert host.ask(M.ClearFault()) == S.OK


@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.parametrize("host", WITH_QEMU, indirect=True)
@deadline_kept
def test_a_device_streams_no_faster_than_the_link_it_states(host):
    """host-board stated 100,000 B/s and streamed 287 kB/s over the pty, so a board's ring
    overflow and TRACE_LOST were never exercised. A device sends no more than
    LIMITS.link_bytes_s on average (0: no limit): asked for more, its ring overflows and
    the records it could not keep come as TRACE_LOST, every record covered once."""
    channels = host.limits.channels & 0x7F
    assert host.ask(M.TraceConfig(channels, 1)) == S.OK
    spring_homed(host)
    assert host.ask(M.StartWindow(4, 1000, 1000, 0)) == S.OK
    marks = []  # (device time [µs], bytes read by then) at each STATUS

    def until(m):
        if isinstance(m, M.StatusReport):
            marks.append((m.time_us, host.rx_bytes))
        return isinstance(m, M.WindowDone)

    msgs = collect(host, until, 30.0)
    done = msgs[-1]
    chunks = [m for m in msgs if isinstance(m, M.TraceChunk) and m.window_id == 4]
    lost = [m for m in msgs if isinstance(m, M.TraceLost) and m.window_id == 4]
    covered = sorted([(c.start, c.n) for c in chunks] + [(t.start, t.n) for t in lost])
    assert sum(n for _, n in covered) == done.n_ticks  # every record, once
    assert all(a + n == b for (a, n), (b, _) in zip(covered, covered[1:], strict=False))
    rate = host.limits.link_bytes_s
    if rate:
        assert lost, "a stream beyond the link's rate overflowed no ring"
        (t0, b0), (t1, b1) = marks[1], marks[-1]
        # what the line carried in that device time, plus a transmit buffer and a frame
        assert b1 - b0 <= rate * (t1 - t0) * 1e-6 + 8192 + 2048, (b1 - b0, t1 - t0)


#: the targets whose transmit buffer a slow host fills within a second (the board's 8-KiB
#: line: host-board, host-san, QEMU); the others buffer far more than a 1-s window sends
SMALL_LINE = [t for t in WITH_QEMU if getattr(t, "values", (t,))[0] in ("host-board",
                                                                       "host-san", "qemu")]


@pytest.mark.parametrize("host", SMALL_LINE, indirect=True)
@deadline_kept
def test_status_keeps_its_rate_while_traces_stream_to_a_slow_reader(host):
    """docs §3: STATUS at 20 Hz or more, traces streaming or not. A STATUS that found no
    room used to be skipped, and the chunks sent first took the room that freed: with a
    host reading 51 kB/s, host-board's came 38 in a 1-s window, gaps of 50 ms. A due STATUS
    now goes before the next chunk and waits for room (40, at most 27.7 ms apart, measured
    once). Asserted: the documented rate, half the firmware's 40 Hz, which leaves room for
    a host that a busy computer holds up (the old firmware met it as well: this guards the
    promise; the measurement is the fix's evidence)."""
    assert host.ask(M.TraceConfig(host.limits.channels & 0x7F, 1)) == S.OK
    spring_homed(host)
    times: list[int] = []  # STATUS device times [µs] during the run

    def until(m):
        if isinstance(m, M.StatusReport) and m.state == M.State.WINDOW:
            times.append(m.time_us)
        return isinstance(m, M.WindowDone) and m.window_id == 5

    host.read_size, host.read_pause = 512, 0.010
    try:
        assert host.ask(M.StartWindow(5, 1000, 1000, 0)) == S.OK
        collect(host, until, 60.0)
    finally:  # a retry (deadline_kept) reads at full speed
        host.read_size, host.read_pause = 4096, 0.0
    assert len(times) >= 20, (len(times), np.diff(times) * 1e-3)


@deadline_kept
def test_estop_is_acted_on_whatever_its_body(host):
    """Finding 8: an ESTOP frame with a stray byte once left the output on."""
    spring_homed(host)
    assert raw(host, M.EStop.TYPE, b"\x55") == S.OK
    assert host.settled_state() == "FAULT"
    assert host.ask(M.ClearFault()) == S.OK


@deadline_kept
def test_a_ping_or_heartbeat_that_does_not_fit_is_bad_message(host):
    """Finding 5: a PING whose body does not fit got no answer."""
    assert raw(host, M.Ping.TYPE, b"\x01\x02\x03") == S.BAD_MESSAGE
    assert raw(host, M.Heartbeat.TYPE, b"\x01") == S.BAD_MESSAGE


@deadline_kept
def test_fields_come_before_the_state(host):
    """Findings 3 and 7: in a window a command out of range is BAD_MESSAGE (not BUSY), and
    a refused SCENE_BEGIN leaves HOMED as it was."""
    spring_homed(host)
    assert host.ask(M.SceneBegin(2, 1, 0, 680.0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 2.0)) \
        == S.BAD_MESSAGE
    assert host.settled_state() == "HOMED"
    assert host.ask(M.StartWindow(1, 60_000, 60_000, 0)) == S.OK
    assert host.ask(M.SetLimit(0)) == S.BAD_MESSAGE
    assert host.ask(M.SetLimit(500)) == S.BUSY
    assert host.ask(M.SceneBegin(2, 1, 0, float("nan"), 0, 0, 0, 0, 0, 0, 0, 0, 0, 1.0)) \
        == S.BAD_MESSAGE
    assert host.settled_state() == "WINDOW"
    assert host.ask(M.StopWindow()) == S.OK


@deadline_kept
def test_an_upload_withdraws_the_scene_until_its_commit(host):
    """Finding 5: the state table's HOMED cells for the upload messages, one behaviour."""
    spring_homed(host)
    assert host.ask(M.SceneChunk(1, 0, 0, ())) == S.OK
    assert host.settled_state() == "IDLE"
    assert host.ask(M.Home(20_000)) == S.BAD_STATE
    assert host.ask(M.SceneCommit(1, 0)) == S.OK
    assert host.ask(M.Home(20_000)) == S.OK


def _play(host: Host, window_id: int, n: int, until=None) -> list[M.Message]:
    assert host.ask(M.PlayStart(window_id, n)) == S.OK
    return collect(host, until or (lambda m: isinstance(m, M.WindowDone)), 30.0)


def _force_cmd(msgs) -> np.ndarray:
    chunks = [m for m in msgs if isinstance(m, M.TraceChunk)]
    return np.concatenate([np.asarray(c.items, float) for c in chunks])


@deadline_kept
def test_a_second_playback_plays_the_buffer_again_and_output_is_off_after(host):
    """Findings 4 and 7: a second PLAY_START without a new upload played zeros on the
    emulator (the firmware played the buffer again); STATUS reported the last playback's
    force while IDLE."""
    assert host.ask(M.TraceConfig(1 << 2, 1)) == S.OK  # force_cmd alone
    assert host.ask(M.PlayChunk(0, 480, (430,) * 480)) == S.OK
    assert host.ask(M.PlayChunk(480, 480, (430,) * 480)) == S.OK
    ramp = host.servo_hz // 20  # 50 ms of ticks: 500 at 10 kHz, 50 on a 1-kHz bridge
    n = min(1000, ramp + 460)
    first = _force_cmd(_play(host, 1, n))
    second = _force_cmd(_play(host, 2, n))
    assert first.size == second.size == n
    # output was off before each: ramped over the first 50 ms, then the buffer's 0.43 N
    for played in (first, second):
        assert np.allclose(played[:ramp], 0.43 * np.arange(1, ramp + 1) / ramp, atol=1e-6)
        assert np.allclose(played[ramp:960], 0.43, atol=1e-6)
    n = host.status_count
    out = host._pump(lambda m: isinstance(m, M.StatusReport) and host.status_count >= n + 2,
                     2.0)
    assert out.state == M.State.IDLE and out.output_mn == 0


def _fault_ends_playback(host: Host, stall: float = 0.0) -> None:
    assert host.ask(M.TraceConfig(1 << 2, 10)) == S.OK
    assert host.ask(M.PlayStart(3, host.limits.play_items)) == S.OK  # 3.8 s or more
    collect(host, lambda m: isinstance(m, M.TraceChunk), 5.0)
    time.sleep(stall)  # no heartbeat meanwhile, as when a busy machine stalls this process
    assert host.ask(M.EStop()) == S.OK
    msgs = collect(host, lambda m: isinstance(m, M.WindowDone), 10.0)
    done = msgs[-1]
    faults = [m for m in msgs if isinstance(m, M.Fault)]
    # one FAULT, the e-stop's (the whole list when not: what came, in order, says why)
    assert len(faults) == 1, [type(m).__name__ for m in msgs if not isinstance(m, M.TraceChunk)]
    (fault,) = faults
    assert fault.code == done.fault == M.FaultCode.ESTOP
    assert done.n_ticks < host.limits.play_items
    # in device time (a busy computer may delay the frames, not the device's clock): the
    # playback's last tick is the one that zeroed output, within a millisecond
    end_us = done.t0_us + done.n_ticks * 1e6 / host.servo_hz
    assert abs(end_us - fault.time_us) <= 1000, (end_us, fault.time_us)
    assert host.ask(M.ClearFault()) == S.OK


@pytest.mark.slow
@deadline_kept
def test_a_fault_ends_a_playback_at_once(host):
    """Finding 4: an e-stop during a playback was reported when the whole buffer had run."""
    _fault_ends_playback(host)


@pytest.mark.parametrize("host", ["host"], indirect=True)
def test_a_host_that_stalls_past_the_watchdog_is_given_another_attempt(host):
    """What a loaded run of the suite met (issue 29): the pytest process stalled past the
    device's 100-ms watchdog during a playback, and the watchdog ended it before the ESTOP
    came (the host then also dropped the WINDOW_DONE that came before the ESTOP's ACK, and
    failed with 'the device did not answer'). That attempt proves nothing about the device,
    so ``deadline_kept`` runs it again; anything else still fails at once."""
    with pytest.raises(AssertionError, match="FaultCode"):  # the watchdog's, not ESTOP's
        _fault_ends_playback(host, stall=0.5)
    assert host.watchdog
    host.clear()
    stalls = [0.5]
    tries = []

    def once():
        tries.append(1)
        _fault_ends_playback(host, stall=stalls.pop() if stalls else 0.0)

    host.attempts(once, host.clear)
    assert len(tries) >= 2  # (more when this machine stalled the process again)
    n = len(tries)

    def wrong():  # a failure with no watchdog fault is the device's answer: no second try
        tries.append(1)
        raise AssertionError("not this host's timing")

    with pytest.raises(AssertionError, match="not this host's timing"):
        host.attempts(wrong)
    assert len(tries) == n + 1


def estop_bound_us(host: Host) -> float:
    """The longest an ESTOP may take to zero output on ``host``'s target, from the frame's
    arrival [µs of device time], as LINK_REPORT counts it (from the last time the device
    found its input empty before the frame: an upper bound on the time since it arrived).

    Written from the document (docs §3), not from the code: the firmware zeroes output at
    the servo tick after an ESTOP's last byte, so one tick plus the frame's time on the
    link; on a pseudo-terminal a frame takes no time to arrive, but the input last seen
    empty may be one tick older than the frame: two ticks. The Python emulator computes
    its servo in blocks of 1 ms and runs on only while its port was found empty within
    the last 5 ms of its time: that wait and two blocks, 7 ms at ×1."""
    if host.target == "python":
        return 7000.0
    return 2 * 1e6 / host.servo_hz


@deadline_kept
def test_an_estop_zeroes_output_within_its_bound_while_traces_stream(host):
    """Issue 29: ESTOP → zero output within one servo tick plus one frame time (two ticks
    on a pseudo-terminal: ``estop_bound_us``), worst case, also while traces stream
    (every base channel at every tick, more than a board's link carries) and during a
    playback. Three e-stops in a window and three in a playback; the device's own worst
    figure since the attempt began (LINK_REPORT)."""
    for k in range(6):
        assert host.ask(M.TraceConfig(host.limits.channels & 0x7F, 1)) == S.OK
        if k % 2:
            assert host.ask(M.PlayStart(8, min(200_000, host.limits.play_items))) == S.OK
        else:
            spring_homed(host)
            assert host.ask(M.StartWindow(7, 60_000, 60_000, 0)) == S.OK
        collect(host, lambda m: isinstance(m, M.TraceChunk), 5.0)  # streaming now
        assert host.ask(M.EStop()) == S.OK
        msgs = collect(host, lambda m: isinstance(m, M.WindowDone), 10.0)
        assert msgs[-1].fault == M.FaultCode.ESTOP
        assert host.ask(M.ClearFault()) == S.OK
    assert host.ask(M.LinkQuery(0)) == S.OK
    worst = host.link_report.estop_max_us
    assert worst != 0xFFFFFFFF  # six were counted
    assert worst <= estop_bound_us(host), (worst, estop_bound_us(host))


@pytest.mark.slow
@deadline_kept
def test_a_from_contact_window_lasts_its_duration_and_position_is_its_tick(host):
    """Findings 5 and 6: a from-contact window lasted one tick too long on the firmware;
    every target reported a POSITION height that belonged to the tick before."""
    assert host.ask(M.TraceConfig(1, 1)) == S.OK  # position alone, every tick
    spring_homed(host)
    wait(host, 0.1)
    assert host.ask(M.StartWindow(5, 300, 30_000, 1)) == S.OK
    msgs = collect(host, lambda m: isinstance(m, M.WindowDone), 40.0)
    done = msgs[-1]
    assert done.first_contact >= 0
    assert done.n_ticks == done.first_contact + round(0.3 * host.servo_hz)
    pos = _force_cmd(msgs)  # channel 0 alone: the position [m]
    heights = [(m.tick, m.height_um) for m in msgs if isinstance(m, M.Position)]
    assert len(heights) >= 5
    for tick, h in heights:
        assert round(pos[tick] * 1e6) == h, (tick, h, pos[tick - 1: tick + 2] * 1e6)


@deadline_kept
def test_the_enable_ramp_runs_after_home_not_in_every_window(host):
    """Finding 7: the emulator ramped output up in the first 50 ms of every window."""
    assert host.ask(M.TraceConfig(1 << 6, 1)) == S.OK  # the flags
    spring_homed(host)
    wait(host, 0.2)  # the 50-ms ramp is over in device time
    assert host.ask(M.StartWindow(6, 200, 200, 0)) == S.OK
    flags = _force_cmd(collect(host, lambda m: isinstance(m, M.WindowDone), 10.0))
    assert flags.size == round(0.2 * host.servo_hz)
    assert not (flags.astype(int) & 16).any()  # bit 4: the enable ramp


@deadline_kept
def test_a_hello_ends_a_window_and_nothing_of_it_follows(host):
    """Finding 5: after a HELLO during a window, the old window's chunks and WINDOW_DONE
    followed HELLO_ACK."""
    spring_homed(host)
    assert host.ask(M.StartWindow(7, 60_000, 60_000, 0)) == S.OK
    collect(host, lambda m: isinstance(m, M.TraceChunk), 5.0)
    assert host.ask(M.Hello(C.PROTOCOL)) == "hello"  # consumed up to LIMITS; what follows is kept
    first = host._pump(lambda m: isinstance(m, M.StatusReport), 5.0)
    after = collect(host, lambda m: isinstance(m, M.StatusReport)
                    and m.time_us - first.time_us >= 500_000, 20.0)
    stale = [m for m in after if getattr(m, "window_id", None) == 7]
    assert not stale, stale[:3]
    assert host.settled_state() == "IDLE"


@deadline_kept
def test_a_half_frame_left_behind_does_not_swallow_the_next_hello(host):
    """Finding 8: after a mid-frame disconnect the next host's first HELLO was lost; a lone
    delimiter before it (as hapticlab's host sends) ends the half frame."""
    half = M.encode(SPRING, 9, 2)[:20]
    host.write(half)
    host.write(b"\x00")
    host.seq += 1
    host.write(M.encode(M.Hello(C.PROTOCOL), host.seq, 1))
    ack = host._pump(lambda m: isinstance(m, M.HelloAck), ANSWER_S)
    assert ack.protocol == C.PROTOCOL


@deadline_kept
def test_the_table_crc_is_the_documented_one(host):
    """A table scene over the wire, committed with zlib's CRC-32 of its i16 LE bytes."""
    items = tuple(range(-100, 100, 10))
    assert host.ask(M.SceneBegin(3, 2, 0, 680.0, 0, 0, 0, 0, 0, 0, 1, 20, 0, 1.0)) == S.OK
    assert host.ask(M.SceneVelocities(3, (0.1,))) == S.OK
    assert host.ask(M.SceneChunk(3, 0, 20, items)) == S.OK
    crc = zlib.crc32(np.asarray(items, "<i2").tobytes())
    assert host.ask(M.SceneCommit(3, crc ^ 1)) == S.TABLE_CRC
    assert host.ask(M.SceneCommit(3, crc)) == S.OK
