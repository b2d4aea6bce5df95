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
