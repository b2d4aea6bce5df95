"""``hapticlab bench link``: the serial link over a pseudo-terminal to the emulator.

* round trip: PING → PONG, N sequential probes (median, p95, p99); baseline in the same
  process: 16 bytes echoed by a thread over a raw pty (no framing, no protocol) — the
  ratio is the protocol's overhead;
* scene upload time per sample kind (real, spring, pulse, sinusoid, a 12 × 1000
  acceleration-matched table), median of repeats;
* contact-event latency: host receive time of each CONTACT minus the host time of its
  device tick, the clock offset taken from the fastest STATUS frame of the window (so
  the figure is the latency above the fastest frame);
* fuzz: ``--fuzz N`` mutated frames through the decoder (0 corrupt frames accepted).

``--firmware host`` measures the reference firmware instead (:func:`firmware_main`): PING,
ESTOP-to-zero during a streaming window, the trace stream's rate and the wait between a
window's last tick and its traces in hand (the moment a rating can be asked), against the
Python emulator measured the same way.
"""

from __future__ import annotations

import os
import select
import subprocess
import sys
import threading
import time

import numpy as np

from ._common import emit, print_table


def _raw_echo_rtt(n: int) -> np.ndarray:
    from device.serial.emulator import open_pty

    master, slave, _ = open_pty()
    stop = threading.Event()

    def echo():
        while not stop.is_set():
            r, _, _ = select.select([master], [], [], 0.05)
            if r:
                os.write(master, os.read(master, 4096))

    t = threading.Thread(target=echo, daemon=True)
    t.start()
    out = []
    msg = b"x" * 16
    try:
        for _ in range(n):
            t0 = time.perf_counter()
            os.write(slave, msg)
            got = b""
            while len(got) < len(msg):
                got += os.read(slave, 4096)
            out.append(time.perf_counter() - t0)
    finally:
        stop.set()
        t.join()
        os.close(master)
        os.close(slave)
    return np.array(out)


