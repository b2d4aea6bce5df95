"""Fitting decaying-sinusoid vibration models Q = A·v·e^(−Bt)·sin(2πft) to recorded taps.

Following SPEC §2: the frequency f from the FFT peak, the decay rate B from the envelope,
and the slope A from the amplitude against incoming speed.

1. f: peak of the mean magnitude spectrum of the taps inside ``band``, refined by a
   parabola through the log-magnitudes of the peak bin and its neighbours.
2. Envelope: each tap is lightly band-passed (zero-phase, 0.4·f to 3·f, removing the
   contact's slow deceleration and sensor noise); the extremum of every half cycle,
   refined by a parabola, samples the envelope. A narrow band-pass and a Hilbert
   envelope instead smear short decays (−10 % to −35 % on B in tests).
3. B: one straight line ln(|extremum| / v) = c_i − B·t fitted jointly over all taps
   (a common decay, one intercept per tap), from each tap's first extremum above ``floor``
   of its largest down to the floor, stopping where the extrema grow again (another
   motion — the contact's own oscillation, a bounce — has taken over); a tap whose
   envelope grows first is left out, unless fewer than two taps are left, when every tap
   is taken from its largest extremum (``VibrationFit.start``).
4. A: each tap's amplitude at contact from its intercept, undoing (i) the extrema
   sitting at sin = ω/√(ω² + B²) rather than 1, and, when the accelerometer's bandwidth
   is given, (ii) its gain |H(f)| and (iii) its phase delay τ at f (the envelope read at
   t is the vibration's at t − τ); then regressed on speed through the origin. Its sign
   from the first extremum: a push out of the surface first gives A < 0, the normal
   velocity being negative.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

from .library import Tap

__all__ = ["VibrationFit", "fit_vibration", "butterworth2"]


@dataclass(frozen=True)
class VibrationFit:
    """Fitted model and the data behind it.

    Attributes
    ----------
    slope : float [1/s]
        A.
    decay : float [1/s]
        B.
    frequency : float [Hz]
        f.
    amplitudes, velocities : ndarray
        Per-tap amplitude at contact [m/s²] and incoming speed [m/s].
    start : str
        Where each tap's ring-down was taken from: ``"first"``, its first extremum above
        the floor (taps whose envelope grows first are left out); ``"peak"``, its largest,
        when fewer than two taps decay from the first (B then includes the contact's own
        decay after the peak: +12 % on wood tapped at one speed, measured).
    """

    slope: float
    decay: float
    frequency: float
    amplitudes: np.ndarray
    velocities: np.ndarray
    start: str = "first"

    def as_dict(self) -> dict:
        return {"slope": self.slope, "decay": self.decay, "frequency": self.frequency}


def butterworth2(f: float, bandwidth: float) -> tuple[float, float]:
    """Gain and phase delay [s] at ``f`` [Hz] of a 2nd-order Butterworth low-pass.

    ``bandwidth`` [Hz] is its −3 dB frequency.
    """
    s = 1j * f / bandwidth
    h = 1.0 / (s * s + math.sqrt(2.0) * s + 1.0)
    return abs(h), -np.angle(h) / (2 * math.pi * f)


def _extrema(x: np.ndarray, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """Time [s] and signed value of the largest |x| in each half cycle (parabola-refined)."""
    sign = np.sign(x)
    cuts = np.flatnonzero(np.diff(sign) != 0) + 1
    edges = np.concatenate([[0], cuts, [len(x)]])
    ts, vs = [], []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        if b - a < 1:
            continue
        k = a + int(np.argmax(np.abs(x[a:b])))
        if 0 < k < len(x) - 1:
            y0, y1, y2 = x[k - 1: k + 2]
            d = y0 - 2 * y1 + y2
            sh = 0.5 * (y0 - y2) / d if d != 0 else 0.0
            sh = float(np.clip(sh, -0.5, 0.5))
            ts.append((k + sh) / rate)
            vs.append(y1 - 0.25 * (y0 - y2) * sh)
        else:
            ts.append(k / rate)
            vs.append(x[k])
    return np.asarray(ts), np.asarray(vs)


def _ringdown(ts: np.ndarray, vs: np.ndarray, floor: float, start: str):
    """A tap's decaying extrema (times [s], values) and the sign of its first push, from
    its first extremum above ``floor`` of its largest, or from its largest (``start``
    ``"peak"``), to where they fall below the floor or grow again; None when fewer than
    two are left."""
    if ts.size == 0:
        return None
    big = np.abs(vs) >= floor * np.max(np.abs(vs))
    first = int(np.argmax(big))
    sign0 = float(np.sign(vs[first]))  # the first push's direction
    i = first if start == "first" else int(np.argmax(np.abs(vs)))
    ts, vs = ts[i:], vs[i:]
    keep = np.abs(vs) >= floor * np.max(np.abs(vs))
    last = int(np.flatnonzero(keep)[-1]) + 1
    # the vibration's envelope only decays: where an extremum grows again, another motion
    # (the contact's own oscillation, a bounce) has taken over
    grows = np.flatnonzero(np.abs(vs[1:last]) > 1.05 * np.abs(vs[:last - 1]))
    if grows.size:
        last = int(grows[0]) + 1
    if last < 2:
        return None
    return ts[:last], vs[:last], sign0


def fit_vibration(taps: list[Tap], rate_hz: float, band: tuple[float, float] = (20.0, 2000.0),
                  accel_bandwidth: float | None = None, floor: float = 0.1,
                  nfft: int = 8192) -> VibrationFit:
    """Fit (A, B, f) to taps (acceleration windows from contact, with incoming speeds).

    Parameters
    ----------
    taps : list of Tap
    rate_hz : float [Hz]
    band : (float, float) [Hz]
        Where to look for the vibration's frequency (above the contact's own dynamics).
    accel_bandwidth : float, optional [Hz]
        Bandwidth of the accelerometer (2nd-order Butterworth) whose gain and delay at f
        are undone.
    floor : float
        Extrema below this fraction of a tap's largest are left out of the fit.
    """
    if len(taps) < 2:
        raise ValueError(f"need at least 2 taps to fit a slope, got {len(taps)}")
    n = len(taps[0].accel)
    w = np.hanning(n)
    spec = np.mean([np.abs(np.fft.rfft(t.accel * w, nfft)) for t in taps], axis=0)
    freq = np.fft.rfftfreq(nfft, 1 / rate_hz)
    hi = min(band[1], 0.45 * rate_hz)
    sel = np.flatnonzero((freq >= band[0]) & (freq <= hi))
    k = int(sel[np.argmax(spec[sel])])
    y0, y1, y2 = np.log(spec[k - 1: k + 2] + 1e-300)
    d = y0 - 2 * y1 + y2
    f = float(freq[k] + (0.5 * (y0 - y2) / d if d != 0 else 0.0) * (freq[1] - freq[0]))

    sos = signal.butter(2, (0.4 * f, min(3 * f, 0.45 * rate_hz)), btype="bandpass", fs=rate_hz,
                        output="sos")
    # each tap's ring-down from its first extremum above the floor; if fewer than two taps
    # decay from there (taps at one speed, all alike, whose ringing builds up over the first
    # cycle: each ended where it grew, and none was left, issue 34), from each tap's largest
    # extremum instead, which the fit then says (``start``)
    filtered = [(tap, *_extrema(signal.sosfiltfilt(sos, tap.accel), rate_hz))
                for tap in taps if tap.velocity > 0]
    for start in ("first", "peak"):
        picked = [(tap, r) for tap, ts, vs in filtered
                  if (r := _ringdown(ts, vs, floor, start)) is not None]
        if len(picked) >= 2:
            break
    else:
        raise ValueError(
            f"{len(picked)} of {len(taps)} taps hold a vibration that decays over at least two "
            f"half cycles inside {band[0]:g}–{hi:g} Hz (the strongest at {f:.0f} Hz; "
            f"{len(taps) - len(filtered)} without an incoming speed; in the others the "
            f"band-passed acceleration grows again, or falls below {floor:g} of its largest, "
            f"one half cycle after it); a slope needs 2")
    rows, cols, vals, first_sign, vels = [], [], [], [], []
    for j, (tap, (ts, vs, sign0)) in enumerate(picked):
        first_sign.append(sign0)
        vels.append(tap.velocity)
        for t, v in zip(ts, vs, strict=True):
            rows.append(j)
            cols.append(t)
            vals.append(math.log(abs(v) / tap.velocity))
    m = len(vels)
    # joint least squares: ln|x|/v = c_j − B·t
    M = np.zeros((len(vals), m + 1))
    M[np.arange(len(vals)), rows] = 1.0
    M[:, m] = -np.asarray(cols)
    sol, *_ = np.linalg.lstsq(M, np.asarray(vals), rcond=None)
    B = float(sol[m])
    c = sol[:m]
    v = np.asarray(vels)
    w_ = 2 * math.pi * f
    amp = np.exp(c) * v * math.sqrt(w_**2 + B**2) / w_
    if accel_bandwidth:
        gain, delay = butterworth2(f, accel_bandwidth)
        amp = amp * math.exp(-B * delay) / gain
    magnitude = float(np.sum(amp * v) / np.sum(v * v))
    sign = -1.0 if np.median(first_sign) >= 0 else 1.0
    return VibrationFit(sign * magnitude, B, f, amp, v, start)
