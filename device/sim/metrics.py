"""Sampled-data realism of a scene: coefficient of restitution and passivity margin.

A virtual spring rendered from sampled, held positions injects energy: during a
contact the held force lags the penetration, so the wall pushes back harder on the
way out than it resisted on the way in. With physical damping b at the device (motor
friction plus the hand's grip), a spring K rendered with period T is passive when

    b > K·T / 2          (Colgate & Schenkel's condition for a ZOH virtual wall)

We report the *passivity margin* b − K·T/2 [N·s/m] (negative: the wall can add
energy) and measure the coefficient of restitution e = |v_out| / |v_in| of a single
tap whose intended motion stops at the surface (so the hand neither drives the stylus
into the wall nor lifts it away): e > 1 means the stylus bounced out faster than it
came in. Real samples are physical contacts with no sampled feedback; their margin
is the physical damping itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..scene import Scene
from .backend import SimDevice
from .params import DeviceParams, HandParams
from .tapper import Tapper

__all__ = ["Restitution", "restitution", "passivity_margin"]


@dataclass(frozen=True)
class Restitution:
    """Result of a single-tap bounce measurement.

    Attributes
    ----------
    v_in, v_out : float [m/s]
        Tip speed entering and leaving the surface (true, not estimated).
    e : float [1]
        v_out / v_in (nan when the stylus never left the surface).
    """

    v_in: float
    v_out: float
    e: float


def passivity_margin(scene: Scene, dev: DeviceParams, hand: HandParams) -> float:
    """b − K·T/2 [N·s/m] for a virtual spring; the physical damping for a real sample."""
    b = dev.motor_damping + hand.damping
    if scene.is_real:
        return b
    return b - float(scene.spring or 0.0) * dev.dt / 2.0


def restitution(scene: Scene, rate_hz: float = 10_000.0, speed: float = 0.11,
                device: DeviceParams | None = None, hand: HandParams | None = None
                ) -> Restitution:
    """Bounce of one tap at ``speed`` [m/s] on ``scene`` at servo rate ``rate_hz`` [Hz].

    A real sample's bounce is read where the kernel located the tip's first meeting with
    it and its first parting from it, inside ticks (:attr:`SimDevice.first_bounce`), so a
    bounce shorter than a tick is measured at any rate; a virtual scene's where the true
    tip position crosses the surface between the recorded ticks."""
    tapper = Tapper(velocity_mean=speed, velocity_sd=0.0, press_depth=0.0, dwell=(2.0, 2.0))
    dev = SimDevice(device=device, hand=hand, tapper=tapper, rate_hz=rate_hz, noise=False)
    dev.load_scene(scene)
    dev.home()
    res = dev.run_window(0.3)
    if scene.is_real:
        v_in, v_out = dev.first_bounce
        if not v_in > 0:
            return Restitution(math.nan, math.nan, math.nan)
        if math.isnan(v_out):
            return Restitution(v_in, 0.0, math.nan)
        return Restitution(v_in, v_out, v_out / v_in)
    tr = res.traces
    z = tr["true_position"] - scene.surface_height
    below = z < 0
    if not below.any():
        return Restitution(float("nan"), float("nan"), float("nan"))
    i_in = int(np.argmax(below))
    v_in = -_at_crossing(z, tr["true_velocity"], tr["true_accel"], i_in - 1, dev.params.dt)
    out = np.flatnonzero(~below[i_in:])
    if out.size == 0:
        return Restitution(v_in, 0.0, float("nan"))
    i_out = i_in + int(out[0])
    v_out = _at_crossing(z, tr["true_velocity"], tr["true_accel"], i_out, dev.params.dt)
    return Restitution(v_in, v_out, v_out / v_in if v_in > 0 else math.nan)


def _at_crossing(z, v, a, i: int, dt: float) -> float:
    """Velocity where z crosses 0 near free-flight tick ``i``, by its local quadratic motion.

    Between ticks the tip moves freely (no contact force), so z ≈ z_i + v_i·τ + a_i·τ²/2
    is accurate to the jerk × τ²; linear interpolation across a contact tick is not.
    """
    zi, vi, ai = float(z[i]), float(v[i]), float(a[i])
    roots = np.roots([ai / 2, vi, zi]) if ai != 0 else np.array([-zi / vi])
    roots = roots[np.isreal(roots)].real
    roots = roots[np.abs(roots) <= 2 * dt] if roots.size else roots
    tau = float(roots[np.argmin(np.abs(roots))]) if roots.size else 0.0
    return vi + ai * tau
