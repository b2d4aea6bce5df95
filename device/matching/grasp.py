"""The grasp-force model of contact vibrations (SPEC §3).

A one-degree-of-freedom two-finger grasping interface hits a surface; the grasped
handle responds as m·ẍ + c·ẋ + k·x = F with m, c, k linear in the grasp force F_g:

    m = 0.023 − 0.00032·F_g [kg],  c = 14 − 0.19·F_g [N·s/m],  k = 75,000 − 1,000·F_g [N/m]

so a(s)/F(s) = K·s² / (T²s² + 2ζTs + 1) with K = 1/k, T = √(m/k), ζ = c / (2√(km)).

The fit of one impact from the measured contact force F(t) and acceleration a(t):

1. damped frequency F_d from the FFT peak of a(t);
2. settling time T_s: where the envelope (half-cycle extrema) falls to 15 % of its peak;
3. σ = −ln(0.15)/T_s, then ζ = σ/√(σ² + ω_d²), ω_n = √(σ² + ω_d²), T = 1/ω_n. The paper's
   ζ = 1/√((π·F_d·T_s)² + 1) is the same relation with σ = 2/T_s, i.e. a threshold of
   e^(−2) = 13.5 %; at 15 % it overestimates σ by 5 % (2/ln(1/0.15) = 1.054), so the
   exact relation is used (``paper_formula=True`` reproduces the printed one);
4. gain: the model is linear in K, so with the measured force driving the unit-gain
   model (K = 1, with the identified T and ζ, through the accelerometer's filter) the
   gain is K = a_peak,measured / a_peak,unit — the model's own peak response, which a
   round trip on synthetic transients recovers exactly;
5. m = T²/K, c = 2ζT/K, k = 1/K, then refined by least squares on the whole transient.

A recursive estimator (:func:`rls_second_order`: instrumental-variable recursion on the
free decay for the poles, then a recursive scalar fit of the scale) gives the online
estimate. Fit quality per transient is MATLAB compare's fit %,
100·(1 − ‖y − ŷ‖/‖y − mean(y)‖), and the RMSE [m/s²].
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, signal

from ..scene import PUBLISHED_GRASP as PUBLISHED
from ..scene import GraspModel, GraspTransient

__all__ = ["GraspModel", "PUBLISHED", "TISSUE", "GraspRig", "Impact", "ImpactFit",
           "identify_impact", "identify_grasp", "fit_percent", "GraspTransient",
           "rls_second_order", "peak_gain", "foh_filter"]

G = 9.80665
#: The rig's unmodelled mode (:attr:`GraspRig.tissue`): 12 % of the handle's mass at twice
#: its natural frequency (~575 Hz at no grasp, inside the accelerometer's 1-kHz band),
#: damping ratio 0.2. The mass share is sized so that the manual fit of 60 impacts scores
#: within the paper's manual range (69.8–79.6 %; measured on seed 1: manual 78.0, least
#: squares 80.9). Our recursive estimator then scores 77.1, below the paper's recursive
#: 80.3–81.4 % (the paper's recursive beat its manual; ours does not). The frequency and
#: damping are our assumption (the paper gives no second mode).
TISSUE = (0.12, 2.0, 0.2)


def fit_percent(y: np.ndarray, yhat: np.ndarray) -> float:
    """MATLAB compare's fit: 100·(1 − ‖y − ŷ‖ / ‖y − mean(y)‖) [%]."""
    y, yhat = np.asarray(y, float), np.asarray(yhat, float)
    return float(100.0 * (1.0 - np.linalg.norm(y - yhat) / np.linalg.norm(y - y.mean())))


def _behind_rc(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: float, rc_hz: float | None):
    """(A, B, C, D) of a system whose output is read through a first-order RC low-pass at
    ``rc_hz`` [Hz] (the RC's output is the last state); unchanged when ``rc_hz`` is None."""
    if not rc_hz:
        return A, B, C, D
    n = A.shape[0]
    wc = 2 * math.pi * rc_hz
    Af = np.zeros((n + 1, n + 1))
    Af[:n, :n] = A
    Af[n, :n] = wc * C
    Af[n, n] = -wc
    out = np.zeros(n + 1)
    out[n] = 1.0
    return Af, np.append(B, wc * D), out, 0.0


def _plant(m: float, c: float, k: float, rc_hz: float | None):
    """(A, B, C, D) of force → acceleration, behind the RC when given."""
    A = np.array([[0.0, 1.0], [-k / m, -c / m]])
    return _behind_rc(A, np.array([0.0, 1.0 / m]), np.array([-k / m, -c / m]), 1.0 / m, rc_hz)


