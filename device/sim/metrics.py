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
    """Bounce of one tap at ``speed`` [m/s] on ``scene`` at servo rate ``rate_hz`` [Hz]."""
    tapper = Tapper(velocity_mean=speed, velocity_sd=0.0, press_depth=0.0, dwell=(2.0, 2.0))
    dev = SimDevice(device=device, hand=hand, tapper=tapper, rate_hz=rate_hz, noise=False)
    dev.load_scene(scene)
    dev.home()
    res = dev.run_window(0.3)
    z = res.traces["true_position"] - scene.surface_height
    v = res.traces["true_velocity"]
    below = z < 0
    if not below.any():
        return Restitution(float("nan"), float("nan"), float("nan"))
    i_in = int(np.argmax(below))
    v_in = -float(np.interp(0.0, [z[i_in], z[i_in - 1]], [v[i_in], v[i_in - 1]]))
    out = np.flatnonzero(~below[i_in:])
    if out.size == 0:
        return Restitution(v_in, 0.0, float("nan"))
    i_out = i_in + int(out[0])
    v_out = float(np.interp(0.0, [z[i_out - 1], z[i_out]], [v[i_out - 1], v[i_out]]))
    e = v_out / v_in if v_in > 0 else math.nan
    return Restitution(v_in, v_out, e)
