"""Stable inversion of a force → acceleration model: the force that produces a target acceleration.

Sampling e^(−sτ)·B(s)/A(s) with a zero-order hold at the servo rate gives a discrete
model whose zeros include sampling zeros; for relative degree 4 (and a fractional
delay) some lie outside the unit circle, so the direct inverse 1/H(z) diverges within
milliseconds (:func:`direct_inverse` shows it). Two stable inverses:

* ``regularized`` — frequency domain: F = H*·A / (|H|² + λ·max|H|²) inside the band,
  zero outside; λ (default 1e-4) bounds the gain where the model has little response
  (1e-3 already costs ~27 % of the target, 1e-4 ~7 %, on the simulated device).
* ``stable`` — exact stable inversion: the zeros inside the unit circle are inverted
  causally, those outside anti-causally (filtering the time-reversed signal), and the
  model's delay becomes an advance. The model is trusted only inside the band: zeros
  below its low edge (|z − 1| < 2π·f_low/f_s — the s² of force → acceleration, and
  whatever low zeros noise gave the fit) would invert into integrators that drift or
  anti-causal exponentials lasting seconds; their inverse is applied exactly inside
  the band and not at all outside it (leaky integrators instead cost ~9° of phase each
  at 66 Hz). The result is non-causal: it needs force before the
  target begins, which a contact-triggered playback cannot give; that part is reported
  as energy outside the window.

* ``windowed`` — the causal force inside the window that minimises
  ‖H·u − a‖² + λ·max|H|²·‖u‖² over the window, with H the model's convolution matrix:
  optimal for playback from contact (no non-causal part to lose), at the cost of a
  dense n×n solve (~50 ms for a 100-ms window at 10 kHz instead of ~1.5 ms).

The first two are followed by the same conditioning: a zero-phase band limit to 10–500 Hz of the
whole (untruncated) inverse, then the 100-ms window with half-cosine tapers so the
transient starts and ends at zero. Band-passing after the truncation instead doubled
the in-window error (a 10-Hz high-pass over a 100-ms window distorts its edges).
:func:`verify` runs the force back through a forward model.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
from scipy import linalg, signal
from scipy.linalg import expm

from .sysid import TFModel

__all__ = ["DiscreteModel", "discretize", "invert", "direct_inverse", "verify", "Inversion",
           "condition_target", "METHODS"]

METHODS = ("regularized", "stable", "windowed")


@dataclass(frozen=True)
class DiscreteModel:
    """y[k] = Σ b[i]·u[k−i] − Σ a[i]·y[k−i] (a[0] = 1): the ZOH-sampled model at ``rate_hz``."""

    b: np.ndarray
    a: np.ndarray
    rate_hz: float

    @property
    def zeros(self) -> np.ndarray:
        b = np.trim_zeros(self.b, "f")
        return np.roots(b) if b.size > 1 else np.array([])

    def response(self, freq: np.ndarray) -> np.ndarray:
        _, h = signal.freqz(self.b, self.a, worN=np.asarray(freq, float), fs=self.rate_hz)
        return h

    def simulate(self, u: np.ndarray) -> np.ndarray:
        return signal.lfilter(self.b, self.a, u)


def discretize(model: TFModel, rate_hz: float) -> DiscreteModel:
    """Exact ZOH equivalent of e^(−sτ)·B(s)/A(s), including a fractional delay.

    With τ = d·T + τ′ (0 ≤ τ′ < T), the held input reaches the plant τ late:
    x[k+1] = Φ·x[k] + Γ₀·u[k−d] + Γ₁·u[k−d−1], Γ₀ = ∫₀^(T−τ′) e^(As)ds·B,
    Γ₁ = e^(A(T−τ′))·∫₀^τ′ e^(As)ds·B.
    """
    T = 1.0 / rate_hz
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", signal.BadCoefficients)
        A, B, C, D = signal.tf2ss(model.num, model.den)
    n = A.shape[0]
    d, frac = divmod(model.delay, T)
    d = int(round(d)) if abs(frac - T) > 1e-15 else int(round(d)) + 1
    frac = model.delay - d * T
    if frac < 1e-15:
        frac = 0.0

    def integ(t: float) -> tuple[np.ndarray, np.ndarray]:
        M = np.zeros((n + 1, n + 1))
        M[:n, :n] = A
        M[:n, n:] = B
        E = expm(M * t)
        return E[:n, :n], E[:n, n:]

    Phi, _ = integ(T)
    P0, G0 = integ(T - frac)
    G1 = P0 @ integ(frac)[1] if frac > 0 else np.zeros((n, 1))
    # augmented state [x; u[k-1]] for the one-sample spill of the fractional delay
    Ad = np.zeros((n + 1, n + 1))
    Ad[:n, :n] = Phi
    Ad[:n, n:] = G1
    Bd = np.zeros((n + 1, 1))
    Bd[:n] = G0
    Bd[n, 0] = 1.0
    Cd = np.concatenate([C, np.zeros((1, 1))], axis=1)
    Dd = D if frac == 0 else np.zeros((1, 1))
    if frac == 0:
        Dd = D
    with warnings.catch_warnings():  # leading numerator zeros are the delay, not a problem
        warnings.simplefilter("ignore", signal.BadCoefficients)
        b, a = signal.ss2tf(Ad, Bd, Cd, Dd)
    b = np.atleast_1d(b.squeeze()).astype(float)
    a = np.atleast_1d(a).astype(float)
    # cancel the pole at z = 0 introduced by the delay state when there is no fraction
    b = np.concatenate([np.zeros(d), b])
    a = np.concatenate([a, np.zeros(d)])
    b, a = _trim_common(b, a)
    return DiscreteModel(b / a[0], a / a[0], rate_hz)


def _trim_common(b: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop trailing zeros shared by both polynomials in z^-1 (pole-zero pairs at z = 0)."""
    while len(b) > 1 and len(a) > 1 and abs(b[-1]) < 1e-14 * np.abs(b).max() \
            and abs(a[-1]) < 1e-14 * np.abs(a).max():
        b, a = b[:-1], a[:-1]
    return b, a