def _plant_with_tissue(m: float, c: float, k: float, tissue: tuple[float, float, float],
                       rc_hz: float | None):
    """(A, B, C, D) of force → the handle's acceleration with a tissue mass on the handle
    (:attr:`GraspRig.tissue`), behind the RC when given. States: handle position and
    velocity, tissue position and velocity (and the RC's output)."""
    mu, ratio, zeta = tissue
    m2 = mu * m
    w2 = ratio * math.sqrt(k / m)
    k2, c2 = m2 * w2 ** 2, 2 * zeta * m2 * w2
    A = np.array([[0.0, 1.0, 0.0, 0.0],
                  [-(k + k2) / m, -(c + c2) / m, k2 / m, c2 / m],
                  [0.0, 0.0, 0.0, 1.0],
                  [k2 / m2, c2 / m2, -k2 / m2, -c2 / m2]])
    B = np.array([0.0, 1.0 / m, 0.0, 0.0])
    return _behind_rc(A, B, A[1].copy(), 1.0 / m, rc_hz)  # the handle's acceleration


def _zoh_response(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: float, dt: float,
                  u: np.ndarray) -> np.ndarray:
    """Output of ẋ = Ax + Bu, y = Cx + Du for ``u`` held over each step ``dt`` [s], mode by
    mode (the discrete system diagonalized: one first-order recursion per eigenvalue), so a
    fast sampling (1 MHz) of a 5th-order plant stays exact where a transfer function's
    polynomials would not."""
    Ad, Bd, Cd, Dd, _ = signal.cont2discrete((A, B[:, None], C[None, :], np.array([[D]])),
                                             dt, method="zoh")
    lam, V = np.linalg.eig(Ad)
    b = np.linalg.solve(V, Bd[:, 0])
    c = Cd[0] @ V
    y = np.zeros(len(u), dtype=complex)
    for i in range(len(lam)):
        # z[k+1] = λ z[k] + b u[k]: the state after step k is the output one step later
        z = signal.lfilter([0.0, b[i]], [1.0, -lam[i]], u.astype(complex))
        y += c[i] * z
    return y.real + Dd[0, 0] * u


def foh_filter(m: float, c: float, k: float, rate_hz: float, rc_hz: float | None
               ) -> tuple[np.ndarray, np.ndarray]:
    """Exact discrete (b, a) of force → acceleration for a force linear between samples.

    The plant (behind the RC when ``rc_hz`` is given) discretized with a first-order hold
    (:func:`scipy.signal.cont2discrete`, ``method="foh"``) at ``rate_hz`` [Hz].
    """
    A, B, C, D = _plant(m, c, k, rc_hz)
    Ad, Bd, Cd, Dd, _ = signal.cont2discrete((A, B[:, None], C[None, :], np.array([[D]])),
                                             1.0 / rate_hz, method="foh")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", signal.BadCoefficients)
        b, a = signal.ss2tf(Ad, Bd, Cd, Dd)
    return b[0], a


def _model_accel(m: float, c: float, k: float, force: np.ndarray, rate_hz: float,
                 rc_hz: float | None) -> np.ndarray:
    """Acceleration [m/s²] of m·ẍ + c·ẋ + k·x = F for a sampled force (linear in between)."""
    b, a = foh_filter(m, c, k, rate_hz, rc_hz)
    return signal.lfilter(b, a, force)


