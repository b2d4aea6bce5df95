"""The link on a busy host: heartbeats that the interpreter cannot hold up, a watchdog that
still catches a host that died or hung, and what the device saw (LINK_REPORT).

Everything runs over pyserial on a real pseudo-terminal to the Python emulator. No test
waits on the host keeping a deadline: a host "busy" here holds the interpreter lock on
purpose (a ctypes call that keeps it), which stops every Python thread deterministically;
the checks are what the device then did, read from its own report and log.
"""

import ctypes
import json
import re
import shutil
import subprocess
import sys
import time

import pytest

from app.participants import ScriptedResponder
from app.recorder import SessionFiles, new_session_dir, read_trials
from app.runner import SessionRunner
from device import Scene, open_device
from device.errors import DeviceFaultError
from device.serial.native import load
from protocols import SessionEngine, parse_protocol

from ..app.test_faults import MINI
from ..conftest import wait_for as _wait_for

FIRM = Scene("firm", spring=680.0)

pytestmark = pytest.mark.skipif(load()[0] is None, reason=f"no native link: {load()[1]}")


def _hold_the_interpreter(seconds: float) -> None:
    """Keep the interpreter lock for ``seconds``: no Python thread of this process runs (a
    hung main loop, a long C call, a stop-the-world collection)."""
    ctypes.PyDLL(None).usleep(int(seconds * 1e6))  # PyDLL: the call keeps the lock


@pytest.mark.realtime
@pytest.mark.integration
@pytest.mark.slow
def test_a_host_whose_interpreter_is_held_keeps_the_device_fed(own_emulator):
    """0.5 s with the interpreter lock held (five watchdog periods): the Python-thread
    heartbeat could not run, the native thread does, and the device's watchdog stays
    quiet. The device's own report shows the frames kept coming through the stall."""
    with open_device(f"serial:{own_emulator.port}") as dev:
        assert dev.link.native
        dev.load_scene(FIRM)
        dev.home()
        dev.device_link_report(reset=True)
        for _ in range(3):
            _hold_the_interpreter(0.5)
            dev.heartbeat()  # a main loop that stalls, then goes on: it renews the lease
        seen = dev.device_link_report()
        assert dev.fault is None, dev.fault
        res = dev.run_window(0.2, from_first_contact=False)
        assert not res.faults
        assert seen["frames"] >= 10  # heartbeats came while the interpreter was held
    assert "FAULT watchdog" not in own_emulator.stderr()


@pytest.mark.realtime
@pytest.mark.integration
def test_the_python_thread_link_is_starved_by_the_same_hold(own_emulator):
    """The control: with reading and heartbeats in Python threads, the same hold stops the
    heartbeats and the device zeroes its output — the failure the native thread removes."""
    with open_device(f"serial:{own_emulator.port}", native=False) as dev:
        assert not dev.link.native and dev.link_stats()["heartbeats"]["why_not"]
        dev.load_scene(FIRM)
        dev.home()
        _hold_the_interpreter(0.5)
        _wait_for(lambda: dev.fault is not None, what="the watchdog fault")
        assert dev.fault.code == "watchdog"
        dev.clear_fault()


HUNG = r"""
import ctypes, sys
from device import Scene, open_device
from device.errors import DeviceFaultError
with open_device("serial:" + sys.argv[1]) as dev:
    dev.load_scene(Scene("firm", spring=680.0))
    dev.home()
    print("homed", flush=True)
    ctypes.PyDLL(None).sleep(30)   # the interpreter hangs, holding its lock
"""


@pytest.mark.realtime
@pytest.mark.integration
@pytest.mark.slow
def test_a_hung_interpreter_still_trips_the_watchdog(own_emulator):
    """A host whose interpreter hangs stops renewing the native thread's lease (1 s); the
    heartbeats stop and the device zeroes its output T_wd after the last of them."""
    host = subprocess.Popen([sys.executable, "-c", HUNG, own_emulator.port],
                            stdout=subprocess.PIPE, text=True)
    try:
        assert host.stdout.readline().strip() == "homed"
        _wait_for(lambda: "FAULT watchdog" in own_emulator.stderr(), what="the watchdog")
        assert host.poll() is None  # the host is still there, hung
    finally:
        host.kill()
        host.wait()
    line = re.search(r"FAULT watchdog .* ([\d.]+) ms after the last heartbeat",
                     own_emulator.stderr())
    assert float(line.group(1)) <= 100.0 + 0.1  # T_wd of device time after the last frame


