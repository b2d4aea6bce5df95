"""Closed-form responses of the damped second-order system, valid for every ζ ≥ 0.

    m·ẍ + c·ẋ + k·x = F   (F constant),   ωn = √(k/m),   ζ = c / (2√(k·m))

The deviation y = x − F/k evolves as

    y(t) = e^(−σt)·[y0·C(t) + (v0 + σ·y0)·S(t)],   σ = ζ·ωn
    v(t) = e^(−σt)·[v0·C(t) − (σ·v0 + ωn²·y0)·S(t)]

with (C, S) = (cos ωd·t, sin(ωd·t)/ωd) below critical damping, (1, t) at ζ = 1 and
(cosh α·t, sinh(α·t)/α) above it. The products e^(−σt)·C and e^(−σt)·S are evaluated so
that nothing overflows or cancels:

* ωd² and α² are formed as ωn²·(1 − ζ)(1 + ζ), exact near ζ = 1;
* above critical damping with α·t ≥ 1 the hyperbolic terms are written as the two
  real exponentials e^(−(σ∓α)t), with σ − α = ωn / (ζ + √(ζ² − 1)) (no cancellation);
* sin(ωd·t)/ωd and sinh(α·t)/α stay finite as ωd, α → 0.

These are the analytic references the simulator's discretization is tested against,
and the building block of the grasp-force model.
"""

from __future__ import annotations

import numpy as np

__all__ = ["decay_terms", "free_response", "step_response", "impulse_response"]


def decay_terms(t, wn: float, zeta: float):
    """Return (e^(−σt)·C(t), e^(−σt)·S(t)) for the homogeneous second-order system.

    Parameters
    ----------
    t : array_like [s]
        Times, >= 0.
    wn : float [rad/s]
        Natural frequency, > 0.
    zeta : float [1]
        Damping ratio, >= 0.

    Returns
    -------
    ec, es : ndarray
        Dimensionless and [s] terms; finite for all inputs.
    """
    if not (wn > 0 and np.isfinite(wn)):
        raise ValueError(f"natural frequency must be finite and > 0 rad/s, got {wn!r}")
    if not (zeta >= 0 and np.isfinite(zeta)):
        raise ValueError(f"damping ratio must be finite and >= 0, got {zeta!r}")
    t = np.asarray(t, dtype=float)
    sigma = zeta * wn
    disc = wn * wn * (1.0 - zeta) * (1.0 + zeta)  # ωd² (>0) or −α² (<0)
    env = np.exp(-sigma * t)
    if disc > 0:
        wd = np.sqrt(disc)
        return env * np.cos(wd * t), env * _sin_over(wd, t)
    if disc == 0:
        return env, env * t
    alpha = np.sqrt(-disc)
    at = alpha * t
    small = at < 1.0
    # α·t < 1: direct form, cosh/sinh are O(1), no overflow and no cancellation.
    ec = np.where(small, env * np.cosh(np.where(small, at, 0.0)), 0.0)
    es = np.where(small, env * _sinh_over(alpha, np.where(small, t, 0.0)), 0.0)
    # α·t >= 1: two decaying exponentials; slow rate σ−α computed without cancellation.
    slow = wn / (zeta + np.sqrt((zeta - 1.0) * (zeta + 1.0)))
    fast = sigma + alpha
    tt = np.where(small, 0.0, t)
    e_slow = np.exp(-slow * tt)
    e_fast = np.exp(-fast * tt)
    ec = np.where(small, ec, 0.5 * (e_slow + e_fast))
    es = np.where(small, es, 0.5 * (e_slow - e_fast) / alpha)
    return ec, es


def _sin_over(w: float, t):
    """sin(w·t)/w, finite as w → 0."""
    return t * np.sinc(w * t / np.pi)


def _sinh_over(a: float, t):
    """sinh(a·t)/a for a·t < 1, finite as a → 0."""
    x = a * t
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(np.abs(x) < 1e-8, 1.0 + x * x / 6.0, np.sinh(x) / np.where(x == 0, 1, x))
    return t * ratio


def free_response(t, x0: float, v0: float, wn: float, zeta: float, x_eq: float = 0.0):
    """Position, velocity and acceleration of the second-order system from rest state (x0, v0).

    Parameters
    ----------
    t : array_like [s]
        Times after the initial state.
    x0 : float [m]
        Initial position.
    v0 : float [m/s]
        Initial velocity.
    wn : float [rad/s]
        Natural frequency.
    zeta : float [1]
        Damping ratio (any value >= 0).
    x_eq : float [m]
        Equilibrium position (F/k for a constant force F).

    Returns
    -------
    x, v, a : ndarray
        [m], [m/s], [m/s²].
    """
    ec, es = decay_terms(t, wn, zeta)
    sigma = zeta * wn
    y0 = x0 - x_eq
    y = y0 * ec + (v0 + sigma * y0) * es
    v = v0 * ec - (sigma * v0 + wn * wn * y0) * es
    a = -2.0 * sigma * v - wn * wn * y
    return x_eq + y, v, a


def step_response(t, mass: float, damping: float, stiffness: float, force: float,
                  x0: float = 0.0, v0: float = 0.0):
    """Response of m·ẍ + c·ẋ + k·x = F to a force held constant from t = 0.

    Parameters
    ----------
    t : array_like [s]
    mass : float [kg]
    damping : float [N·s/m]
    stiffness : float [N/m]
    force : float [N]
    x0 : float [m]
    v0 : float [m/s]

    Returns
    -------
    x, v, a : ndarray
        [m], [m/s], [m/s²].
    """
    if mass <= 0 or stiffness <= 0 or damping < 0:
        raise ValueError("mass and stiffness must be > 0 and damping >= 0, got "
                         f"m={mass!r} kg, c={damping!r} N·s/m, k={stiffness!r} N/m")
    wn = np.sqrt(stiffness / mass)
    zeta = damping / (2.0 * np.sqrt(stiffness * mass))
    return free_response(t, x0, v0, wn, zeta, x_eq=force / stiffness)


def impulse_response(t, wn: float, zeta: float):
    """Unit-impulse response h(t) [s] of ÿ + 2ζωn·ẏ + ωn²·y = δ(t): e^(−σt)·S(t)."""
    return decay_terms(t, wn, zeta)[1]
