"""``hapticlab bench accuracy``: what the servo rate costs and what it buys, scene by scene.

Rows: every scene of the built-in protocols (``protocols.BUILTIN``) × tap × servo rate (1,
2, 4, 5, 10 and 20 kHz), each against the same scene and tap simulated at 100 kHz. The taps
are single taps at 0.05, 0.11 and 0.25 m/s (the papers' range: SPEC §1 reports 0.11 ± 0.033
m/s), and ``people``: a 3-s window of taps drawn from the simulated participants'
population, N(0.11, 0.033²) m/s (:class:`device.sim.tapper.Tapper`'s defaults), the same
taps at every rate (one seed). Per row, with no sensor noise:

* ``accel_err``: ‖a − a_ref‖₂ / ‖a_ref‖₂ of the true tip acceleration over the window,
  compared at the coarse rate's tick times;
* ``accel_peak_err``: the signed relative error of the window's peak |a|;
* ``force_peak_err``: the same for the force the device renders (``force_out``); none
  for a real sample, which the device does not render;
* ``jnd``: how differently the simulated participant feels the window: the distance
  between the felt features (:func:`app.participant_model.felt_features`: stop, jolt,
  pitch, ring) at this rate and at 100 kHz, in the model's just-noticeable differences
  (``JND``); 1 is the smallest difference the model's person notices on average;
* ``realtime_factor``: simulated seconds per wall second of the window at this rate,
  the median of ``--repeats`` runs (the ratio against the same window at 100 kHz, timed in
  the same process, is printed beside it).

The matched samples' libraries are built on each rate's simulated device first (in a
temporary store, unless ``HAPTICLAB_LIBRARIES`` is set). The summary gives, per scene,
the lowest rate at which every tap is felt within 1 JND of the reference, and the worst
row of each kind at each rate.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ._common import emit, library_store, median_time, print_table

RATES = (1_000, 2_000, 4_000, 5_000, 10_000, 20_000)
REF_RATE = 100_000
#: single-tap speeds [m/s]; ``people`` is the participants' distribution
TAPS = (0.05, 0.11, 0.25, "people")
ONE_TAP_S = 0.35  # s from the first contact: felt_features looks up to 225 ms past it
PEOPLE_S = 3.0
PEOPLE_SEED = 3
#: the felt difference a person notices on average [JND units]
NOTICEABLE = 1.0


def _device(scene, rate: float, tap, seed: int = PEOPLE_SEED):
    from device.sim.backend import SimDevice
    from device.sim.params import DeviceParams
    from device.sim.tapper import Tapper

    tapper = (Tapper() if tap == "people"
              else Tapper(velocity_mean=float(tap), velocity_sd=0.0, dwell=(0.5, 0.5)))
    dev = SimDevice(device=DeviceParams().with_rate(rate), tapper=tapper, noise=False,
                    seed=seed)
    dev.load_scene(scene)
    return dev


def _window(scene, rate: float, tap):
    dev = _device(scene, rate, tap)
    span = PEOPLE_S if tap == "people" else ONE_TAP_S

    def once():
        dev.reseed(dev.seed)  # every repeat the same taps: the timed windows are the same
        dev.home()
        return dev.run_window(span)

    return once


def _on_ticks(t: np.ndarray, t_ref: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """``ref`` (sampled at ``t_ref``, :data:`REF_RATE`) at the times ``t`` of a coarser rate
    that divides it; NaN where the reference has no sample at that instant (to 1e-3 of its
    period: device times are whole ticks)."""
    k = np.rint((t - t_ref[0]) * REF_RATE).astype(np.int64)
    near = np.abs(t_ref[np.clip(k, 0, len(ref) - 1)] - t) < 1e-3 / REF_RATE
    ok = (k >= 0) & (k < len(ref)) & near
    out = np.full(len(t), np.nan)
    out[ok] = ref[k[ok]]
    return out


def _peak_err(x: np.ndarray, ref: np.ndarray) -> float:
    p_ref = float(np.max(np.abs(ref))) if ref.size else 0.0
    if not p_ref > 0:
        return math.nan
    return float(np.max(np.abs(x))) / p_ref - 1.0


def compare(res, ref, real: bool) -> dict:
    """Errors of window ``res`` against the reference window ``ref`` (see the module
    docstring); a value that cannot be defined is NaN and printed in words."""
    from app.participant_model import JND, felt_features

    t, tr, tr_ref = res.traces["t"], res.traces, ref.traces
    a_ref = _on_ticks(t, tr_ref["t"], tr_ref["true_accel"])
    ok = np.isfinite(a_ref)
    a, a_ref = tr["true_accel"][ok], a_ref[ok]
    norm = float(np.linalg.norm(a_ref))
    out = {"accel_err": float(np.linalg.norm(a - a_ref)) / norm if norm > 0 else math.nan,
           "accel_peak_err": _peak_err(a, a_ref)}
    if real:
        out["force_peak_err"] = math.nan
    else:
        f_ref = _on_ticks(t, tr_ref["t"], tr_ref["force_out"])[ok]
        out["force_peak_err"] = _peak_err(tr["force_out"][ok], f_ref)
    f, f0 = felt_features(res), felt_features(ref)
    both = np.isfinite(f) & np.isfinite(f0)
    out["jnd"] = (float(np.sqrt(np.sum(((f[both] - f0[both]) / JND[both]) ** 2)))
                  if both.any() else math.nan)
    out["contacts"] = len(res.contacts)
    out["contacts_ref"] = len(ref.contacts)
    return out


def samples() -> list[tuple[str, object]]:
    """(protocol/sample, scene) of every scene of the built-in protocols, each once."""
    from .energy import samples as every

    return every()


def measure(scenes, rates=RATES, taps=TAPS, repeats: int = 3) -> list[dict]:
    """Every row of the benchmark for ``scenes`` ((name, scene) pairs)."""
    rows = []
    for name, sc in scenes:
        for tap in taps:
            ref_once = _window(sc, REF_RATE, tap)
            ref = ref_once()
            ref_wall = median_time(ref_once, repeats)
            for rate in rates:
                once = _window(sc, rate, tap)
                res = once()
                wall = median_time(once, repeats)
                sim_s = len(res.traces["t"]) / rate
                row = {"scene": name, "kind": sc.kind, "tap": tap, "rate_hz": rate,
                       "realtime_factor": sim_s / wall,
                       "cost_vs_ref": wall / ref_wall,
                       "faults": [f.code for f in res.faults], "warnings": list(res.warnings)}
                row.update(compare(res, ref, sc.is_real))
                rows.append(row)
    return rows


def lowest_rate(rows: list[dict], scene: str) -> float | None:
    """The lowest rate at which every tap of ``scene`` is felt within :data:`NOTICEABLE` of
    the reference (and at every higher rate measured too); None if no rate is."""
    ok = {}
    for r in rows:
        if r["scene"] == scene:
            ok.setdefault(r["rate_hz"], True)
            ok[r["rate_hz"]] &= math.isfinite(r["jnd"]) and r["jnd"] < NOTICEABLE
    best = None
    for rate in sorted(ok, reverse=True):
        if not ok[rate]:
            break
        best = rate
    return best


def _worst(values) -> float:
    """The largest of ``values``; NaN (not felt, undefined) if any is."""
    values = list(values)
    if not values or any(not math.isfinite(v) for v in values):
        return math.nan
    return max(values)


def _pct(x: float) -> str:
    return "undefined" if not math.isfinite(x) else f"{100 * x:+.1f} %"


def _num(x: float, fmt: str) -> str:
    return "not felt" if not math.isfinite(x) else format(x, fmt)


def main(args) -> int:
    from .energy import with_libraries

    with library_store("hapticlab-accuracy-"):
        scenes = samples()
        t0 = time.perf_counter()
        for rate in (*RATES, REF_RATE):
            with_libraries(scenes, rate)
        rows = measure(scenes, repeats=args.repeats)
        wall = time.perf_counter() - t0
    names = list(dict.fromkeys(r["scene"] for r in rows))
    lowest = {n: lowest_rate(rows, n) for n in names}
    payload = {"rows": rows, "lowest_rate_within_1_jnd": lowest, "ref_rate_hz": REF_RATE,
               "repeats": args.repeats, "seconds": wall}
    if args.json:
        emit(payload, True)
        return 0
    print_report(payload)
    return 0


def print_report(payload: dict) -> None:
    """The benchmark's tables from its JSON payload."""
    rows, lowest = payload["rows"], payload["lowest_rate_within_1_jnd"]
    names = list(lowest)
    worst = []
    kinds = list(dict.fromkeys(r["kind"] for r in rows))
    for kind in kinds:
        for tap in TAPS:
            for rate in RATES:
                sel = [r for r in rows if r["kind"] == kind and r["tap"] == tap
                       and r["rate_hz"] == rate]
                j = max(sel, key=lambda r: r["jnd"] if math.isfinite(r["jnd"]) else math.inf)
                a = max(sel, key=lambda r: r["accel_err"])
                rt = float(np.median([r["realtime_factor"] for r in sel]))
                worst.append((kind, tap, rate, f"{100 * a['accel_err']:.1f} % ({a['scene']})",
                              f"{_num(j['jnd'], '.2f')} ({j['scene']})",
                              _pct(max((r["force_peak_err"] for r in sel
                                        if math.isfinite(r["force_peak_err"])),
                                       key=abs, default=math.nan)),
                              f"{rt:.0f}"))
    print_table(f"accuracy against {REF_RATE // 1000} kHz: the worst scene of each kind "
                f"(every scene of the built-in protocols; taps in m/s, 'people' = N(0.11, 0.033²))",
                ["kind", "tap", "rate [Hz]", "accel error (worst)", "JND (worst)",
                 "peak force (worst)", "× real time (median)"], worst)
    print_table(f"lowest rate at which every tap is felt within {NOTICEABLE:g} JND of "
                f"{REF_RATE // 1000} kHz",
                ["scene", "kind", "lowest rate", "JND at 1 kHz (worst tap)",
                 "JND at 10 kHz (worst tap)"],
                [(n, next(r["kind"] for r in rows if r["scene"] == n),
                  "none measured" if lowest[n] is None else f"{lowest[n]:,} Hz",
                  _num(_worst(r["jnd"] for r in rows if r["scene"] == n
                              and r["rate_hz"] == 1_000), ".2f"),
                  _num(_worst(r["jnd"] for r in rows if r["scene"] == n
                              and r["rate_hz"] == 10_000), ".2f"))
                 for n in names])
    print(f"{len(rows)} rows in {payload['seconds']:.0f} s; timings are medians of "
          f"{payload['repeats']} repeats")
