"""The operator console's keys, through a real pseudo-terminal."""

import io
import json
import os
import subprocess
import sys
import time

import pytest

from app.console import KeyConsole
from device import Scene, open_device

# the key reader is a thread: an exception in it (it once read a closed terminal after
# close()) fails these tests instead of becoming a warning on the next one
pytestmark = pytest.mark.filterwarnings("error::pytest.PytestUnhandledThreadExceptionWarning")


@pytest.fixture
def tty_stdin(monkeypatch):
    master, slave = os.openpty()
    f = os.fdopen(slave, "r", buffering=1)
    monkeypatch.setattr(sys, "stdin", f)
    yield master
    os.close(master)


def _until(pred, limit=5.0):
    end = time.monotonic() + limit
    while time.monotonic() < end and not pred():
        time.sleep(0.01)
    return pred()


@pytest.fixture
def dev():
    """The simulated device, homed on a spring: output on, so an e-stop has work to do."""
    d = open_device("sim")
    d.load_scene(Scene("firm", spring=680.0))
    d.home()
    return d


@pytest.mark.realtime
@pytest.mark.integration
def test_keys_act_only_in_their_state_and_estop_acts_at_once(tty_stdin, dev):
    """A key pressed where it means nothing is discarded with a line saying so; nothing
    pressed in one state acts in the next (an s during a trial never skips the next one)."""
    con = KeyConsole(dev, live=False)
    try:
        con.set_state("placing")
        os.write(tty_stdin, b"x")  # not an operator key: nothing
        os.write(tty_stdin, b"r")
        assert con.poll(2.0) == "go"
        con.set_state("trial")
        os.write(tty_stdin, b"s")  # a skip during a trial: discarded, said so
        assert _until(lambda: any("key 's' ignored" in m for m in con.view.messages))
        assert con.poll(0.3) is None
        con.set_state("placing")  # the next trial: the s did not carry over
        assert con.poll(0.3) is None
        os.write(tty_stdin, b"s")
        assert con.poll(2.0) == "skip"
        os.write(tty_stdin, b"p")
        assert con.poll(2.0) == "pause"
        con.set_state("paused")
        os.write(tty_stdin, b"r")  # r does nothing while paused
        assert con.poll(0.3) is None
        os.write(tty_stdin, b"p")
        assert con.poll(2.0) == "resume"
        con.set_state("placing")
        os.write(tty_stdin, b"ngrip looser\x7fr\r")  # a note, with a correction
        assert _until(lambda: con.notes)
        assert con.take_notes()[0]["text"] == "grip looser"
        os.write(tty_stdin, b"e")  # e-stop: on the device immediately, not queued
        assert _until(lambda: dev.fault is not None)
        assert dev.fault.code == "estop" and dev.output_force == 0.0
        assert not con.actions
        con.set_state("fault")
        os.write(tty_stdin, b"c")
        assert con.poll(2.0) == "clear"
    finally:
        con.close()


@pytest.mark.realtime
@pytest.mark.integration
def test_non_ascii_keys_never_end_the_reader_and_estop_acts_in_every_state(tty_stdin, dev):
    """A German operator's keys: ü beside p, a note about Müller, a byte no encoding knows.
    The reader reads whole characters, says what it cannot use, and e (Ctrl-E inside a note)
    latches the e-stop in every state — the rating screen included."""
    con = KeyConsole(dev, live=False)
    try:
        con.set_state("placing")
        os.write(tty_stdin, "ü".encode())  # one key, two bytes: nothing happens
        os.write(tty_stdin, "ö".encode()[:1])  # half a character, the rest in the next read
        time.sleep(0.2)
        os.write(tty_stdin, "ö".encode()[1:] + b"\xff")  # and a byte that is no character
        os.write(tty_stdin, b"p")  # the reader is alive: p still pauses
        assert con.poll(2.0) == "pause"
        con.set_state("placing")
        os.write(tty_stdin, "nProband Müller: Griff zu fest\r".encode())
        assert _until(lambda: con.notes)
        assert con.take_notes()[0]["text"] == "Proband Müller: Griff zu fest"
        os.write(tty_stdin, "nÄrger".encode())  # a note half typed: e is a letter in it ...
        os.write(tty_stdin, b"e")
        time.sleep(0.3)
        assert dev.fault is None
        os.write(tty_stdin, b"\x05")  # ... and Ctrl-E is the e-stop, at once
        assert _until(lambda: dev.fault is not None) and dev.fault.code == "estop"
        os.write(tty_stdin, b"\r")
        assert _until(lambda: con.notes) and con.take_notes()[0]["text"] == "Ärgere"
        for state in ("rating", "trial", "idle", "reference", "paused", "placing", "fault"):
            dev.clear_fault()
            con.set_state(state)
            os.write(tty_stdin, "é".encode() + b"e")
            assert _until(lambda: dev.fault is not None), state
            assert dev.output_force == 0.0
        assert not any("ignored" in m for m in con.view.messages if "'e'" in m)
        assert any("E-STOP latched" in m for m in con.view.messages)
        os.write(tty_stdin, b"\x1b[C\x1bOD")  # arrow keys (ESC [ C, ESC O D): no c, no D
        assert con.poll(0.5) is None and dev.fault is not None
        os.write(tty_stdin, b"c")  # c itself still clears
        assert con.poll(2.0) == "clear"
    finally:
        con.close()


