"""``hapticlab bench sim``: simulator speed versus accuracy.

Rows: scene × servo rate (1, 2, 5, 10, 20 kHz) →

* ``realtime_factor``: simulated seconds per wall second for a 5-s tap window
  (median of ``--repeats``), including the tapper, kernel and trace post-processing;
* ``us_per_tick``: wall microseconds per servo tick of that window;
* ``rel_error``: ‖a − a_ref‖₂ / ‖a_ref‖₂ of the true tip acceleration over one tap
  (5 ms before to 100 ms after contact, 0.11 m/s, no sensor noise) against the same
  tap simulated at 100 kHz, compared at the coarse rate's tick times;
* ``stable``: the window stays finite and bounded (|v| < 1 m/s).

Baseline, in the same process: the same tick loop interpreted by Python (numba's
``py_func``), timed on a 0.2-s window of the spring scene.

A second table gives the kernel-only cost per tick by scene kind (the tick loop runs
only what the scene needs: no rendering for real samples, no transient code for
springs). A third reports sampled-data realism per scene and rate: the coefficient of
restitution of one tap and the rigid-body passivity margin (see
:mod:`device.sim.metrics`), including a 10 kN/m virtual wall tapped at 0.05 m/s.
"""

from __future__ import annotations

import contextlib
import time

import numpy as np

from ._common import emit, median_time, print_table

RATES = (1_000, 2_000, 5_000, 10_000, 20_000)
REF_RATE = 100_000.0
SPEED_SCENES = ("wood", "wood_on_foam", "firm_spring", "pulse_firm", "sinusoid_firm")


def realism_scenes() -> dict:
    """The realism protocol's scenes by sample id (matched libraries linked to their source)."""
    from protocols import load_protocol

    return {k: s.scene for k, s in load_protocol("realism").samples.items()}


def _tap_accel(scene, rate_hz: float, speed: float = 0.11):
    from device.sim.backend import SimDevice
    from device.sim.params import DeviceParams
    from device.sim.tapper import Tapper

    tapper = Tapper(velocity_mean=speed, velocity_sd=0.0, dwell=(0.3, 0.3))
    dev = SimDevice(device=DeviceParams(servo_rate_hz=rate_hz), tapper=tapper, noise=False)
    dev.load_scene(scene)
    dev.home()
    r = dev.run_window(0.12)
    return r.traces["t"], r.traces["true_accel"], r.traces["true_position"]


def rel_error(scene, rate_hz: float) -> float:
    t_ref, a_ref, z_ref = _tap_accel(scene, REF_RATE)
    t, a, _ = _tap_accel(scene, rate_hz)
    i0 = int(np.argmax(z_ref < scene.surface_height))
    t_c = t_ref[i0]
    stride = int(round(REF_RATE / rate_hz))
    sel = (t >= t_c - 0.005) & (t <= t_c + 0.100)
    idx = np.flatnonzero(sel)
    ref = a_ref[idx * stride]
    return float(np.linalg.norm(a[idx] - ref) / np.linalg.norm(ref))


def window_run(scene, rate_hz: float, seed: int = 7):
    from device.sim.backend import SimDevice

    dev = SimDevice(rate_hz=rate_hz, seed=seed)
    dev.load_scene(scene)

    def once():
        dev.home()
        return dev.run_window(5.0)

    res = once()  # compile / warm caches
    return dev, once, res


@contextlib.contextmanager
def interpreted_kernel():
    """Swap the compiled kernel functions for their pure-Python originals."""
    from device.sim import kernel, tapper

    saved = {}
    for mod in (kernel, tapper):
        for name, obj in vars(mod).items():
            if hasattr(obj, "py_func"):
                saved[(mod, name)] = obj
                setattr(mod, name, obj.py_func)
    try:
        yield
    finally:
        for (mod, name), obj in saved.items():
            setattr(mod, name, obj)


def baseline_us_per_tick(scene) -> float:
    from device.sim.backend import SimDevice

    dev = SimDevice(rate_hz=10_000)
    dev.load_scene(scene)
    with interpreted_kernel():
        dev.home()
        t0 = time.perf_counter()
        r = dev.run_window(0.2, from_first_contact=False)
        wall = time.perf_counter() - t0
    return wall / len(r.traces["t"]) * 1e6


KIND_SCENES = ("wood", "foam", "firm_spring", "pulse_firm", "sinusoid_firm")


@contextlib.contextmanager
def kernel_timer(acc: dict):
    """Accumulate wall nanoseconds and ticks spent inside the compiled kernel only."""
    from device.sim import kernel

    compiled = kernel.run_ticks

    def timed(*a):
        t0 = time.perf_counter_ns()
        n_done = compiled(*a)
        acc["ns"] += time.perf_counter_ns() - t0
        acc["ticks"] += n_done - a[0]
        return n_done

    kernel.run_ticks = timed
    try:
        yield
    finally:
        kernel.run_ticks = compiled