@dataclass(frozen=True)
class Impact:
    """One recorded grasp impact.

    Attributes
    ----------
    grasp_force : float [N]
    force : ndarray [N]
        Contact force sensor, from just before the impact.
    accel : ndarray [m/s²]
        Accelerometer (through its RC filter, clipped at its range, with noise).
    rate_hz : float [Hz]
    true : tuple (m, c, k)
        What the simulation used (for tests).
    """

    grasp_force: float
    force: np.ndarray
    accel: np.ndarray
    rate_hz: float
    true: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class GraspRig:
    """Simulated 1-DoF grasping interface (SPEC §3): 10 kHz, accelerometer ±18 g behind a
    1 kHz RC low-pass, contact force sensor.

    Attributes
    ----------
    model : GraspModel
    rate_hz : float [Hz]
    rc_hz : float [Hz]
        Accelerometer RC low-pass.
    accel_range : float [m/s²]
    accel_noise : float [m/s²]
        White noise rms.
    force_noise : float [N]
        Force sensor noise rms.
    pulse : float [s]
        Duration of the half-sine contact force of an impact (steel tip on balsa).
    window : float [s]
        Recorded time from the impact.
    tissue : (float, float, float), optional
        A mode the second-order model does not have: the finger pads' tissue as a mass
        ``μ·m`` on the handle, tuned alone to ``r`` × the handle's natural frequency with
        damping ratio ``ζ`` (``(μ, r, ζ)``). ``None``: the handle is the published model
        alone, and every fit is a round trip. :data:`TISSUE` is sized so that the manual fit
        scores within the paper's manual range (SPEC §3: 69.8–79.6 %).
    """

    model: GraspModel = PUBLISHED
    rate_hz: float = 10_000.0
    rc_hz: float = 1_000.0
    accel_range: float = 18 * G
    accel_noise: float = 0.5
    force_noise: float = 0.02
    pulse: float = 0.0004
    window: float = 0.030
    tissue: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        if self.tissue is None:
            return
        try:
            mu, ratio, zeta = (float(x) for x in self.tissue)
        except (TypeError, ValueError):
            raise ValueError(f"tissue must be (mass share, frequency ratio, damping ratio), "
                             f"got {self.tissue!r}") from None
        if not (all(math.isfinite(x) for x in (mu, ratio, zeta)) and mu > 0 and ratio > 0
                and zeta >= 0):
            raise ValueError(f"tissue (mass share, frequency ratio, damping ratio) must be "
                             f"finite with share and ratio > 0 and damping >= 0, got "
                             f"{self.tissue!r}")
        object.__setattr__(self, "tissue", (mu, ratio, zeta))

    def impact(self, rng: np.random.Generator, grasp_force: float, peak_force: float) -> Impact:
        """One impact: the continuous half-sine contact force integrated at 100× the rate
        (a different path from the fit's first-order hold), then sampled."""
        m, c, k = self.model.at(grasp_force)
        n = int(round(self.window * self.rate_hz))
        pre = 10
        over = 100
        onset = float(rng.uniform(0, 1)) / self.rate_hz  # the impact falls between samples
        tf = (np.arange((n + pre) * over) - pre * over) / (self.rate_hz * over)
        ff = np.where((tf >= onset) & (tf <= onset + self.pulse),
                      peak_force * np.sin(np.pi * np.clip(tf - onset, 0, self.pulse) / self.pulse),
                      0.0)
        A, B, C, D = (_plant(m, c, k, self.rc_hz) if self.tissue is None else
                      _plant_with_tissue(m, c, k, self.tissue, self.rc_hz))
        a = _zoh_response(A, B, C, D, 1 / (self.rate_hz * over), ff)[::over]
        force = ff[::over]
        a = np.clip(a + rng.normal(0, self.accel_noise, a.size), -self.accel_range,
                    self.accel_range)
        f = force + rng.normal(0, self.force_noise, force.size)
        return Impact(float(grasp_force), f, a, self.rate_hz, (m, c, k))

    def impacts(self, n: int, seed: int, grasp_range: tuple[float, float] = (2.0, 20.0),
                peak_range: tuple[float, float] = (0.8, 2.5)) -> list[Impact]:
        """``n`` impacts at uniformly drawn grasp forces [N] and contact-force peaks [N].

        The peaks keep the direct response F/m within the accelerometer's ±18 g; harder
        impacts clip, and the estimators then leave the clipped samples out.
        """
        rng = np.random.default_rng(seed)
        return [self.impact(rng, float(rng.uniform(*grasp_range)),
                            float(rng.uniform(*peak_range))) for _ in range(n)]


@dataclass
class ImpactFit:
    """The second-order model fitted to one impact.

    Attributes
    ----------
    fd : float [Hz]
        Damped frequency.
    ts : float [s]
        Settling time (envelope to 15 %).
    zeta, T, K : float
        Manual estimates ([1], [s], [s²/kg] = 1/k).
    manual, ls, rls : tuple (m, c, k)
        Manual, least-squares-refined and recursive estimates.
    fit : dict
        Fit % per estimate ("manual", "ls", "rls").
    rmse : dict
        RMSE [m/s²] per estimate.
    """

    grasp_force: float
    fd: float
    ts: float
    zeta: float
    T: float
    K: float
    manual: tuple[float, float, float]
    ls: tuple[float, float, float]
    rls: tuple[float, float, float]
    fit: dict = field(default_factory=dict)
    rmse: dict = field(default_factory=dict)


def _onset(force: np.ndarray) -> int:
    thr = 0.2 * np.max(force)
    return max(0, int(np.argmax(force > thr)) - 1)