@pytest.mark.realtime
@pytest.mark.integration
def test_an_estop_after_c_is_never_cleared_by_it(tty_stdin, dev):
    """c queued, then e before the session acts on the c, or while the clear is on its way
    to the device: the device stays latched (the later key wins), and the operator is told
    why; a c with no e-stop after it clears."""
    import threading

    class SlowClear:  # the clear takes a while to reach the device (a serial round trip)
        def __init__(self, d):
            self.d, self.fault, self.sent, self.go = d, None, threading.Event(), threading.Event()

        def estop(self):
            self.d.estop()

        def clear_fault(self):
            self.sent.set()
            assert self.go.wait(5.0)
            self.d.clear_fault()

    slow = SlowClear(dev)
    con = KeyConsole(slow, live=False)
    said = lambda text: any(text in m for m in con.view.messages)  # noqa: E731
    try:
        dev.estop()
        con.set_state("fault")
        os.write(tty_stdin, b"c")
        assert _until(lambda: con.actions)
        os.write(tty_stdin, b"e")  # the operator changed their mind before the c was acted on
        assert _until(lambda: any("E-STOP latched" in m for m in con.view.messages))
        assert con.poll(2.0) == "clear"
        slow.go.set()
        assert con.clear_fault(slow) == "an E-STOP was pressed after c"
        assert dev.fault is not None and dev.fault.code == "estop"

        slow.go.clear()
        con.set_state("fault")  # as the session does after a refused clear
        os.write(tty_stdin, b"c")
        assert con.poll(2.0) == "clear"
        done = []
        worker = threading.Thread(target=lambda: done.append(con.clear_fault(slow)))
        worker.start()
        assert slow.sent.wait(5.0)
        con.view.messages.clear()  # (the view keeps the last six)
        os.write(tty_stdin, b"e")  # while the clear is on its way
        assert _until(lambda: said("E-STOP latched"))
        slow.go.set()  # the clear reaches the device after the e-stop did
        worker.join(5.0)
        assert done == ["an E-STOP was pressed while it was being cleared, and is latched "
                        "again"]
        assert dev.fault is not None and dev.fault.code == "estop" and dev.output_force == 0.0

        con.set_state("fault")
        os.write(tty_stdin, b"c")
        assert con.poll(2.0) == "clear"  # taken by the session: what comes now is later
        con.view.messages.clear()
        os.write(tty_stdin, b"eq")  # e, then q (which once re-marked the c as after the e)
        assert _until(lambda: said("key 'q' ignored: clearing")) and said("E-STOP latched")
        slow.go.set()
        assert con.clear_fault(slow) == "an E-STOP was pressed after c"
        assert dev.fault is not None

        con.set_state("fault")
        os.write(tty_stdin, b"c")  # nothing after it: cleared
        assert con.poll(2.0) == "clear"
        assert con.clear_fault(dev) is None and dev.fault is None
    finally:
        con.close()


@pytest.mark.realtime
@pytest.mark.integration
def test_an_estop_the_device_does_not_confirm_is_said_loudly(tty_stdin):
    """A link that fails as e is pressed: the console says the e-stop is not confirmed and
    names the device's own button, and the reader goes on."""

    class Gone:
        fault = None

        def estop(self):
            raise OSError(5, "Input/output error")

    con = KeyConsole(Gone(), live=False)
    try:
        con.set_state("trial")
        os.write(tty_stdin, b"e")
        assert _until(lambda: any("E-STOP NOT CONFIRMED" in m for m in con.view.messages))
        assert not any("E-STOP latched" in m for m in con.view.messages)
        con.set_state("placing")
        os.write(tty_stdin, b"r")
        assert con.poll(2.0) == "go"
    finally:
        con.close()