def direct_inverse(dm: DiscreteModel, y: np.ndarray) -> np.ndarray:
    """The naive causal inverse A(z)/B(z) (unstable when B has zeros outside the circle)."""
    b = np.trim_zeros(dm.b, "f")
    lead = len(dm.b) - len(b)
    with np.errstate(all="ignore"):
        u = signal.lfilter(dm.a, b, np.concatenate([y[lead:], np.zeros(lead)]))
    return u


def _stable_inverse(dm: DiscreteModel, y: np.ndarray, pad: int, f_low: float,
                    f_high: float) -> np.ndarray:
    """Exact stable (non-causal) inverse of dm applied to y, with ``pad`` samples before."""
    b = np.trim_zeros(dm.b, "f")
    lead = len(dm.b) - len(b)  # pure delay in samples → advance
    zeros = np.roots(b) if len(b) > 1 else np.array([])
    w_low = 2 * math.pi * f_low / dm.rate_hz
    dc = np.abs(zeros - 1.0) < w_low
    inside = zeros[~dc & (np.abs(zeros) < 1.0)]
    outside = zeros[~dc & (np.abs(zeros) >= 1.0)]
    gain = b[0]
    x = np.concatenate([np.zeros(pad), y, np.zeros(pad)])
    # causal part: A(z) / (gain · Π(1 − z_i z^-1)), zeros inside the circle
    den_in = np.real(np.poly(inside)) if inside.size else np.array([1.0])
    u = signal.lfilter(dm.a, den_in * gain, x)
    # anti-causal part: 1/Π(1 − z_o z^-1) = Π(−1/z_o)·z^m / Π(1 − z/z_o)
    if outside.size:
        c = np.real(np.poly(1.0 / outside))  # Π(1 − w/z_o) in w = z (time-reversed z^-1)
        u = signal.lfilter([1.0], c, u[::-1])[::-1]
        u = u * np.real(np.prod(-1.0 / outside))
        m = outside.size
        u = np.concatenate([u[m:], np.zeros(m)])  # z^m: advance by m samples
    if lead:
        u = np.concatenate([u[lead:], np.zeros(lead)])
    if dc.any():  # below-band zeros: exact inverse inside the band, nothing outside
        n = int(2 ** math.ceil(math.log2(len(u) * 2)))
        U = np.fft.rfft(u, n)
        f = np.fft.rfftfreq(n, 1 / dm.rate_hz)
        zinv = np.exp(-2j * np.pi * f / dm.rate_hz)
        Z = np.prod([1 - z0 * zinv for z0 in zeros[dc]], axis=0)
        keep = (f >= f_low) & (f <= f_high)
        U = np.where(keep, U / np.where(keep, Z, 1.0), 0.0)
        u = np.fft.irfft(U, n)[: len(u)].real
    return u


def _regularized_inverse(dm: DiscreteModel, y: np.ndarray, pad: int, lam: float,
                         band: tuple[float, float]) -> np.ndarray:
    x = np.concatenate([np.zeros(pad), y, np.zeros(pad)])
    n = int(2 ** math.ceil(math.log2(len(x) * 2)))
    X = np.fft.rfft(x, n)
    f = np.fft.rfftfreq(n, 1 / dm.rate_hz)
    H = dm.response(f)
    U = np.conj(H) * X / (np.abs(H) ** 2 + lam * np.max(np.abs(H) ** 2))
    U[(f < band[0]) | (f > band[1])] = 0.0
    return np.fft.irfft(U, n)[: len(x)]