def peak_gain(accel: np.ndarray, force: np.ndarray, T: float, zeta: float, rate_hz: float,
              rc_hz: float | None = 1_000.0, valid: np.ndarray | None = None) -> float:
    """Gain K [1/(N/m)] of K·s²/(T²s² + 2ζTs + 1) from the peak acceleration.

    The response is linear in K, so driving the unit-gain model (K = 1: k = 1, m = T²,
    c = 2ζT) with the measured force through the sensor's filter gives a peak a₁, and
    K = a_peak,measured / a₁. No closed form for the peak of an impact response is
    needed, and the pulse shape and the sensor filter are accounted for.
    """
    ok = np.ones(len(accel), bool) if valid is None else np.asarray(valid, bool)
    unit = _model_accel(T * T, 2 * zeta * T, 1.0, force, rate_hz, rc_hz)
    return float(np.max(np.abs(accel[ok])) / np.max(np.abs(unit[ok])))


def identify_impact(imp: Impact, threshold: float = 0.15, paper_formula: bool = False,
                    rc_hz: float | None = 1_000.0, accel_range: float | None = 18 * G,
                    clip_level: float = 2.0) -> ImpactFit:
    """Identify m, c, k of one impact (see the module docstring).

    Samples at the accelerometer's range limit (clipped) are left out of the gain, the
    least-squares fit and the recursive estimate.
    """
    rate = imp.rate_hz
    i0 = _onset(imp.force)
    a = imp.accel[i0:]
    F = imp.force[i0:]
    ok = np.abs(a) < clip_level * np.max(np.abs(a)) if np.ptp(a) > 0 else np.ones(a.size, bool)
    if accel_range is not None:
        ok = np.abs(a) < 0.999 * accel_range
    nfft = 8192
    spec = np.abs(np.fft.rfft(a * np.hanning(a.size), nfft))
    freq = np.fft.rfftfreq(nfft, 1 / rate)
    band = np.flatnonzero((freq > 20) & (freq < 0.45 * rate))
    kk = int(band[np.argmax(spec[band])])
    y0, y1, y2 = np.log(spec[kk - 1: kk + 2])
    d = y0 - 2 * y1 + y2
    fd = float(freq[kk] + (0.5 * (y0 - y2) / d if d else 0.0) * (freq[1] - freq[0]))
    # envelope from half-cycle extrema; settling where it falls below threshold × peak
    from .vibration import _extrema

    te, ve = _extrema(a, rate)
    env = np.abs(ve)
    ip = int(np.argmax(env))
    after = np.flatnonzero(env[ip:] < threshold * env[ip])
    if after.size == 0:
        raise ValueError("the transient does not settle to the threshold inside the window")
    j = ip + int(after[0])
    # interpolate log-linearly between the extrema around the crossing
    l0, l1 = math.log(env[j - 1]), math.log(env[j])
    target = math.log(threshold * env[ip])
    t_cross = te[j - 1] + (target - l0) / (l1 - l0) * (te[j] - te[j - 1])
    ts = float(t_cross - te[ip])
    wd = 2 * math.pi * fd
    if paper_formula:
        zeta = 1.0 / math.sqrt((math.pi * fd * ts) ** 2 + 1.0)
        T = ts * zeta / 2.0
    else:
        sigma = -math.log(threshold) / ts
        wn = math.sqrt(sigma**2 + wd**2)
        zeta, T = sigma / wn, 1.0 / wn
    K = peak_gain(a, F, T, zeta, rate, rc_hz, ok)
    manual = (T * T / K, 2 * zeta * T / K, 1.0 / K)

    def resid(p):
        m_, c_, k_ = np.exp(p)
        return (_model_accel(m_, c_, k_, F, rate, rc_hz) - a)[ok]

    sol = optimize.least_squares(resid, np.log(manual), method="lm")
    ls = tuple(float(v) for v in np.exp(sol.x))
    rls = rls_second_order(F, a, rate, rc_hz, valid=ok)
    fits, rmses = {}, {}
    for name, (m_, c_, k_) in (("manual", manual), ("ls", ls), ("rls", rls)):
        yhat = _model_accel(m_, c_, k_, F, rate, rc_hz)
        fits[name] = fit_percent(a[ok], yhat[ok])
        rmses[name] = float(np.sqrt(np.mean((a[ok] - yhat[ok]) ** 2)))
    return ImpactFit(imp.grasp_force, fd, ts, zeta, T, K, manual, ls, rls, fits, rmses)