@pytest.mark.realtime
@pytest.mark.integration
@pytest.mark.slow
def test_the_lease_ends_the_heartbeats_after_its_stated_second(own_emulator):
    """The bound the test above cannot give (it waits for the fault, however late): the
    interpreter held for 3 s, three times the lease. The device must fault during the hold,
    and the frames it received meanwhile are at most what the native thread sends in one
    lease: a HEARTBEAT per T_wd/4 of silence, so LEASE_S / (T_wd/4) of them (40), plus the
    LINK_QUERY that asks and a few frames around the hold. A count, not a time: a slower
    native thread sends fewer, never more; a 1.2-s lease would send 48 (a 20-s lease sent
    121 and kept the device fed)."""
    from device.serial.link import LEASE_S

    with open_device(f"serial:{own_emulator.port}") as dev:
        assert dev.link.native
        dev.load_scene(FIRM)
        dev.home()
        t_wd = dev.info.watchdog_s
        dev.device_link_report(reset=True)
        _hold_the_interpreter(3.0)
        seen = dev.device_link_report()
        # 41–42 measured: 40 heartbeats of the lease, the LINK_QUERY, one around the reset
        assert seen["frames"] <= LEASE_S / (t_wd / 4) + 5, seen
        _wait_for(lambda: dev.fault is not None, what="the watchdog fault")
        assert dev.fault.code == "watchdog"
        # the refusal says who fell silent, once: here the device saw this host's frames
        # stop for the hold (3 s) less the lease (1 s), far over T_wd
        with pytest.raises(DeviceFaultError) as told:
            dev.run_window(0.1)
        msg = str(told.value)
        assert "this host wrote its frames at most" in msg, msg
        gap = float(re.search(r"the device saw them at most ([\d.]+) ms apart", msg)[1])
        assert gap > 1e3 * (3.0 - LEASE_S) * 0.9, msg
        with pytest.raises(DeviceFaultError) as again:
            dev.run_window(0.1)
        assert "device saw" not in str(again.value)
        dev.clear_fault()


@pytest.mark.realtime
@pytest.mark.integration
@pytest.mark.slow
@pytest.mark.parametrize("native", [True, False], ids=["native", "python-threads"])
def test_a_main_loop_that_hangs_without_the_interpreter_lock_trips_the_watchdog(
        own_emulator, native):
    """The hang the reader thread used to hide (an audit of issue 29): the thread that
    drives the device waits forever (a deadlock, a wait on the participant that never
    returns: here a sleep, which lets every other Python thread run) while the link's
    reader thread goes on reading. Reads renew no lease, so the heartbeats stop LEASE_S
    after the last command, native or in Python threads, and the device zeroes its output.
    The same count as above bounds the frames it got meanwhile (the native reader renewed
    at every turn before, and the device got a heartbeat every 25 ms for the whole hang)."""
    from device.serial.link import LEASE_S

    with open_device(f"serial:{own_emulator.port}", native=native) as dev:
        assert dev.link.native == native
        dev.load_scene(FIRM)
        dev.home()
        t_wd = dev.info.watchdog_s
        dev.device_link_report(reset=True)
        time.sleep(3 * LEASE_S)  # the main loop hangs; the reader thread reads on
        assert dev.link._reader.is_alive()
        seen = dev.device_link_report()
        assert seen["frames"] <= LEASE_S / (t_wd / 4) + 5, seen
        _wait_for(lambda: dev.fault is not None, what="the watchdog fault")
        assert dev.fault.code == "watchdog"
        assert dev.link_stats()["heartbeats"]["lease_lapses"] > 0
        dev.clear_fault()


class SlowToAnswer(ScriptedResponder):
    """Takes longer than the lease and the watchdog together to rate each trial, and notes
    what the device reported meanwhile."""

    def __init__(self, dev, seconds: float):
        self.dev, self.seconds, self.seen = dev, seconds, []

    def answer(self, response, question, rng):
        time.sleep(self.seconds)  # nothing drives the device meanwhile
        self.seen.append((self.dev.fault, self.dev.output_force))
        return super().answer(response, question, rng)


@pytest.mark.realtime
@pytest.mark.integration
@pytest.mark.slow
def test_a_participant_who_takes_long_to_answer_meets_no_watchdog(own_emulator, tmp_path):
    """The other half of the lease: a session's main loop legitimately leaves the device
    alone while the participant answers. The runner zeroes the output as each window ends,
    so the lapsed lease stops heartbeats to a device whose watchdog is not armed (docs §3:
    armed while output is enabled), and the next window homes it again."""
    from device.serial.link import LEASE_S

    p = parse_protocol(MINI.replace("repetitions = 2", "repetitions = 1"), "mini.toml")
    folder, n = new_session_dir(tmp_path, "P01")
    files = SessionFiles(folder)
    files.start("")
    with open_device(f"serial:{own_emulator.port}") as dev:
        ui = SlowToAnswer(dev, LEASE_S + 4 * dev.info.watchdog_s)
        runner = SessionRunner(protocol=p, engine=SessionEngine(p, 3, "P01"), device=dev,
                               files=files, responder=ui, participant="P01", session=n,
                               seed=3)
        try:
            status = runner.run()
        except Exception as exc:  # what the link saw, for a failure under load to explain
            raise AssertionError(f"{exc}\nlink: {dev.link_stats()}\nemulator: "
                                 f"{own_emulator.stderr()[-1500:]}") from exc
        assert status == "complete", dev.link_stats()
        assert dev.link_stats()["heartbeats"]["lease_lapses"] > 0  # the lease did lapse
    rows, _ = read_trials(folder / "trials.tsv")
    assert [r["status"] for r in rows] == ["valid"] * 2
    assert ui.seen == [(None, 0.0)] * 2  # output off, no fault, while each answer came
    assert "FAULT" not in own_emulator.stderr()


