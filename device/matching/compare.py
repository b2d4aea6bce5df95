"""How close a scene's contact accelerations are to a real sample's: a spectral distance.

Signature of a set of taps: for each clean tap (:func:`~device.matching.library.segment_taps`,
100 ms from contact), the magnitude spectrum of the accelerometer window (Hann window,
zero-padded to 4096 points) divided by the tap's incoming speed, in dB; averaged over
taps. Distance between two signatures: the RMS of their dB difference over 10–500 Hz
(the band the device can render and acceleration matching targets). 0 dB means the
same spectral shape and level per unit speed; 6 dB is a factor of two on average.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene import Scene
from .library import record_taps, segment_taps

__all__ = ["Signature", "signature", "spectral_distance", "scene_distances", "Verification",
           "verify_library"]

NFFT = 4096
BAND = (10.0, 500.0)


@dataclass(frozen=True)
class Signature:
    """Mean speed-normalized acceleration spectrum [dB re 1 (m/s²)/(m/s)] of a set of taps."""

    freq: np.ndarray
    db: np.ndarray
    n_taps: int


def signature(results, window: float = 0.100) -> Signature:
    taps = segment_taps(results, window)
    if not taps:
        raise ValueError("no clean taps to build a spectral signature from")
    rate = results[0].rate_hz
    w = np.hanning(len(taps[0].accel))
    spec = [20 * np.log10(np.abs(np.fft.rfft(t.accel * w, NFFT)) / t.velocity + 1e-12)
            for t in taps]
    freq = np.fft.rfftfreq(NFFT, 1 / rate)
    keep = (freq >= BAND[0]) & (freq <= BAND[1])
    return Signature(freq[keep], np.mean(spec, axis=0)[keep], len(taps))


def spectral_distance(a: Signature, b: Signature) -> float:
    """RMS dB difference of two signatures over 10–500 Hz."""
    if a.freq.shape != b.freq.shape or not np.allclose(a.freq, b.freq):
        raise ValueError("signatures on different frequency grids (different servo rates?)")
    return float(np.sqrt(np.mean((a.db - b.db) ** 2)))


def scene_distances(make_device, scenes: dict[str, Scene], reference: Scene,
                    windows: int = 6) -> dict[str, float]:
    """Distance of each scene's taps to the reference's, on fresh devices from ``make_device``."""
    ref = signature(record_taps(make_device(), reference, windows))
    return {name: spectral_distance(signature(record_taps(make_device(), sc, windows)), ref)
            for name, sc in scenes.items()}


@dataclass(frozen=True)
class Verification:
    """How close a library's playback comes to the real sample it reproduces.

    Attributes
    ----------
    matched_db, spring_db : float [dB]
        Spectral distance to the real taps of taps on the matched scene, and on its spring
        alone (the same scene without the library: the baseline).
    matched_taps, spring_taps : int
        Clean taps each was computed from.
    """

    matched_db: float
    spring_db: float
    matched_taps: int
    spring_taps: int

    def verdict(self) -> str:
        """Against the distance scale: ≤ 3 dB is close (within a factor √2 in amplitude on
        average over 10–500 Hz), ≤ 6 dB fair (within a factor two), far above. The spring
        alone is the baseline measured the same way (on a sample whose low band the spring
        already matches, wood on foam, it can be the closer of the two): when it is no
        farther than the library, the verdict says the library gains nothing here."""
        if self.matched_db <= 3.0:
            grade = "close (≤ 3 dB: within a factor √2 on average)"
        elif self.matched_db <= 6.0:
            grade = "fair (≤ 6 dB: within a factor two on average)"
        else:
            grade = ("far (> 6 dB): check the identification (hapticlab device sysid --png "
                     "sysid.png) and rebuild with more --windows")
        if self.spring_db <= self.matched_db:
            grade += (f", and no closer than the spring alone ({self.spring_db:.1f} dB): the "
                      "library gains nothing measurable on this device")
        return grade


def verify_library(device, real_results, matched: Scene, spring: Scene, windows: int = 2,
                   **measure) -> Verification:
    """Tap ``matched`` (a scene playing the library) and ``spring`` (the same without it) for
    ``windows`` windows each and compare both with the real taps ``real_results`` (the
    build's recordings). ``measure`` goes to :func:`record_taps` (``on_fault``, ``pace``)."""
    ref = signature(real_results)
    m = signature(record_taps(device, matched, windows, **measure))
    s = signature(record_taps(device, spring, windows, **measure))
    return Verification(spectral_distance(m, ref), spectral_distance(s, ref), m.n_taps,
                        s.n_taps)