def rls_second_order(force: np.ndarray, accel: np.ndarray, rate_hz: float,
                     rc_hz: float | None = 1_000.0, forgetting: float = 1.0,
                     valid: np.ndarray | None = None, settle: float = 0.0015,
                     decimate: int = 4) -> tuple[float, float, float]:
    """Recursive (sample-by-sample) estimate of m, c, k from one impact, in two stages.

    1. Poles: y[n] = −a₁·y[n−1] − a₂·y[n−2] on the free decay, from ``settle`` seconds after
       the impact (when the contact pulse and the accelerometer RC's own mode have died
       out, the sampled response of a second-order system obeys this exactly), on the
       signal taken every ``decimate``-th sample (at 35 samples per cycle the two poles
       crowd z = 1 and the estimate is ill-conditioned), estimated by recursive
       instrumental variables with the outputs three and four (decimated) samples back as
       instruments: plain recursive least squares is biased by the sensor noise in its
       regressors (damping 6× too high at 0.5 m/s² noise). On 20 noisy simulated
       impacts: median error 0.9 % on ω_n, 3.9 % on ζ. The poles give ω_n and ζ.
    2. Scale: with c/m = 2ζω_n and k/m = ω_n² fixed, the response to the measured force
       is (1/m) × a known shape g[n]; 1/m is updated recursively as Σg·y / Σg².

    The equation of motion sampled directly (F = m·a + c·v + k·x with integrated
    velocity and displacement) is not usable here: the 0.4-ms contact pulse spans four
    samples, and its discretization error, integrated, swamps k·x.

    Returns
    -------
    (m [kg], c [N·s/m], k [N/m])
    """
    y = np.asarray(accel, float)
    ok = np.ones(y.size, bool) if valid is None else np.asarray(valid, bool)
    n0 = int(round(settle * rate_hz))
    yd, okd = y[n0::decimate], ok[n0::decimate]
    theta = np.zeros(2)
    P = np.eye(2) * 1e6
    for n in range(4, yd.size):
        if not okd[n - 4: n + 1].all():
            continue
        phi = np.array([-yd[n - 1], -yd[n - 2]])
        z = np.array([-yd[n - 3], -yd[n - 4]])  # instruments: free of the noise at n−2..n
        Pz = P @ z
        g = Pz / (forgetting + phi @ Pz)
        theta = theta + g * (yd[n] - phi @ theta)
        P = (P - np.outer(g, phi @ P)) / forgetting
    poles = np.roots([1.0, theta[0], theta[1]]).astype(complex)
    s = np.log(poles) * rate_hz / decimate
    wn = float(np.sqrt(np.abs(s[0] * s[1])))
    zeta = float(np.clip(-np.real(s[0] + s[1]) / (2 * wn), 1e-6, 10.0))
    shape = _model_accel(1.0, 2 * zeta * wn, wn * wn, force, rate_hz, rc_hz)
    sgy = sgg = 0.0
    for n in range(y.size):  # recursive scalar least squares for 1/m
        if ok[n]:
            sgy += shape[n] * y[n]
            sgg += shape[n] * shape[n]
    m = sgg / sgy if sgy != 0 else float("nan")
    return float(m), float(2 * zeta * wn * m), float(wn * wn * m)


def identify_grasp(impacts: list[Impact], estimate: str = "ls") -> dict:
    """Identify every impact and fit m, c, k linearly against grasp force.

    Returns
    -------
    dict
        ``{"m": {"intercept", "slope"}, "c": {…}, "k": {…}, "fit_percent": {"median", "p10",
        "p90", "by_estimate"}, "rmse": {…}, "n_impacts", "estimate"}``.
    """
    if len(impacts) < 3:
        raise ValueError(f"{len(impacts)} impacts: a line through m, c and k against grasp "
                         "force fitted to fewer than 3 has no residual to judge it by")
    fits = [identify_impact(i) for i in impacts]
    fg = np.array([f.grasp_force for f in fits])
    est = np.array([getattr(f, estimate) for f in fits])
    out: dict = {"estimate": estimate, "n_impacts": len(fits)}
    for j, name in enumerate(("m", "c", "k")):
        slope, intercept = np.polyfit(fg, est[:, j], 1)
        out[name] = {"intercept": float(intercept), "slope": float(slope)}
    fp = np.array([f.fit[estimate] for f in fits])
    out["fit_percent"] = {"median": float(np.median(fp)), "p10": float(np.percentile(fp, 10)),
                          "p90": float(np.percentile(fp, 90)),
                          "by_estimate": {e: float(np.median([f.fit[e] for f in fits]))
                                          for e in ("manual", "ls", "rls")}}
    out["rmse"] = {e: float(np.median([f.rmse[e] for f in fits])) for e in ("manual", "ls", "rls")}
    return out
