"""``hapticlab bench matching``: acceleration matching, speed against accuracy.

Tables (all on the simulated device, 10 kHz, targets = recorded wood_on_foam taps).
Tables 1 and 2 record and play without accelerometer noise, so that they measure the
methods rather than the sensor (with 0.3 m/s² noise every method floors near 0.5,
the noise in the recorded targets); table 3 varies the noise.

1. model order (2…8) × inversion method → in-window error of the acceleration the
   *device* produces when the force is played (hand holding the stylus, free air),
   against the conditioned target; the model's own prediction error; time per transient.
   Baseline in the same process: the ``windowed`` method, a dense regularized
   least-squares solve (Toeplitz matrix of the model's impulse response); the others'
   time is reported as a ratio to it.
2. library size (3…40) × blend (nearest, two-nearest linear, single scaled) → error of
   the played force against held-out taps (other recordings) at their speeds, and the
   bytes the device must hold.
3. ETFE estimator × accelerometer noise → dB / degree error against the true plant.
4. scene_match: spectral distance (device.matching.compare) of every virtual realism
   scene to real wood_on_foam taps.
"""

from __future__ import annotations

import time

import numpy as np

from ._common import emit, print_table

ORDERS = (2, 3, 4, 5, 6, 7, 8)
SIZES = (3, 5, 8, 12, 20, 40)
BLENDS = ("nearest", "linear", "scale")
NOISES = (0.1, 0.3, 1.0, 3.0)


def _rel_degree(order: int) -> int:
    return min(4, order - 2)


PREROLL = 0.1  # s of zero command first, so the 50-ms enable ramp has finished


def _played_error(dev, force: np.ndarray, target: np.ndarray, skip: float = 0.0) -> float:
    """Play ``force`` on the device (hand holding the stylus) and compare to ``target``.

    ``skip`` [s] leaves the first part of the window out of the comparison.
    """
    from device.matching.inversion import condition_target

    n0 = int(round(PREROLL * dev.info.servo_rate_hz))
    res = dev.play_force(np.concatenate([np.zeros(n0), force, np.zeros(200)]))
    a = res.traces["accel"][n0: n0 + len(target)]
    a = condition_target(a - res.traces["accel"][n0 - 50: n0].mean(), dev.info.servo_rate_hz)
    k = int(round(skip * dev.info.servo_rate_hz))
    return float(np.linalg.norm(a[k:] - target[k:]) / np.linalg.norm(target[k:]))