def main(args) -> int:
    from device import Scene, TransientTable, open_device
    from device.scene import TableTransient
    from device.serial.fuzz import fuzz
    from protocols import load_protocol

    if getattr(args, "load", None) is not None:
        from .link_load import main as load_main

        return load_main(args)
    if getattr(args, "firmware", None):
        return firmware_main(args)
    n_ping = 2000
    proc = subprocess.Popen([sys.executable, "-m", "app", "device", "emulate", "--seed", "3"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    port = proc.stdout.readline().strip()
    try:
        with open_device(f"serial:{port}") as dev:
            for _ in range(50):
                dev.ping()  # warm-up
            rtt = np.array([dev.ping() for _ in range(n_ping)])
            proto = load_protocol("realism")
            rng = np.random.default_rng(0)
            table = TransientTable(np.linspace(0.05, 0.16, 12), rng.normal(0, 0.5, (12, 1000)),
                                   "linear", 0.8)
            scenes = {"real (wood)": proto.samples["wood"].scene,
                      "spring": proto.samples["firm_spring"].scene,
                      "pulse": proto.samples["pulse_firm"].scene,
                      "sinusoid": proto.samples["sinusoid_firm"].scene,
                      "matched (12×1000 table)": Scene("matched", spring=680.0,
                                                       transient=TableTransient(table))}
            uploads = {}
            for name, sc in scenes.items():
                times = []
                for _ in range(max(3, args.repeats)):
                    t0 = time.perf_counter()
                    dev.load_scene(sc)
                    times.append(time.perf_counter() - t0)
                uploads[name] = float(np.median(times))
            dev.load_scene(scenes["pulse"])
            dev.home()
            dev.contact_rx.clear()
            offsets = []

            def progress(_t, _p):
                if dev.last_status is not None:
                    offsets.append(dev.last_status[0] - dev.last_status[1])

            res = dev.run_window(5.0, on_progress=progress)
            offset = min(offsets) if offsets else float("nan")
            t0_dev = res.traces["t"][0]
            rate = res.rate_hz
            lat = np.array([rx - (offset + t0_dev + tick / rate) for rx, tick in dev.contact_rx])
            stats = dev.link_stats()
    finally:
        proc.terminate()
        proc.wait(timeout=10)
    raw = _raw_echo_rtt(n_ping)
    fz = fuzz(args.fuzz, seed=1) if args.fuzz else None
    ms = lambda a, q: float(np.percentile(a, q) * 1e3)  # noqa: E731
    payload = {
        "rtt_ms": {"p50": ms(rtt, 50), "p95": ms(rtt, 95), "p99": ms(rtt, 99), "n": n_ping},
        "baseline_raw_pty_echo_ms": {"p50": ms(raw, 50), "p99": ms(raw, 99)},
        "protocol_overhead_ratio_p50": float(np.median(rtt) / np.median(raw)),
        "upload_ms": {k: v * 1e3 for k, v in uploads.items()},
        "contact_latency_ms": {"p50": ms(lat, 50) if lat.size else None,
                               "max": float(lat.max() * 1e3) if lat.size else None,
                               "n": int(lat.size)},
        "link_stats": stats,
        "fuzz": fz.as_dict() if fz else None,
    }
    if args.json:
        emit(payload, True)
        return 0
    r = payload["rtt_ms"]
    b = payload["baseline_raw_pty_echo_ms"]
    print_table(f"link: PING round trip over the pty ({n_ping} probes)",
                ["", "p50 [ms]", "p95 [ms]", "p99 [ms]"],
                [("protocol (frame, CRC, decode, reply)", f"{r['p50']:.3f}", f"{r['p95']:.3f}",
                  f"{r['p99']:.3f}"),
                 ("baseline: raw 16-byte echo, same process", f"{b['p50']:.3f}", "",
                  f"{b['p99']:.3f}")])
    print(f"protocol / raw echo (p50): {payload['protocol_overhead_ratio_p50']:.1f}×; "
          f"target p99 < 2 ms: {'met' if r['p99'] < 2 else 'NOT met'}")
    print_table("link: scene upload (median)", ["scene", "ms"],
                [(k, f"{v:.2f}") for k, v in payload["upload_ms"].items()])
    c = payload["contact_latency_ms"]
    if c["n"]:
        print(f"contact event latency (device tick → host, above the fastest STATUS frame): "
              f"median {c['p50']:.2f} ms, max {c['max']:.2f} ms over {c['n']} contacts")
    if fz:
        print(f"fuzz: {fz.frames} frames, {fz.mutated} mutated → {fz.accepted_corrupt} corrupt "
              f"frames accepted, {fz.intact_lost} clean frames lost after corruption")
    return 0


def _start(*args: str) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen([sys.executable, "-m", "app", "device", "emulate", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    return proc, proc.stdout.readline().strip()


def _window_figures(port: str, n_windows: int) -> dict:
    """PING, ESTOP-to-zero, trace streaming and the window-end-to-rating wait on one port.

    Device events are put on the host's clock with the offset of the fastest STATUS frame
    (host receive time − device time, minimum over the run), so a latency derived from it
    is an upper bound: it includes the fastest frame's one-way delay."""
    from device import open_device
    from device.suite import SUITE_SCENES

    with open_device(f"serial:{port}") as dev:
        for _ in range(50):
            dev.ping()
        rtt = np.array([dev.ping() for _ in range(1000)])
        offsets: list[float] = []

        def note(*_):
            if dev.last_status is not None:
                offsets.append(dev.last_status[0] - dev.last_status[1])

        waits, rates, zero, ack = [], [], [], []
        for _ in range(n_windows):  # window end → traces in hand (the rating can be asked)
            dev.load_scene(SUITE_SCENES["firm_spring"])
            dev.home()
            t_start = time.perf_counter()
            res = dev.run_window(1.0, from_first_contact=False, on_progress=note)
            t_back = time.perf_counter()
            note()
            n = len(res.traces["t"])
            t_end_host = min(offsets) + res.traces["t"][0] + n / res.rate_hz
            waits.append(t_back - t_end_host)
            rates.append(n / (t_back - t_start))
        for _ in range(n_windows):  # ESTOP during a streaming window → output zero
            dev.load_scene(SUITE_SCENES["pulse_firm"])
            dev.home()
            sent: list[float] = []

            def stop(t, _p, sent=sent):
                note()
                if t >= 0.3 and not sent:
                    sent.append(time.perf_counter())
                    dev.estop()
                    ack.append(time.perf_counter() - sent[0])

            res = dev.run_window(1.0, from_first_contact=False, on_progress=stop)
            if res.faults and sent:
                zero.append(min(offsets) + res.faults[0].t - sent[0])
            dev.clear_fault()
        rate = dev.info.servo_rate_hz
        version = dev.link.version
    ms = lambda a, q: float(np.percentile(a, q) * 1e3)  # noqa: E731
    if zero and min(zero) < 0:
        # a zeroing before its ESTOP was sent: the device's clock runs ahead of its frames
        # (the Python emulator computes its servo 1 ms ahead of the wall clock and sends
        # STATUS from there), so this upper bound cannot be formed
        zero = []
    return {"protocol": version,
            "rtt_ms": {"p50": ms(rtt, 50), "p99": ms(rtt, 99), "n": int(rtt.size)},
            "estop_to_zero_ms": {"p50": ms(zero, 50), "max": float(max(zero) * 1e3),
                                 "n": len(zero), "servo_tick_ms": 1e3 / rate} if zero else None,
            "estop_ack_ms": {"p50": ms(ack, 50), "max": float(max(ack) * 1e3)} if ack else None,
            "stream_records_per_s": float(np.median(rates)),
            "stream_kB_per_s": float(np.median(rates) * 7 * 4 / 1e3),
            "window_end_to_traces_ms": {"p50": ms(waits, 50), "max": float(max(waits) * 1e3),
                                        "n": len(waits)}}


def firmware_main(args) -> int:
    """``hapticlab bench link --firmware host``: the figures over the host-built firmware
    (protocol 2, traces streamed), with the Python emulator (protocol 2 too, its servo in
    Python) measured the same way in the same process as the baseline."""
    rows = {}
    for label, emu_args in (("firmware (host build, v2)", ("--firmware", args.firmware,
                                                              "--seed", "3")),
                            ("Python emulator (v2), baseline", ("--seed", "3"))):
        proc, port = _start(*emu_args)
        try:
            rows[label] = _window_figures(port, max(5, args.repeats))
        finally:
            proc.terminate()
            proc.wait(timeout=10)
    fw, base = rows.values()
    payload = {"firmware": fw, "baseline_python_emulator": base,
               "window_end_wait_ratio_p50": fw["window_end_to_traces_ms"]["p50"]
               / base["window_end_to_traces_ms"]["p50"],
               "goal_window_end_wait_ms": 50.0}
    if args.json:
        emit(payload, True)
        return 0
    table = []
    for label, r in rows.items():
        z = r["estop_to_zero_ms"]
        w = r["window_end_to_traces_ms"]
        table.append((label, f"{r['rtt_ms']['p50']:.3f} / {r['rtt_ms']['p99']:.3f}",
                      f"{z['p50']:.2f} / {z['max']:.2f}" if z else "not formed",
                      f"{r['stream_records_per_s']:.0f} ({r['stream_kB_per_s']:.0f} kB/s)",
                      f"{w['p50']:.1f} / {w['max']:.1f}"))
    print_table("link over the firmware vs the Python emulator (medians / worst)",
                ["device", "PING p50/p99 [ms]", "ESTOP→zero p50/max [ms]",
                 "trace records/s", "window end → traces [ms]"], table)
    print(f"window end → traces, firmware / Python emulator (p50): "
          f"{payload['window_end_wait_ratio_p50']:.3f}×; goal ≤ 50 ms: "
          f"{'met' if fw['window_end_to_traces_ms']['max'] <= 50 else 'NOT met'} (worst case)")
    return 0
