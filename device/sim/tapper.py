"""A simulated hand that taps: the intended motion fed to the hand impedance.

Each tap is a stroke of the *reference* (intended) stylus height, relative to the
surface:

1. accelerate downwards from ``top`` with a raised-cosine velocity ramp (``accel_time``)
   to the tap's speed v;
2. cruise at −v until the reference is ``press_depth`` below the surface (the real
   stylus is stopped by the surface on the way; it then presses with the hand
   stiffness × the remaining distance);
3. dwell there, rise back to ``top`` along a half cosine, pause, repeat.

The hand pulls the stylus with its impedance towards the intended motion and adds
what an internal model of the moving mass would (mass × intended acceleration plus
the device's friction × intended velocity): in free air the stylus follows the
intention, and on contact the impedance alone reacts.

The speed of each tap is drawn from a normal distribution (default 0.11 ± 0.033 m/s,
the incoming velocities reported in SPEC §1), truncated to [v_min, v_max]. The stylus
follows the reference through the hand's mass–spring–damper, so the speed at
contact is close to, not equal to, v — and the device measures it with its encoder.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._jit import lazy_njit

__all__ = ["Tapper", "TapPlan", "HoldPlan"]


@dataclass(frozen=True)
class Tapper:
    """Tapping behaviour of a simulated person.

    Attributes
    ----------
    velocity_mean, velocity_sd : float [m/s]
        Distribution of intended tap speeds.
    velocity_min, velocity_max : float [m/s]
        Truncation of that distribution.
    top : float [m]
        Height above the surface where each stroke starts (and where homing leaves the stylus).
    press_depth : float [m]
        How far below the surface the intended motion goes (0: it stops at the surface).
    accel_time : float [s]
        Duration of the velocity ramp at the start of a stroke.
    dwell : tuple of float [s]
        Range of the time held pressed.
    rise_time : float [s]
        Duration of the lift back to ``top``.
    pause : tuple of float [s]
        Range of the rest at the top between taps.
    sweep : tuple of float [m/s]
        When given, the intended speeds in turn (cycled) instead of drawn ones — for
        measurements that must cover a range, such as the energy audit.
    """

    velocity_mean: float = 0.11
    velocity_sd: float = 0.033
    velocity_min: float = 0.02
    velocity_max: float = 0.40
    top: float = 0.02
    press_depth: float = 0.004
    accel_time: float = 0.06
    dwell: tuple[float, float] = (0.06, 0.12)
    rise_time: float = 0.20
    pause: tuple[float, float] = (0.05, 0.20)
    sweep: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        checks = {
            "velocity_mean": self.velocity_mean > 0, "velocity_sd": self.velocity_sd >= 0,
            "velocity_min": 0 < self.velocity_min <= self.velocity_max,
            "top": self.top > 0, "press_depth": self.press_depth >= 0,
            "accel_time": self.accel_time > 0, "rise_time": self.rise_time > 0,
            "dwell": 0 <= self.dwell[0] <= self.dwell[1],
            "pause": 0 <= self.pause[0] <= self.pause[1],
            "sweep": all(np.isfinite(v) and v > 0 for v in self.sweep),
        }
        for name, ok in checks.items():
            if not ok:
                raise ValueError(f"tapper parameter {name} out of range: {getattr(self, name)!r}")

    def plan(self, rng: np.random.Generator, duration: float, surface_height: float = 0.0,
             speeds: np.ndarray | None = None) -> TapPlan:
        """Draw the strokes covering ``duration`` [s] of device time.

        Parameters
        ----------
        rng : numpy.random.Generator
            Source of all randomness (tap speeds, dwell and pause times).
        duration : float [s]
        surface_height : float [m]
        speeds : array_like, optional [m/s]
            Intended speeds to use instead of drawing them (cycled).
        """
        strokes = []
        t = 0.0
        i = 0
        if speeds is None and self.sweep:
            speeds = np.asarray(self.sweep, dtype=float)
        while t < duration:
            if speeds is not None:
                v = float(np.asarray(speeds, dtype=float)[i % len(speeds)])
            else:
                v = float(np.clip(rng.normal(self.velocity_mean, self.velocity_sd),
                                  self.velocity_min, self.velocity_max))
            dwell = float(rng.uniform(*self.dwell))
            pause = float(rng.uniform(*self.pause))
            dist = self.top + self.press_depth
            ta = min(self.accel_time, 2 * dist / v)
            tc = max(0.0, (dist - v * ta / 2) / v)
            strokes.append((t, v, ta, tc, dwell, self.rise_time, pause))
            t += ta + tc + dwell + self.rise_time + pause
            i += 1
        return TapPlan(np.array(strokes, dtype=float), self.top, self.press_depth,
                       float(surface_height))


@dataclass
class TapPlan:
    """Strokes of one window; evaluates the intended position and velocity at any time.

    ``strokes`` columns: start [s], speed [m/s], accel, cruise, dwell, rise, pause [s].
    """

    strokes: np.ndarray
    top: float
    press_depth: float
    surface_height: float

    @property
    def speeds(self) -> np.ndarray:
        """Intended speed of each tap [m/s]."""
        return self.strokes[:, 1]

    def reference(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Intended height [m], velocity [m/s] and acceleration [m/s²] at times ``t`` [s].

        ``t`` must be sorted. The acceleration omits the impulse where a stroke stops
        at its bottom (the stylus is against the surface then).
        """
        t = np.ascontiguousarray(t, dtype=float)
        z = np.empty_like(t)
        v = np.empty_like(t)
        a = np.empty_like(t)
        _reference(t, self.strokes, self.top, -self.press_depth, self.surface_height, z, v, a)
        return z, v, a