def main(args) -> int:
    from device.matching.compare import scene_distances
    from device.matching.inversion import METHODS, condition_target, discretize, invert
    from device.matching.library import (
        TransientLibrary,
        even_spread,
        record_taps,
        segment_taps,
    )
    from device.matching.sysid import (
        etfe,
        fit_transfer_function,
        identify_system,
        swept_sine,
        true_response,
    )
    from device.sim.backend import SimDevice
    from device.sim.params import DeviceParams
    from device.sim.plant import Y, build_plant
    from protocols import load_protocol

    proto = load_protocol("realism")
    source = proto.samples["wood_on_foam"].scene
    rate = 10_000.0
    idn = identify_system(SimDevice(seed=101))
    dev = SimDevice(seed=101, noise=False)
    train = segment_taps(record_taps(SimDevice(seed=202, noise=False), source, 12))
    held = segment_taps(record_taps(SimDevice(seed=303, noise=False), source, 4))
    targets = [t for t in train[:: max(1, len(train) // 8)]][:8]

    # 1. order × method
    order_rows = []
    for order in ORDERS:
        model = fit_transfer_function(idn.etfe, order, _rel_degree(order))
        dm = discretize(model, rate)
        for method in METHODS:
            errs, late_errs, pred_errs, times = [], [], [], []
            for tap in targets:
                tgt = condition_target(tap.accel, rate)
                t0 = time.perf_counter()
                inv = invert(dm, tap.accel, method)
                force, pe = inv.force, inv.in_window_error
                times.append(time.perf_counter() - t0)
                errs.append(_played_error(dev, force, tgt))
                late_errs.append(_played_error(dev, force, tgt, skip=0.005))
                pred_errs.append(pe)
            order_rows.append({"order": order, "relative_degree": _rel_degree(order),
                               "method": method, "played_error": float(np.median(errs)),
                               "played_error_after_5ms": float(np.median(late_errs)),
                               "model_error": float(np.median(pred_errs)),
                               "ms_per_transient": 1e3 * float(np.median(times)),
                               "fit_db_rms": model.err_db_rms, "fit_deg_rms": model.err_deg_rms})
    for r in order_rows:  # baseline: the dense windowed solve, same order
        base = next(b for b in order_rows if b["order"] == r["order"]
                    and b["method"] == "windowed")
        r["speedup_vs_windowed"] = base["ms_per_transient"] / r["ms_per_transient"]

    # 2. library size × blend, against held-out taps
    dm7 = discretize(idn.model, rate)
    size_rows = []
    vel = np.array([t.velocity for t in train])
    for size in SIZES:
        pick = even_spread(vel, size)
        forces = np.stack([invert(dm7, train[i].accel).force for i in pick])
        lib = TransientLibrary(vel[pick], forces, {})
        for blend in BLENDS:
            table = lib.table(1.0, blend)
            if blend == "scale":  # one entry, the median speed, scaled
                mid = int(np.argsort(vel[pick])[len(pick) // 2])
                from device import TransientTable

                table = TransientTable([vel[pick][mid]], forces[mid], "scale")
            errs = [_played_error(dev, table.force_at(h.velocity), condition_target(h.accel, rate))
                    for h in held]
            nbytes = lib.nbytes if blend != "scale" else forces.shape[1] * 4 + 4
            size_rows.append({"entries": size if blend != "scale" else 1, "from": size,
                              "blend": blend, "heldout_error": float(np.median(errs)),
                              "bytes": int(nbytes)})

    # 3. ETFE estimator × noise
    p = build_plant(dev.params, dev.hand)
    row = np.zeros(p.n_states + 3)
    row[Y] = 1.0
    etfe_rows = []
    sweep = swept_sine(rate, amplitude=1.0)
    for noise in NOISES:
        ndev = SimDevice(device=DeviceParams(accel_noise_rms=noise), seed=7)
        ys = []
        for _ in range(16):
            a = ndev.play_force(sweep.force).traces["accel"]
            ys.append(a - a[:10].mean())
        ys = np.array(ys)
        cases = {"raw ratio (1 run)": etfe(sweep.force, ys[:1], rate, smooth_hz=0),
                 "smoothed (1 run)": etfe(sweep.force, ys[:1], rate),
                 "polar average (4 runs)": etfe(sweep.force, ys[:4], rate, method="polar"),
                 "synchronous avg (4 runs)": etfe(sweep.force, ys[:4], rate),
                 "synchronous avg (16 runs)": etfe(sweep.force, ys, rate)}
        for name, est in cases.items():
            e = est.in_band((10.0, 500.0))
            Ht = true_response(p.A[0], p.B[0], row, e.freq, rate)
            r = e.H / Ht
            db = 20 * np.log10(np.abs(r))
            deg = np.degrees(np.angle(r))
            etfe_rows.append({"estimator": name, "noise": noise,
                              "db_rms": float(np.sqrt(np.mean(db**2))),
                              "db_max": float(np.max(np.abs(db))),
                              "deg_rms": float(np.sqrt(np.mean(deg**2))),
                              "deg_max": float(np.max(np.abs(deg)))})

    # 4. scene match
    virt = {k: s.scene for k, s in proto.samples.items() if not s.is_real}
    dist = scene_distances(lambda: SimDevice(seed=11), virt, source)
    match_rows = [{"scene": k, "kind": virt[k].kind, "distance_db": v}
                  for k, v in sorted(dist.items(), key=lambda kv: kv[1])]

    payload = {"order_method": order_rows, "library": size_rows, "etfe": etfe_rows,
               "scene_match": match_rows,
               "taps": {"train": len(train), "heldout": len(held), "targets": len(targets)}}
    if args.json:
        emit(payload, True)
        return 0
    print_table("matching: model order × inversion (median over 8 recorded wood_on_foam taps)",
                ["order", "rel. deg", "method", "played error", "after 5 ms", "model error",
                 "ms/transient",
                 "speed × windowed", "fit dB rms", "fit ° rms"],
                [(r["order"], r["relative_degree"], r["method"], f"{r['played_error']:.3f}",
                  f"{r['played_error_after_5ms']:.3f}", f"{r['model_error']:.3f}",
                  f"{r['ms_per_transient']:.2f}",
                  f"{r['speedup_vs_windowed']:.1f}", f"{r['fit_db_rms']:.2f}",
                  f"{r['fit_deg_rms']:.1f}") for r in order_rows])
    print_table(f"matching: library size × blend (error against {len(held)} held-out taps)",
                ["entries", "blend", "held-out error", "bytes on device"],
                [(r["entries"] if r["blend"] != "scale" else f"1 of {r['from']}", r["blend"],
                  f"{r['heldout_error']:.3f}", r["bytes"]) for r in size_rows])
    print_table("matching: ETFE estimator × accelerometer noise (error vs the true plant)",
                ["estimator", "noise [m/s²]", "dB rms", "dB max", "° rms", "° max"],
                [(r["estimator"], r["noise"], f"{r['db_rms']:.2f}", f"{r['db_max']:.2f}",
                  f"{r['deg_rms']:.1f}", f"{r['deg_max']:.1f}") for r in etfe_rows])
    print_table("scene_match: spectral distance to real wood_on_foam taps (RMS dB, 10–500 Hz)",
                ["scene", "kind", "distance [dB]"],
                [(r["scene"], r["kind"], f"{r['distance_db']:.2f}") for r in match_rows])
    return 0
