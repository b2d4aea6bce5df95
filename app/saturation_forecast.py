"""``hapticlab device check``: before test day, how often would each virtual sample saturate?

The simulated tapper (incoming speeds around 0.11 ± 0.033 m/s, SPEC §1) taps each virtual
sample of the protocol on a simulated device with the *target* device's ratings (current
limit, force constant, effective mass, servo rate); the share of taps and of trials that
saturate is reported, with a warning above ``warn`` of trials.
"""

from __future__ import annotations

__all__ = ["saturation_check"]


def saturation_check(protocol, info, windows: int = 12, seed: int = 0, warn: float = 0.2,
                     velocity_mean: float = 0.11, velocity_sd: float = 0.033,
                     say=print) -> list[dict]:
    """Per virtual sample: taps, saturating taps and trials (5-s windows) with a saturation."""
    from device import SimulatedHand
    from device.sim.backend import SimDevice

    from .libraries import LIBRARY_SEED, prepare_libraries, with_libraries

    hand = SimulatedHand(tap_speed=velocity_mean, tap_speed_sd=velocity_sd)
    twin = SimDevice.with_ratings(info, seed=seed)
    # matched samples play a library built on the simulated twin (announced when built)
    libs = prepare_libraries(protocol, twin, "sim", say=say,
                             opener=lambda: SimDevice.with_ratings(info, seed=LIBRARY_SEED))
    protocol = with_libraries(protocol, libs)
    rows = []
    for sid, sample in protocol.samples.items():
        if sample.is_real or sample.scene.transient is None or not sample.rated:
            continue
        dev = SimDevice.with_ratings(info, seed=seed)
        dev.set_simulated_hand(hand)
        dev.load_scene(sample.scene)
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