@pytest.mark.integration
def test_device_check_reports_saturation_by_sample():
    out = subprocess.run([sys.executable, "-m", "app", "device", "check", "realism", "--json",
                          "--windows", "6"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    rows = {r["sample"]: r for r in json.loads(out.stdout)["rows"]}
    assert set(rows) == {"pulse_firm", "pulse_soft", "sinusoid_firm", "sinusoid_soft",
                         "matched_firm", "matched_soft"}
    # the pulses (≤ 1 N at the fastest taps) never reach the 3-N limit; sinusoids can
    assert rows["pulse_firm"]["tap_rate"] == 0 and rows["pulse_soft"]["tap_rate"] == 0
    assert max(rows["sinusoid_firm"]["tap_rate"], rows["sinusoid_soft"]["tap_rate"]) > 0


def test_familiarization_runs_until_the_participant_is_done(tmp_path):
    from app.participants import Responder
    from app.recorder import SessionFiles, new_session_dir, read_trials
    from app.runner import SessionRunner
    from protocols import SessionEngine, load_protocol

    class ThreeWindows(Responder):
        n = 0

        def keep_tapping(self):
            self.n += 1
            return self.n < 3

        def rate(self, trial, scale, result, rng):
            return 4, 1.0

    p = load_protocol("realism")
    folder, n = new_session_dir(tmp_path, "P01")
    dev = open_device("sim", seed=1)
    runner = SessionRunner(protocol=p, engine=SessionEngine(p, 1, "P01"), device=dev,
                           files=SessionFiles(folder), responder=ThreeWindows(),
                           participant="P01", session=n, seed=1, traces="none")
    trial = runner.engine.next_trial([])
    runner._attempt(trial)
    rows, _ = read_trials(folder / "trials.tsv")
    assert rows[0]["phase"] == "familiarization" and rows[0]["status"] == "valid"
    assert int(rows[0]["n_taps"]) > 15  # three 5-s windows of taps


@pytest.mark.realtime
@pytest.mark.integration
def test_the_counter_counts_items_never_past_their_number(tty_stdin, dev):
    """Issue 30 (7): after redraws the panel read '50 of 45' (attempts against items). It
    counts finished items, the attempt's number in brackets; at the last item, and after
    it, never more than the items there are."""
    from rich.console import Console

    con = KeyConsole(dev, live=False)
    try:
        for done, shown in ((44, "item 45 of 45"), (45, "item 45 of 45")):
            con.view.phase, con.view.total, con.view.done, con.view.trial = "testing", 45, \
                done, 50
            out = Console(record=True, width=160, file=io.StringIO())
            out.print(con._render())
            text = out.export_text()
            assert f"testing · {shown} (trial #50)" in text, text
    finally:
        con.close()


@pytest.mark.realtime
@pytest.mark.integration
def test_bytes_that_are_no_character_are_said_and_the_keys_still_act(tty_stdin, dev):
    """A terminal whose encoding is not the one it sends (Latin-1 'ü' into a UTF-8 reader)
    was replaced silently; it is said, dropped from a note, and e still stops at once."""
    con = KeyConsole(dev, live=False)
    try:
        con.set_state("placing")
        os.write(tty_stdin, b"nM\xfcller\r")  # 'Müller' from a Latin-1 terminal
        assert _until(lambda: con.notes)
        assert con.notes[0]["text"] == "Mller"
        assert any("not utf-8 text was ignored" in m.lower() for m in con.view.messages)
        os.write(tty_stdin, b"\xff\xfee")
        assert _until(lambda: dev.fault is not None) and dev.fault.code == "estop"
    finally:
        con.close()


@pytest.mark.realtime
@pytest.mark.integration
def test_a_terminal_that_goes_away_is_said_and_the_session_goes_on(dev):
    """The operator's terminal closed (an ssh session dropped, the window closed): the key
    reader says so and ends (the device's own button still acts); the console keeps
    answering the runner, which never hangs on it."""
    master, slave = os.openpty()
    f = os.fdopen(slave, "r", buffering=1)
    old = sys.stdin
    sys.stdin = f
    try:
        con = KeyConsole(dev, live=False)
        try:
            con.set_state("placing")
            os.write(master, b"r")
            assert con.poll(2.0) == "go"
            os.close(master)
            assert _until(lambda: any("terminal" in m and "no longer read" in m
                                      for m in con.view.messages))
            assert con.poll(0.1) is None  # the runner's poll still returns
        finally:
            con.close()
    finally:
        sys.stdin = old
        f.close()


@pytest.mark.realtime
@pytest.mark.integration
def test_close_survives_a_live_view_that_cannot_draw_any_more(tty_stdin, dev):
    """With the live view on (a real session), close() draws a last frame: on a terminal
    that went away that raised EIO in the session's finally, replacing its result."""
    con = KeyConsole(dev, live=False)

    class GoneTerminal:
        def stop(self):
            raise OSError(5, "Input/output error")

    con._live = GoneTerminal()
    con.close()  # no exception