@dataclass
class HoldPlan:
    """The hand holding the stylus still at ``height`` [m] (for system-identification runs)."""

    height: float

    def reference(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.asarray(t, dtype=float)
        return np.full_like(t, self.height), np.zeros_like(t), np.zeros_like(t)


@lazy_njit
def _reference(t, strokes, top, bottom, h, z_out, v_out, a_out):
    """Piecewise stroke profile (see the module docstring); ``t`` ascending."""
    k = 0
    n_str = strokes.shape[0]
    for i in range(t.shape[0]):
        while k + 1 < n_str and t[i] >= strokes[k + 1, 0]:
            k += 1
        t0, v, ta, tc, dw, tr = (strokes[k, 0], strokes[k, 1], strokes[k, 2], strokes[k, 3],
                                 strokes[k, 4], strokes[k, 5])
        tau = max(t[i] - t0, 0.0)
        if tau < ta:  # raised-cosine velocity ramp
            x = tau / ta
            z = top - v * (tau / 2 - ta / (2 * math.pi) * math.sin(math.pi * x))
            vel = -v * (1 - math.cos(math.pi * x)) / 2
            acc = -v * math.pi / (2 * ta) * math.sin(math.pi * x)
        elif tau < ta + tc:  # cruise
            z = top - v * ta / 2 - v * (tau - ta)
            vel = -v
            acc = 0.0
        elif tau < ta + tc + dw:  # dwell pressed
            z = bottom
            vel = 0.0
            acc = 0.0
        elif tau < ta + tc + dw + tr:  # half-cosine rise
            y = (tau - ta - tc - dw) / tr
            z = bottom + (top - bottom) * (1 - math.cos(math.pi * y)) / 2
            vel = (top - bottom) * math.pi / (2 * tr) * math.sin(math.pi * y)
            acc = (top - bottom) * (math.pi / tr) ** 2 / 2 * math.cos(math.pi * y)
        else:  # pause at the top
            z = top
            vel = 0.0
            acc = 0.0
        z_out[i] = h + z
        v_out[i] = vel
        a_out[i] = acc