def condition_target(accel: np.ndarray, rate_hz: float, band: tuple[float, float] = (10.0, 500.0)
                     ) -> np.ndarray:
    """Zero-phase smoothing of a measured acceleration window: band-pass, no phase shift."""
    sos = signal.butter(4, band, btype="bandpass", fs=rate_hz, output="sos")
    pad = min(len(accel) - 1, 3 * 50)
    return signal.sosfiltfilt(sos, accel, padlen=pad)


@dataclass(frozen=True)
class Inversion:
    """A force transient and how well it reproduces its target.

    Attributes
    ----------
    force : ndarray [N]
        The transient to play from contact, length of the window.
    target : ndarray [m/s²]
        The conditioned target acceleration over the window.
    predicted : ndarray [m/s²]
        Forward model response to ``force``.
    in_window_error : float [1]
        ‖predicted − target‖ / ‖target‖ over the window.
    energy_outside : float [1]
        Fraction of the raw inverse's force energy outside the window (before contact
        or after its end), which playback cannot deliver.
    method : str
    """

    force: np.ndarray
    target: np.ndarray
    predicted: np.ndarray
    in_window_error: float
    energy_outside: float
    method: str


def invert(dm: DiscreteModel, accel: np.ndarray, method: str = "regularized",
           lam: float = 1e-4, band: tuple[float, float] = (10.0, 500.0),
           taper_start: float = 0.001, taper_end: float = 0.01,
           forward: DiscreteModel | None = None) -> Inversion:
    """Force [N] that makes the model's acceleration follow ``accel`` [m/s²] from contact.

    Parameters
    ----------
    dm : DiscreteModel
        The identified model at the servo rate.
    accel : ndarray [m/s²]
        Acceleration after contact (the window, e.g. 100 ms), sample 0 at contact.
    method : {'regularized', 'stable', 'windowed'}
    lam : float
        Regularization of the ``regularized`` method, relative to max |H|².
    band : (float, float) [Hz]
        Band kept in the force (zero-phase band-pass).
    taper_start, taper_end : float [s]
        Half-cosine ramps at the start and end of the window.
    forward : DiscreteModel, optional
        Model used for verification (default ``dm``).
    """
    if method not in METHODS:
        raise ValueError(f"inversion method must be one of {', '.join(METHODS)}, got {method!r}")
    rate = dm.rate_hz
    target = condition_target(np.asarray(accel, float), rate, band)
    n = len(target)
    if method == "windowed":
        force = _windowed_inverse(dm, target, lam) * _taper(n, rate, taper_start, taper_end)
        v = verify(forward or dm, force, target)
        return Inversion(force, target, v[0], v[1], 0.0, method)
    pad = n
    if method == "regularized":
        raw = _regularized_inverse(dm, target, pad, lam, band)
    else:
        raw = _stable_inverse(dm, target, pad, band[0], band[1])
    raw = _bandlimit(raw, rate, band)
    total = float(np.sum(raw**2))
    win = raw[pad: pad + n].copy()
    outside = 1.0 - float(np.sum(win**2)) / total if total > 0 else 0.0
    win *= _taper(n, rate, taper_start, taper_end)
    v = verify(forward or dm, win, target)
    return Inversion(win, target, v[0], v[1], outside, method)


def _windowed_inverse(dm: DiscreteModel, target: np.ndarray, lam: float) -> np.ndarray:
    """min ‖H·u − a‖² + λ·max|H|²·‖u‖² over the window (H: Toeplitz of the impulse response)."""
    n = len(target)
    imp = np.zeros(n)
    imp[0] = 1.0
    h = dm.simulate(imp)
    H = linalg.toeplitz(h, np.zeros(n))
    gain2 = float(np.max(np.abs(np.fft.rfft(h, 4 * n))) ** 2)
    A = H.T @ H + lam * gain2 * np.eye(n)
    return linalg.solve(A, H.T @ target, assume_a="pos")


def _bandlimit(u: np.ndarray, rate: float, band: tuple[float, float]) -> np.ndarray:
    """Zero-phase band limit by an FFT mask (the signal is padded, so no wrap-around)."""
    n = int(2 ** math.ceil(math.log2(len(u) * 2)))
    U = np.fft.rfft(u, n)
    f = np.fft.rfftfreq(n, 1 / rate)
    U[(f < band[0]) | (f > band[1])] = 0.0
    return np.fft.irfft(U, n)[: len(u)]


def _taper(n: int, rate: float, start: float, end: float) -> np.ndarray:
    w = np.ones(n)
    a = max(1, int(round(start * rate)))
    b = max(1, int(round(end * rate)))
    w[:a] = 0.5 * (1 - np.cos(np.pi * np.arange(a) / a))
    w[n - b:] = 0.5 * (1 + np.cos(np.pi * (np.arange(b) + 1) / b))
    return w


def verify(dm: DiscreteModel, force: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, float]:
    """Forward-simulate ``force`` and return (predicted acceleration, relative error)."""
    pred = dm.simulate(np.asarray(force, float))
    err = float(np.linalg.norm(pred - target) / np.linalg.norm(target))
    return pred, err
