"""``hapticlab device check``: before test day, how often would each virtual sample saturate?

The simulated tapper (incoming speeds around 0.11 ± 0.033 m/s, SPEC §1) taps each virtual
sample of the protocol on a simulated device with the *target* device's ratings (current
limit, force constant, effective mass, servo rate); the share of taps and of trials that
saturate is reported, with a warning above ``warn`` of trials.
"""

from __future__ import annotations

from dataclasses import replace

__all__ = ["saturation_check"]


def saturation_check(protocol, info, windows: int = 12, seed: int = 0, warn: float = 0.2,
                     velocity_mean: float = 0.11, velocity_sd: float = 0.033) -> list[dict]:
    """Per virtual sample: taps, saturating taps and trials (5-s windows) with a saturation."""
    from device.sim.backend import SimDevice
    from device.sim.params import DeviceParams
    from device.sim.tapper import Tapper

    params = replace(DeviceParams(), servo_rate_hz=float(info.servo_rate_hz),
                     current_limit=float(info.current_limit),
                     force_constant=float(info.force_constant),
                     motor_mass=max(1e-4, float(info.effective_mass) - DeviceParams().tip_mass))
    rows = []
    for sid, sample in protocol.samples.items():
        if sample.is_real or sample.scene.transient is None or not sample.rated:
            continue
        dev = SimDevice(device=params, seed=seed,
                        tapper=Tapper(velocity_mean=velocity_mean, velocity_sd=velocity_sd))
        try:
            dev.load_scene(sample.scene)
        except Exception as exc:  # e.g. a library only the real device can provide
            rows.append({"sample": sid, "error": str(exc)})
            continue
        taps = sat_taps = sat_trials = 0
        for _ in range(windows):
            dev.home()
            res = dev.run_window(protocol.window.duration)
            taps += len(res.contacts)
            starts = [s.t for s in res.saturations]
            sat_taps += sum(any(0 <= s - c.t < 0.3 for s in starts) for c in res.contacts)
            sat_trials += bool(res.saturations)
        rows.append({"sample": sid, "taps": taps, "saturating_taps": sat_taps,
                     "tap_rate": sat_taps / taps if taps else float("nan"),
                     "trial_rate": sat_trials / windows,
                     "warning": sat_trials / windows > warn})

    return rows
