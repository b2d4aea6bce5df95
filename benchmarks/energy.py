"""``hapticlab bench energy``: does any simulated sample give the stylus more than it took?

Rows: every sample of the built-in protocols (``protocols.BUILTIN``) × servo rate (1, 10, 20
kHz), each a 30-s window of taps sweeping 0.02–0.4 m/s
(:func:`device.sim.audit.energy_audit`): energy the stylus put into the actuator and the
sample, energy they gave back, the largest restitution of single taps at 0.02, 0.11 and 0.4
m/s, the fastest arrival at the surface and the fastest departure from it (true tip speeds),
the device's own estimate of the fastest contact, the fastest intended tap, and the verdict.
Every real sample must be passive; a virtual scene's verdict says when and why it is active.

Baseline, in the same process: a lossless real contact (70 kN/m, no damping) audited the
same way. It stores and returns energy without loss, so its out/in is what the accounting
itself reads for a perfectly elastic sample; every other row's out/in is printed beside it.
The matched samples' libraries are built on each rate's simulated device first (in a
temporary store, unless ``HAPTICLAB_LIBRARIES`` is set).
"""

from __future__ import annotations

import time

from ._common import emit, library_store, print_table

RATES = (1_000, 10_000, 20_000)
WINDOW_S = 30.0


def samples() -> list[tuple[str, object]]:
    """(protocol/sample, scene) of every sample of the built-in protocols, each scene once."""
    from protocols import BUILTIN, load_protocol

    out, seen = [], set()
    for name in BUILTIN:
        for sid, s in load_protocol(name).samples.items():
            if s.scene not in seen:
                seen.add(s.scene)
                out.append((f"{name}/{sid}", s.scene))
    return out


def with_libraries(scenes, rate: float) -> list:
    """The scenes, with each library transient's library built on this rate's simulated
    device (any rate :class:`~device.sim.params.DeviceParams` allows, 100 kHz included)."""
    from device import LibraryTransient
    from device.matching.library import build_into_store, find_library
    from device.sim.backend import SimDevice
    from device.sim.params import DeviceParams

    dev = SimDevice(device=DeviceParams().with_rate(rate))
    for _, sc in scenes:
        t = sc.transient
        if isinstance(t, LibraryTransient) and find_library(dev.info, t) is None:
            build_into_store(dev, t.source_scene)
    return scenes


def main(args) -> int:
    from dataclasses import replace

    from device import Material, Scene
    from device.sim.audit import energy_audit

    with library_store("hapticlab-energy-"):
        scenes = samples()
        lossless = Scene("lossless_contact", material=Material(70_000.0, 0.0))
        rows, base = [], {}
        t0 = time.perf_counter()
        for rate in RATES:
            with_libraries(scenes, rate)
            b = energy_audit(lossless, rate, WINDOW_S)
            base[rate] = b.energy_out_j / b.energy_in_j
            for name, sc in scenes:
                r = energy_audit(replace(sc, name=name), rate, WINDOW_S)
                d = r.as_dict()
                d["out_over_in"] = r.energy_out_j / r.energy_in_j if r.energy_in_j else None
                d["lossless_out_over_in"] = base[rate]
                rows.append(d)
        wall = time.perf_counter() - t0
    real = [r for r in rows if r["kind"] == "real"]
    payload = {"rows": rows, "baseline": {"what": "lossless real contact, 70 kN/m",
                                          "out_over_in": base},
               "real_samples_passive": all(r["passive"] for r in real),
               "window_s": WINDOW_S, "seconds": wall}
    if args.json:
        emit(payload, True)
        return 0 if payload["real_samples_passive"] else 1
    print_table(f"energy audit: {WINDOW_S:g}-s windows of taps sweeping 0.02–0.4 m/s",
                ["sample", "kind", "rate [Hz]", "in [mJ]", "out [mJ]", "out/in",
                 "lossless out/in", "max e", "max contact [m/s]", "max rebound [m/s]",
                 "measured", "max tap [m/s]", "verdict"],
                [(r["scene"], r["kind"], int(r["rate_hz"]), f"{1e3 * r['energy_in_j']:.1f}",
                  f"{1e3 * r['energy_out_j']:.1f}", f"{r['out_over_in']:.3f}",
                  f"{r['lossless_out_over_in']:.4f}", f"{r['max_restitution']:.3f}",
                  f"{r['max_contact_speed']:.3f}", f"{r['max_rebound_speed']:.3f}",
                  f"{r['max_measured_contact_speed']:.3f}",
                  f"{r['max_tap_speed']:.3f}", r["verdict"])
                 for r in rows])
    n_real = len(real)
    ok = sum(r["passive"] for r in real)
    print(f"real samples passive: {ok} of {n_real} rows; {wall:.0f} s")
    return 0 if ok == n_real else 1