@pytest.mark.realtime
@pytest.mark.integration
def test_the_device_reports_what_it_saw_of_the_host(own_emulator):
    """LINK_REPORT: frames and the gaps between them in device time; a reset starts afresh
    and HELLO does too."""
    with open_device(f"serial:{own_emulator.port}") as dev:
        first = dev.device_link_report(reset=True)
        assert first["frames"] >= 2 and first["bad_frames"] == 0
        assert first["gaps"] == first["frames"] - 1 == sum(first["gap_hist_2ms"])
        top = max(k for k, c in enumerate(first["gap_hist_2ms"]) if c)  # the longest's bin
        assert 2 * top <= first["gap_max_ms"] < (2 * top + 2 if top < 63 else float("inf"))
        dev.load_scene(FIRM)
        dev.home()
        dev.run_window(0.3, from_first_contact=False)
        again = dev.device_link_report()
        assert again["since_s"] >= first["since_s"]
        assert again["frames"] > 2  # counted from the reset, not from HELLO
        report = dev.link_stats()
        assert report["device_saw"]["frames"] >= again["frames"]
        hb = report["heartbeats"]
        assert hb["native"] and hb["gaps"] > 0 and hb["gap_max_ms"] > 0
        assert hb["memory_locked"] in ("ring, stack and state", "stack and state", "no")
        # real-time scheduling is granted or said to be refused, never silently absent
        assert hb["rt_priority"] > 0 or hb["rt_refused"]


NO_RT = r"""
import json, sys
from device import Scene, open_device
from device.errors import DeviceFaultError
with open_device("serial:" + sys.argv[1]) as dev:
    dev.load_scene(Scene("firm", spring=680.0))
    dev.home()
    res = dev.run_window(0.3, from_first_contact=False)
    print(json.dumps({"hb": dev.link_stats()["heartbeats"], "faults": len(res.faults),
                      "records": len(res.traces["t"])}))
"""


@pytest.mark.realtime
@pytest.mark.integration
@pytest.mark.skipif(shutil.which("setpriv") is None, reason="setpriv (util-linux) missing")
def test_without_real_time_scheduling_the_link_says_so_and_works(own_emulator):
    """The fallback where the system grants no real-time priority (a process without
    CAP_SYS_NICE): the threads run at normal priority, the link says why, and works."""
    out = subprocess.run(["setpriv", "--bounding-set", "-sys_nice", "--inh-caps", "-sys_nice",
                          sys.executable, "-c", NO_RT, own_emulator.port],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    assert got["hb"]["native"] and got["hb"]["rt_priority"] == 0
    assert got["hb"]["rt_refused"] == "Operation not permitted"
    assert got["faults"] == 0 and got["records"] == 3000


def test_gap_percentiles_are_bin_edges_never_above_the_largest_gap():
    """By hand: 3 gaps in the 2–4 ms bin and 1 in 6–8 ms; p50 falls in the 2–4 bin (edge
    4 ms), p99 and p99.9 in the 6–8 bin, whose edge (8 ms) is above the exact largest gap
    (6.5 ms) and is replaced by it."""
    from device.serial.link import gap_percentiles

    got = gap_percentiles([0, 3, 0, 1], 2.0, max_ms=6.5)
    assert got == {"gap_p50_ms": 4.0, "gap_p99_ms": 6.5, "gap_p999_ms": 6.5, "gaps": 4}
    assert gap_percentiles([0, 3, 0, 1], 2.0)["gap_p999_ms"] == 8.0
    assert gap_percentiles([0, 0], 2.0, max_ms=None)["gap_p50_ms"] is None


def test_the_bench_bounds_a_fault_rate_it_did_not_see():
    """`bench link` printed 0 faults per hour after 20 s without one; it now gives the
    one-sided 95 % upper bound too. Poisson bounds, as tabled (Garwood 1936): none seen,
    -ln 0.05 = 2.996 per exposure (the rule of three); one, 4.744; five, 10.51."""
    from benchmarks.link_load import _per_hour, faults_upper95

    assert faults_upper95(0, 3600) == pytest.approx(2.996, abs=1e-3)
    assert faults_upper95(1, 3600) == pytest.approx(4.744, abs=1e-3)
    assert faults_upper95(5, 3600) == pytest.approx(10.513, abs=1e-3)
    assert faults_upper95(0, 20) == pytest.approx(2.996 * 180, rel=1e-3)
    assert _per_hour(0, 20) == "0 (≤ 539)"