def kernel_costs(scenes: dict, names, repeats: int) -> list[dict]:
    """Kernel-only ns per tick over a 5-s window at 10 kHz for each scene, interleaved.

    Every scene replays the same hand motion (same seed) in each round, so the cost
    difference to the spring-only scene is paired: ``extra_ns`` is the median of the
    per-round differences and ``frac_slower`` how often the scene was the slower one.
    """
    onces = {n: window_run(scenes[n], 10_000, seed=11)[1] for n in names}
    per: dict[str, list[float]] = {n: [] for n in names}
    for _ in range(max(11, 8 * repeats)):
        for n, once in onces.items():
            acc = {"ns": 0, "ticks": 0}
            with kernel_timer(acc):
                once()
            per[n].append(acc["ns"] / acc["ticks"])
    ref = np.asarray(per["firm_spring"])
    out = []
    for n in names:
        a = np.asarray(per[n])
        d = a - ref
        out.append({"scene": n, "kind": scenes[n].kind, "ns_per_tick": float(np.median(a)),
                    "extra_ns_vs_spring": float(np.median(d)),
                    "frac_slower_than_spring": float(np.mean(d > 0)) if n != "firm_spring"
                    else float("nan")})
    return out


def main(args) -> int:
    from device import Scene
    from device.sim.metrics import passivity_margin, restitution
    from device.sim.params import DeviceParams, HandParams

    scenes = realism_scenes()
    rows = []
    for name in SPEED_SCENES:
        sc = scenes[name]
        for rate in RATES:
            dev, once, res = window_run(sc, rate)
            wall = median_time(once, args.repeats)
            n = len(res.traces["t"])
            sim_s = n / rate
            v = res.traces["true_velocity"]
            stable = bool(np.all(np.isfinite(v)) and np.max(np.abs(v)) < 1.0)
            rows.append({"scene": name, "kind": sc.kind, "rate_hz": rate,
                         "realtime_factor": sim_s / wall, "us_per_tick": wall / n * 1e6,
                         "rel_error": rel_error(sc, rate), "stable": stable})
    base = baseline_us_per_tick(scenes["firm_spring"])
    spring10 = next(r for r in rows if r["scene"] == "firm_spring" and r["rate_hz"] == 10_000)
    baseline = {"what": "interpreted tick loop, firm_spring, 10 kHz",
                "us_per_tick": base, "speedup": base / spring10["us_per_tick"]}

    hand = HandParams()
    bounce = []
    wall_scene = Scene("wall_10kN", spring=10_000.0)
    # matched samples are left out here: their library is built per device (and per rate)
    # and plays a pulse-like table; the other transients stand for them
    for name, sc, speed in ([(n, scenes[n], 0.11) for n in scenes if scenes[n].kind != "library"]
                            + [("wall_10kN", wall_scene, 0.05)]):
        for rate in RATES:
            r = restitution(sc, rate, speed=speed)
            bounce.append({"scene": name, "rate_hz": rate, "speed": speed, "restitution": r.e,
                           "passivity_margin": passivity_margin(
                               sc, DeviceParams(servo_rate_hz=rate), hand)})

    work = kernel_costs(scenes, KIND_SCENES, args.repeats)

    payload = {"rows": rows, "baseline": baseline, "restitution": bounce,
               "work_by_kind": work, "repeats": args.repeats}
    if args.json:
        emit(payload, True)
        return 0
    print_table("sim: speed vs accuracy (5-s window; error vs 100 kHz on one 0.11 m/s tap)",
                ["scene", "kind", "rate [Hz]", "× real time", "µs/tick", "rel. error", "stable"],
                [(r["scene"], r["kind"], r["rate_hz"], f"{r['realtime_factor']:.0f}",
                  f"{r['us_per_tick']:.3f}", f"{r['rel_error']:.2e}",
                  "yes" if r["stable"] else "NO") for r in rows])
    print(f"baseline ({baseline['what']}): {base:.2f} µs/tick; compiled loop is "
          f"{baseline['speedup']:.0f}× faster (median of {args.repeats} repeats)")
    print_table("sim: per-tick work by scene kind (kernel only, 10 kHz, 5-s window)",
                ["scene", "kind", "ns/tick (median)", "extra ns vs spring (paired)",
                 "rounds slower than spring"],
                [(w["scene"], w["kind"], f"{w['ns_per_tick']:.1f}",
                  f"{w['extra_ns_vs_spring']:+.2f}",
                  "—" if w["scene"] == "firm_spring"
                  else f"{100 * w['frac_slower_than_spring']:.0f} %") for w in work])
    print_table("sim: sampled-data realism (restitution e of one tap; margin b − K·T/2)",
                ["scene", "rate [Hz]", "tap [m/s]", "e", "margin [N·s/m]"],
                [(b["scene"], b["rate_hz"], b["speed"], f"{b['restitution']:.3f}",
                  f"{b['passivity_margin']:.2f}") for b in bounce])
    return 0
