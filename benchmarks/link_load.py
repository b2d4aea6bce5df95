"""``hapticlab bench link --load 0,1,2,4``: the link on a busy computer.

For each device target (the Python emulator, the host-built firmware, the host build with
the board's resources, the STM32F405 build under QEMU; on request the bridges over the
Force Dimension and OpenHaptics stand-ins, ``dhd-stub`` and ``hd-stub``) and each number N
of competing CPU-bound processes of normal priority, a session's traffic runs for
``--seconds``: windows streaming every trace channel, each drawn on a PsychoPy window as
the runner draws it (the tap screen during the window, the rating screen between windows),
an e-stop from another thread (as the operator's key reader sends it) every fifth window,
alternating between a window and a playback. Measured:

* the gaps between the host's frames **as the device saw them** (LINK_REPORT: p50, p99,
  p99.9 from 2-ms bins, and the exact maximum, in device time), and as the host wrote
  them;
* watchdog faults that were not asked for, per hour;
* e-stop latency in three parts: on the host, from the moment the e-stop was due to the
  ESTOP frame written (another thread calls ``estop()``, as the console's key reader does,
  so it first waits for the interpreter); across the link, bounded by the PING round trip
  measured after each window; on the device, from its arrival to the servo tick that
  zeroed output, as the device measured it (LINK_REPORT: counted from the last time it
  found its input empty before the frame, an upper bound);
* the longest stall of a Python thread in the host (how long the interpreter kept a
  thread from running: what a heartbeat in Python would have waited).

Each cell runs twice in the same process: with the native link thread and, as the
baseline, with reading and heartbeats in Python threads (``native=False``).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

from ._common import emit, print_table

TARGETS = {"python": (), "host": ("--firmware", "host"),
           "host-board": ("--firmware", "host-board"), "qemu": ("--firmware", "qemu"),
           "dhd-stub": ("--firmware", "dhd-stub"), "hd-stub": ("--firmware", "hd-stub")}
_HOG = "while True: pass"


def _hogs(n: int) -> list[subprocess.Popen]:
    return [subprocess.Popen([sys.executable, "-c", _HOG]) for _ in range(n)]


def _start_target(name: str, log) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen([sys.executable, "-m", "app", "device", "emulate", "--seed", "3",
                             *TARGETS[name]], stdout=subprocess.PIPE, stderr=log, text=True)
    port = proc.stdout.readline().strip()
    if not port.startswith("/dev/"):
        proc.kill()
        raise RuntimeError(f"target {name} did not announce a port")
    return proc, port


class _Screen:
    """The participant's window as a session draws it, or nothing without a display."""

    def __init__(self, window: bool):
        self.screen = None
        self.xvfb = None
        self.why = ""
        if not window:
            self.why = "--no-window"
            return
        if not os.environ.get("DISPLAY"):
            if shutil.which("Xvfb") is None:
                self.why = "no display and no Xvfb"
                return
            n = 140 + os.getpid() % 50
            self.xvfb = subprocess.Popen(["Xvfb", f":{n}", "-screen", "0", "1280x1024x24",
                                          "-nolisten", "tcp"], stdout=subprocess.DEVNULL,
                                         stderr=subprocess.DEVNULL)
            for _ in range(100):
                if os.path.exists(f"/tmp/.X11-unix/X{n}"):
                    break
                time.sleep(0.05)
            os.environ["DISPLAY"] = f":{n}"
        from app.screen import PsychoPyScreen
        from protocols import load_protocol

        self.screen = PsychoPyScreen(load_protocol("factorial"), keys=lambda: [])

    def tap(self, t: float, partial, duration: float) -> None:
        if self.screen is not None:
            self.screen.progress(t, partial, duration)

    def rating(self, seconds: float) -> None:
        """The rating question on screen for ``seconds``, redrawn every frame (60 Hz)."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            if self.screen is not None:
                self.screen._frame("How realistic was this?", "1 … 10, then ENTER")
            time.sleep(1 / 60)

    def close(self) -> None:
        if self.screen is not None:
            self.screen.close()
        if self.xvfb is not None:
            self.xvfb.terminate()
            self.xvfb.wait(timeout=5)


def _unasked(faults: list[str], code: str, where: str) -> None:
    """A fault the bench did not ask for (its own e-stops are not counted: nothing else
    presses the device's e-stop here)."""
    if code != "estop":
        faults.append(f"{code} {where}")


class _Seen:
    """The device's LINK_REPORTs of a run, added up (each read resets the device's)."""

    def __init__(self):
        self.hist = np.zeros(64)
        self.frames = self.bad = 0
        self.gap_max = 0.0

    def add(self, rep: dict | None) -> None:
        if rep is None:
            return
        self.hist += rep["gap_hist_2ms"]
        self.frames += rep["frames"]
        self.bad += rep["bad_frames"]
        self.gap_max = max(self.gap_max, rep["gap_max_ms"])

    def summary(self) -> dict | None:
        from device.serial.link import gap_percentiles

        if not self.frames:
            return None
        return {"frames": self.frames, "bad_frames": self.bad, "gap_max_ms": self.gap_max,
                **gap_percentiles(self.hist, 2.0, self.gap_max)}


def _cell(port: str, seconds: float, screen: _Screen, native: bool) -> dict:
    """One run of session traffic on ``port`` for ``seconds``."""
    from device import open_device
    from device.errors import DeviceFaultError
    from device.serial import messages as M
    from device.suite import SUITE_SCENES

    faults: list[str] = []
    call_to_frame, reaction, rtt = [], [], []
    seen = _Seen()
    windows = 0
    with open_device(f"serial:{port}", native=native) as dev:
        if dev.fault is not None:
            dev.clear_fault()
        dev.device_link_report(reset=True)
        dev.link.heartbeat_report(reset=True)

        def draw(t, partial):
            screen.tap(t, partial, 2.0)

        end = time.monotonic() + seconds
        k = 0
        while time.monotonic() < end:
            k += 1
            estop_now = k % 5 == 0
            playback = estop_now and (k // 5) % 2 == 0
            if dev.fault is not None:  # latched between windows (while the rating was shown)
                _unasked(faults, dev.fault.code, "between windows")
                dev.clear_fault()
            dev.load_scene(SUITE_SCENES["pulse_firm"])
            try:
                dev.home()
            except DeviceFaultError:
                _unasked(faults, dev.fault.code if dev.fault else "?", "before a window")
                dev.clear_fault()
                continue
            timer = None
            due = time.perf_counter() + 0.3  # when the operator's key "arrives"
            if estop_now:
                # as the console's key reader: another thread, which must first get the
                # interpreter (the call→frame time counts from when it was due)
                timer = threading.Timer(0.3, dev.estop)
                timer.start()
            try:
                if playback:
                    res = dev.play_force(np.zeros(int(dev.info.servo_rate_hz)))
                else:
                    res = dev.run_window(2.0, from_first_contact=False, on_progress=draw)
            except DeviceFaultError:  # latched between HOME and the start
                _unasked(faults, dev.fault.code if dev.fault else "?", "before the start")
                dev.clear_fault()
                continue
            finally:
                if timer is not None:
                    timer.join()
            windows += 1
            if res.faults:
                f = res.faults[0]
                if estop_now and f.code == "estop":
                    sent = dev.link.last_sent.get(M.EStop.TYPE)
                    if sent is not None:
                        call_to_frame.append(sent - due)
                    rep = dev.device_link_report(reset=True)
                    seen.add(rep)
                    if rep is not None and rep["estop_max_ms"] is not None:
                        reaction.append(rep["estop_max_ms"] * 1e-3)
                else:
                    _unasked(faults, f.code, "in a window")
            elif estop_now:
                faults.append("e-stop not reported")
            if dev.fault is not None:
                dev.clear_fault()
            dev.zero()  # as the session runner: output off while the rating is shown
            rtt.append(dev.ping())
            screen.rating(0.5)
        seen.add(dev.device_link_report())
        lim = dev.link.limits
        link = {"link_bytes_s": lim.link_bytes_s if lim else None,
                "decimation": dev._decimation, "watchdog_ms": dev.info.watchdog_s * 1e3}
        host = dev.link.heartbeat_report()
        stall = dev.link.link_stats()["host_stall_max_ms"]
        rate = dev.info.servo_rate_hz
    ms = lambda a, q: float(np.percentile(a, q) * 1e3) if len(a) else None  # noqa: E731
    return {"native": native, "seconds": seconds, "windows": windows,
            "spurious_faults": len(faults), "fault_codes": faults,
            "faults_per_hour": len(faults) * 3600 / seconds,
            "faults_per_hour_upper95": faults_upper95(len(faults), seconds),
            "device_saw": seen.summary(), "host_wrote": host, "host_stall_max_ms": stall,
            "link": link,
            "estop": {"n": len(reaction),
                      "call_to_frame_ms": {"p50": ms(call_to_frame, 50),
                                           "max": ms(call_to_frame, 100)},
                      "device_reaction_ms": {"p50": ms(reaction, 50), "max": ms(reaction, 100)},
                      "ping_rtt_ms": {"p50": ms(rtt, 50), "max": ms(rtt, 100)},
                      "servo_tick_ms": 1e3 / rate}}


def faults_upper95(k: int, seconds: float) -> float:
    """One-sided 95 % upper bound on a rate of faults per hour after ``k`` in ``seconds``
    (Poisson, exact: half the chi-square quantile with 2k + 2 degrees of freedom; for none
    it is the 'rule of three', 3 / exposure)."""
    from scipy.stats import chi2

    return float(chi2.ppf(0.95, 2 * k + 2) / 2 * 3600 / seconds)


def _per_hour(k: int, seconds: float) -> str:
    """Faults per hour as measured, with the bound a short run allows: none in 20 s is
    not 'none per hour'."""
    return f"{k * 3600 / seconds:.0f} (≤ {faults_upper95(k, seconds):.0f})"


def main(args) -> int:
    loads = [int(x) for x in str(args.load).split(",")]  # checked: benchmarks._options
    targets = [t.strip() for t in (args.targets or "python,host,host-board,qemu").split(",")]
    modes = (True, False) if args.baseline else (True,)
    screen = _Screen(not args.no_window)
    rows = []
    try:
        for target in targets:
            for n in loads:
                for native in modes:
                    log = tempfile.TemporaryFile("w+")
                    proc, port = _start_target(target, log)
                    hogs = _hogs(n)
                    try:
                        time.sleep(0.5)  # the hogs are running
                        r = _cell(port, args.seconds, screen, native)
                    finally:
                        for h in hogs:
                            h.kill()
                            h.wait()
                        proc.terminate()
                        proc.wait(timeout=20)
                        log.seek(0)
                        said = [ln.strip() for ln in log if "FAULT" in ln]
                        log.close()
                    r.update(target=target, load=n, device_log=said)
                    rows.append(r)
                    print(_line(r), file=sys.stderr if args.json else sys.stdout, flush=True)
    finally:
        screen.close()
    payload = {"cores": os.cpu_count(), "window": screen.why or "PsychoPy window drawn",
               "rows": rows}
    if args.json:
        emit(payload, True)
        return 0
    table = []
    for r in rows:
        d = r["device_saw"] or {}
        e = r["estop"]
        table.append((r["target"], r["load"], "native" if r["native"] else "Python",
                      _f(d.get("gap_p50_ms")), _f(d.get("gap_p99_ms")), _f(d.get("gap_p999_ms")),
                      _f(d.get("gap_max_ms")),
                      _per_hour(r["spurious_faults"], r["seconds"]),
                      f"{_f(e['call_to_frame_ms']['p50'])} / {_f(e['call_to_frame_ms']['max'])}",
                      f"{_f(e['ping_rtt_ms']['p50'])} / {_f(e['ping_rtt_ms']['max'])}",
                      f"{_f(e['device_reaction_ms']['p50'])} / "
                      f"{_f(e['device_reaction_ms']['max'])}",
                      _f(r["host_stall_max_ms"])))
    print_table(f"heartbeat gaps the device saw, faults and e-stop latency under load "
                f"({os.cpu_count()} cores; {payload['window']}; {args.seconds:g} s per row)",
                ["target", "load", "link", "gap p50", "p99", "p99.9", "max [ms]", "faults/h",
                 "e-stop due→sent", "PING RTT", "arrived→zeroed", "host stall"], table)
    print("gaps: between the host's frames as the device saw them (2-ms bins; max exact); "
          "e-stop [ms, p50 / max]: due→sent on the host (the key reader's thread waits for "
          "the interpreter), the link bounded by the PING round trip, arrived→zeroed on "
          "the device (its own count of ticks, from when it last found its input empty); "
          "host stall: the longest a Python thread of the host was kept from running; "
          "faults/h as measured (≤ the one-sided 95 % upper bound the run's length allows)")
    for native in modes:
        cells = [r for r in rows if r["native"] is native]
        k, secs = sum(r["spurious_faults"] for r in cells), sum(r["seconds"] for r in cells)
        print(f"{'native' if native else 'Python'} link, all cells: {k} spurious fault(s) in "
              f"{secs / 60:.1f} min of session traffic: {_per_hour(k, secs)} per hour")
    return 0


def _f(x) -> str:
    return "—" if x is None else f"{x:.2f}"


def _line(r: dict) -> str:
    d = r["device_saw"] or {}
    return (f"{r['target']:>10} load {r['load']} {'native' if r['native'] else 'Python':6}: "
            f"device saw gaps p99.9 {_f(d.get('gap_p999_ms'))} ms, max "
            f"{_f(d.get('gap_max_ms'))} ms; {r['spurious_faults']} spurious fault(s) in "
            f"{r['windows']} windows; e-stop call→frame max "
            f"{_f(r['estop']['call_to_frame_ms']['max'])} ms, arrived→zeroed max "
            f"{_f(r['estop']['device_reaction_ms']['max'])} ms")
