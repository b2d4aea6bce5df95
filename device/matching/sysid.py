"""System identification from commanded force to measured acceleration.

1. :func:`swept_sine` — an exponential sweep over the band, extended beyond it with
   cosine fades (so the band's ends are not biased by the fade) and followed by
   silence (so the response has decayed inside the record).
2. :func:`identify_system` — plays the sweep on a device while the hand holds the stylus, at
   several force levels with repeats.
3. :func:`etfe` — empirical transfer function estimate: synchronous average of the
   repeats, ratio of DFTs smoothed over neighbouring frequencies, and the coherence
   across repeats.
4. :func:`fit_transfer_function` — a continuous-time model of chosen order, relative
   degree and delay, fitted over the band by Sanathanan–Koerner iterations, with its
   error in dB and degrees.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from ..errors import DeviceError
from .measure import OnFault, Pace, measured
from .record import BuildRecord

__all__ = ["Sweep", "swept_sine", "ETFE", "etfe", "TFModel", "fit_transfer_function",
           "identify_system", "SystemIdentification", "accel_at_every_tick", "sweep_seconds"]


@contextmanager
def accel_at_every_tick(device) -> Iterator[float]:
    """Record the accelerometer alone, at every servo tick, while the block runs (then
    every channel again). Matching divides spectra sample by sample at the servo rate, so
    a device that can only thin its traces out (a narrow link) is refused here rather than
    fitted wrongly.

    Yields
    ------
    float [Hz]
        The servo rate.

    Raises
    ------
    DeviceError
        The device cannot stream its accelerometer at every tick.
    """
    rate = float(device.info.servo_rate_hz)
    got = device.set_trace_channels(("accel",))
    try:
        if got < rate * (1 - 1e-9):
            raise DeviceError(f"{device.info.model}: its link carries the accelerometer at "
                              f"{got:g} Hz, not at every servo tick ({rate:g} Hz); "
                              "system identification and matching need every tick (a faster link: "
                              "USB, or a UART at a higher baud rate)")
        yield rate
    finally:
        device.set_trace_channels(None)


@dataclass(frozen=True)
class Sweep:
    """An excitation signal and its design.

    Attributes
    ----------
    force : ndarray [N]
        Samples at ``rate_hz``.
    rate_hz : float [Hz]
    band : tuple of float [Hz]
        Frequencies swept at full amplitude.
    """

    force: np.ndarray
    rate_hz: float
    band: tuple[float, float]


def swept_sine(rate_hz: float, band: tuple[float, float] = (10.0, 500.0),
               duration: float = 2.5, amplitude: float = 1.0, extend: float = 1.5,
               silence: float = 0.5) -> Sweep:
    """Exponential swept sine with extended, faded ends and trailing silence.

    Parameters
    ----------
    rate_hz : float [Hz]
        Sample rate (the servo rate).
    band : (float, float) [Hz]
        Band swept at full amplitude, in ``duration`` seconds.
    duration : float [s]
        Time spent inside the band.
    amplitude : float [N]
        Force amplitude.
    extend : float [1]
        The sweep starts at band[0]/extend and ends at band[1]·extend; the parts outside
        the band fade in and out with half cosines.
    silence : float [s]
        Zeros appended after the sweep.
    """
    f0, f1 = band
    if not (0 < f0 < f1 < rate_hz / 2):
        raise ValueError(f"band must satisfy 0 < f0 < f1 < rate/2, got {band} at {rate_hz} Hz")
    if extend < 1 or duration <= 0 or silence < 0:
        raise ValueError("need extend >= 1, duration > 0 s and silence >= 0 s")
    k = math.log(f1 / f0) / duration  # rate of the exponential sweep [1/s]
    fa, fb = f0 / extend, f1 * extend
    fb = min(fb, 0.45 * rate_hz)
    t_start = math.log(fa / f0) / k  # negative
    t_end = math.log(fb / f0) / k
    t = np.arange(int(round((t_end - t_start) * rate_hz))) / rate_hz + t_start
    phase = 2 * math.pi * f0 * (np.exp(k * t) - 1) / k
    x = np.sin(phase - phase[0])
    env = np.ones_like(t)
    head = t < 0
    env[head] = 0.5 * (1 - np.cos(math.pi * (t[head] - t_start) / -t_start)) if t_start < 0 else 1
    tail = t > duration
    if tail.any():
        env[tail] = 0.5 * (1 + np.cos(math.pi * (t[tail] - duration) / (t_end - duration)))
    force = np.concatenate([amplitude * env * x, np.zeros(int(round(silence * rate_hz)))])
    return Sweep(force, float(rate_hz), (float(f0), float(f1)))


@dataclass(frozen=True)
class ETFE:
    """Empirical transfer function estimate.

    Attributes
    ----------
    freq : ndarray [Hz]
    H : ndarray, complex [(m/s²)/N]
        Acceleration per unit force.
    coherence : ndarray [1]
        Across repeats (1: the repeats agree; noise lowers it).
    """

    freq: np.ndarray
    H: np.ndarray
    coherence: np.ndarray

    def in_band(self, band: tuple[float, float]) -> ETFE:
        m = (self.freq >= band[0]) & (self.freq <= band[1])
        return ETFE(self.freq[m], self.H[m], self.coherence[m])


def etfe(u: np.ndarray, ys: np.ndarray, rate_hz: float, smooth_hz: float = 2.0,
         method: str = "sync") -> ETFE:
    """Estimate H(f) = Y(f)/U(f) from one input and repeated outputs.

    Parameters
    ----------
    u : ndarray, shape (n,) [N]
        The force command (identical in every repeat).
    ys : ndarray, shape (r, n) [m/s²]
        Measured accelerations, one row per repeat.
    rate_hz : float [Hz]
    smooth_hz : float [Hz]
        Width of the Hann window over which cross- and auto-spectra are averaged
        across neighbouring frequencies (0: raw ratio).
    method : str
        ``sync`` — average the repeats in time first (synchronous averaging: noise falls
        as 1/√r while the response stays), then one smoothed ratio. With the same
        excitation in every repeat this equals averaging the repeats' ETFEs in the
        complex domain, as the paper did. ``polar`` — average the repeats' ETFEs as
        magnitude in dB and phase (circular mean) separately, a common alternative; the
        mean of log-magnitudes is biased low by noise.
    """
    u = np.asarray(u, dtype=float)
    ys = np.atleast_2d(np.asarray(ys, dtype=float))
    n = u.size
    U = np.fft.rfft(u)
    Ys = np.fft.rfft(ys, axis=1)
    freq = np.fft.rfftfreq(n, 1 / rate_hz)
    df = rate_hz / n
    half = max(0, int(round(smooth_hz / df / 2)))
    w = np.hanning(2 * half + 3)[1:-1] if half > 0 else np.ones(1)
    w /= w.sum()

    def smooth(x: np.ndarray) -> np.ndarray:
        if half == 0:
            return x
        return np.convolve(x.real, w, "same") + 1j * np.convolve(x.imag, w, "same") \
            if np.iscomplexobj(x) else np.convolve(x, w, "same")

    Suu = smooth(np.abs(U) ** 2)
    if method == "sync":
        Ym = Ys.mean(axis=0)
        H = smooth(Ym * np.conj(U)) / Suu
    elif method == "polar":
        each = [smooth(Y * np.conj(U)) / Suu for Y in Ys]
        db = np.mean([20 * np.log10(np.abs(h) + 1e-300) for h in each], axis=0)
        ph = np.angle(np.mean([h / np.abs(h) for h in each], axis=0))  # circular mean
        H = 10 ** (db / 20) * np.exp(1j * ph)
    else:
        raise ValueError(f"etfe method must be 'sync' or 'polar', got {method!r}")
    r = Ys.shape[0]
    if r > 1:
        num = smooth(np.abs(Ys.sum(axis=0) * np.conj(U)) ** 2)
        den = smooth(r * (np.abs(Ys) ** 2).sum(axis=0) * np.abs(U) ** 2)
        coh = np.clip(num / np.where(den > 0, den, np.inf), 0, 1)
    else:
        coh = np.ones_like(freq)
    return ETFE(freq, H, coh)


@dataclass(frozen=True)
class TFModel:
    """H(s) = e^(−sτ)·B(s)/A(s), continuous time.

    Attributes
    ----------
    num, den : ndarray
        Polynomial coefficients in s, highest power first (den monic).
    delay : float [s]
    err_db_rms, err_db_max, err_deg_rms, err_deg_max : float
        Fit error over the band (model vs estimate).
    band : tuple of float [Hz]
    """

    num: np.ndarray
    den: np.ndarray
    delay: float
    err_db_rms: float = 0.0
    err_db_max: float = 0.0
    err_deg_rms: float = 0.0
    err_deg_max: float = 0.0
    band: tuple[float, float] = (10.0, 500.0)

    @property
    def order(self) -> int:
        return len(self.den) - 1

    @property
    def relative_degree(self) -> int:
        return len(self.den) - len(np.trim_zeros(self.num, "f"))

    def response(self, freq: np.ndarray) -> np.ndarray:
        s = 2j * np.pi * np.asarray(freq, dtype=float)
        return np.polyval(self.num, s) / np.polyval(self.den, s) * np.exp(-s * self.delay)

    def to_dict(self) -> dict:
        return {"num": self.num.tolist(), "den": self.den.tolist(), "delay_s": self.delay,
                "order": self.order, "relative_degree": self.relative_degree,
                "band_hz": list(self.band), "err_db_rms": self.err_db_rms,
                "err_db_max": self.err_db_max, "err_deg_rms": self.err_deg_rms,
                "err_deg_max": self.err_deg_max}

    @classmethod
    def from_dict(cls, d: dict) -> TFModel:
        return cls(np.asarray(d["num"], float), np.asarray(d["den"], float), d["delay_s"],
                   d.get("err_db_rms", 0.0), d.get("err_db_max", 0.0), d.get("err_deg_rms", 0.0),
                   d.get("err_deg_max", 0.0), tuple(d.get("band_hz", (10.0, 500.0))))


def _fit_errors(H_fit: np.ndarray, H: np.ndarray) -> tuple[float, float, float, float]:
    ratio = H_fit / H
    db = 20 * np.log10(np.abs(ratio))
    deg = np.degrees(np.angle(ratio))
    return (float(np.sqrt(np.mean(db**2))), float(np.max(np.abs(db))),
            float(np.sqrt(np.mean(deg**2))), float(np.max(np.abs(deg))))


def fit_transfer_function(est: ETFE, order: int = 7, relative_degree: int = 4,
                          delay: float | None = None, band: tuple[float, float] = (10.0, 500.0),
                          iterations: int = 30, weight_by_coherence: bool = True,
                          delays: np.ndarray | None = None, zeros_at_origin: int = 0) -> TFModel:
    """Fit e^(−sτ)·B(s)/A(s) to an ETFE over ``band``.

    Sanathanan–Koerner iterations: minimise Σ |(B(jω) − H·e^(jωτ)·A(jω)) / A_prev(jω)|²,
    linear in the coefficients, with frequency scaled by the band's geometric centre
    for conditioning. Unstable poles are reflected into the left half plane.

    Parameters
    ----------
    est : ETFE
    order : int
        Denominator degree n.
    relative_degree : int
        n − (numerator degree), >= 0.
    delay : float or None [s]
        Fixed delay; None searches ``delays`` (default 0–1 ms in 0.025-ms steps) for the
        smallest phase-and-magnitude error.
    band : (float, float) [Hz]
    zeros_at_origin : int
        Zeros fixed at s = 0 (force → acceleration of a stylus held by a spring-like hand
        has two). On noise-free data the free fit finds them itself; on measured data,
        fixing them worsened the in-band phase on the simulated device (12° vs 0.4°), so
        the default leaves the numerator free. Zeros the fit puts below the band are not
        trusted by the inversion (see :mod:`device.matching.inversion`).
    """
    if not (1 <= order <= 12 and 0 <= relative_degree <= order):
        raise ValueError(f"need 1 <= order <= 12 and 0 <= relative degree <= order, got "
                         f"{order}, {relative_degree}")
    e = est.in_band(band)
    if delay is None:
        grid = np.arange(0, 1.0001e-3, 2.5e-5) if delays is None else np.asarray(delays)
        fits = [fit_transfer_function(est, order, relative_degree, float(d), band, iterations,
                                      weight_by_coherence, zeros_at_origin=zeros_at_origin)
                for d in grid]
        return min(fits, key=lambda m: m.err_db_rms**2 + (m.err_deg_rms / 8.7) ** 2)
    w0 = 2 * np.pi * math.sqrt(band[0] * band[1])
    s = 2j * np.pi * e.freq / w0
    Hd = e.H * np.exp(2j * np.pi * e.freq * delay)  # remove the delay from the data
    m = order - relative_degree
    z0 = int(zeros_at_origin)
    if not 0 <= z0 <= m:
        raise ValueError(f"zeros_at_origin must be within 0..{m} (numerator degree), got {z0}")
    # inverse-variance weights: the variance of an ETFE bin goes as (1 − γ²)/γ²
    coh = np.clip(e.coherence, 1e-6, 1 - 1e-9)
    weight = np.sqrt(coh / (1 - coh)) if weight_by_coherence else np.ones_like(e.freq)
    # unknowns: b_m..b_z0 (m+1−z0), a_{n-1}..a_0 (n); A(s) = s^n + a_{n-1}s^{n-1} + …
    S_b = np.stack([s**k for k in range(m, z0 - 1, -1)], axis=1)
    S_a = np.stack([s**k for k in range(order - 1, -1, -1)], axis=1)
    a_prev = np.ones_like(s)
    coef = None
    for _ in range(iterations):
        wk = weight / np.abs(a_prev)
        M = np.concatenate([S_b, -Hd[:, None] * S_a], axis=1) * wk[:, None]
        rhs = Hd * s**order * wk
        Mr = np.concatenate([M.real, M.imag])
        rr = np.concatenate([rhs.real, rhs.imag])
        coef, *_ = np.linalg.lstsq(Mr, rr, rcond=None)
        a = np.concatenate([[1.0], coef[m + 1 - z0:]])
        a_prev = np.polyval(a, s)
    b = np.concatenate([coef[: m + 1 - z0], np.zeros(z0)])
    a = np.concatenate([[1.0], coef[m + 1 - z0:]])
    # stabilise: reflect right-half-plane poles (keeps the magnitude response)
    poles = np.roots(a)
    if np.any(poles.real > 0):
        poles = np.where(poles.real > 0, -poles.conj(), poles)
        a = np.real(np.poly(poles))
    # back to physical frequency: s = s_phys / w0
    num = b * w0 ** (order - np.arange(m, -1, -1))
    den = a * w0 ** np.arange(0, order + 1)
    den_lead = den[0]
    num, den = num / den_lead, den / den_lead
    num = np.concatenate([np.zeros(order - m), num])
    model = TFModel(num=num, den=den, delay=float(delay), band=band)
    return TFModel(num, den, float(delay), *_fit_errors(model.response(e.freq), e.H), band)


@dataclass
class SystemIdentification:
    """Result of :func:`identify_system`: the averaged estimate, the per-level estimates,
    the fit."""

    etfe: ETFE
    per_level: dict[float, ETFE]
    model: TFModel
    rate_hz: float
    levels: tuple[float, ...]
    repeats: int
    meta: dict = field(default_factory=dict)


def identify_system(device, levels: tuple[float, ...] = (0.5, 1.0, 1.5), repeats: int = 4,
             band: tuple[float, float] = (10.0, 500.0), duration: float = 2.5,
             order: int = 7, relative_degree: int = 4, delay: float | None = None,
             smooth_hz: float = 2.0, zeros_at_origin: int = 0, *,
             record: BuildRecord | None = None, on_fault: OnFault | None = None,
             pace: Pace | None = None) -> SystemIdentification:
    """Identify force → acceleration on ``device`` while the hand holds the stylus.

    Plays :func:`swept_sine` at each force level ``repeats`` times (device.play_force),
    estimates the ETFE per level by synchronous averaging, averages the levels in the
    complex domain, and fits a model.

    Each sweep is one measurement (:func:`~device.matching.measure.measured`): a fault
    during it goes to ``on_fault`` and the sweep is played again once it is cleared;
    ``record`` keeps every finished sweep and gives back those of an earlier run; ``pace``
    counts them (progress and time left).

    Raises
    ------
    MeasurementFault
        A fault that was not cleared (the sweeps finished before it are in ``record``).
    """
    per_level = {}
    with accel_at_every_tick(device) as rate:
        for level in levels:
            sweep = swept_sine(rate, band, duration, level)
            ys = []
            for k in range(repeats):
                y = None if record is None else record.sweep(level, k)
                if y is None:
                    what = f"sweep at {level:g} N, repeat {k + 1} of {repeats}"
                    t0 = time.perf_counter()
                    res = measured(device, lambda f=sweep.force: device.play_force(f), what,
                                   on_fault)
                    y = res.traces["accel"] - np.mean(res.traces["accel"][:10])
                    if record is not None:
                        record.add_sweep(level, k, y)
                    if pace is not None:
                        pace.did(what, time.perf_counter() - t0)
                ys.append(y)
            per_level[level] = etfe(sweep.force, np.array(ys), rate, smooth_hz)
    freq = next(iter(per_level.values())).freq
    H = np.mean([e.H for e in per_level.values()], axis=0)
    coh = np.mean([e.coherence for e in per_level.values()], axis=0)
    est = ETFE(freq, H, coh)
    model = fit_transfer_function(est, order, relative_degree, delay, band,
                                  zeros_at_origin=zeros_at_origin)
    return SystemIdentification(est, per_level, model, rate, tuple(levels), repeats,
                          {"device": device.info.to_dict(), "duration_s": duration,
                           "band_hz": list(band)})


def sweep_seconds(rate_hz: float, band: tuple[float, float] = (10.0, 500.0),
                  duration: float = 2.5) -> float:
    """How long one system-identification sweep plays [s of device time]."""
    return len(swept_sine(rate_hz, band, duration).force) / rate_hz


def true_response(plant_A: np.ndarray, plant_B: np.ndarray, output_row: np.ndarray,
                  freq: np.ndarray, rate_hz: float | None = None) -> np.ndarray:
    """Frequency response of a state-space plant from input 0 to a linear output row.

    With ``rate_hz`` it includes the zero-order hold's e^(−sT/2)·sinc(fT) (what a
    sampled command through a continuous plant looks like), for comparing estimates.
    """
    ns = plant_A.shape[0]
    c = output_row[:ns]
    d = output_row[ns] if output_row.size > ns else 0.0
    b = plant_B[:, 0]
    eye = np.eye(ns)
    H = np.array([c @ np.linalg.solve(2j * np.pi * f * eye - plant_A, b) + d
                  for f in np.asarray(freq, dtype=float)])
    if rate_hz:
        T = 1 / rate_hz
        H = H * np.exp(-1j * np.pi * freq * T) * np.sinc(freq * T)
    return H
