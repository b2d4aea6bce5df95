"""Continuous-time linear dynamics of device + hand (+ sample) and their exact ZOH discretization.

States (SI units)::

    0 z1   motor-side position [m]         (the encoder reads this one)
    1 v1   motor-side velocity [m/s]
    2 z2   tip/hand position [m]            (the accelerometer sits here)
    3 v2   tip/hand velocity [m/s]
    4 fa   force delivered by the amplifier/actuator [N]
    5 y    accelerometer output before noise/ADC [m/s²]
    6 yd   its derivative [m/s³]
    7 fh   the hand's pull k_h·z_ref + b_h·v_ref towards its intended motion [N]
    8 q    sample ringing acceleration [m/s²]   (only for real samples that ring)
    9 qd   its derivative [m/s³]

Inputs, held constant over each servo tick::

    0 f_cmd   commanded force after the current clamp [N] (zero-order hold: what a
              sampled-data device does)
    1 fh_rate slope of the hand's pull over the tick [N/s] (the hand is a continuous
              input: its pull is interpolated linearly between ticks, not held)
    2 one     constant 1 (carries k_s·h of the contact spring)

A real sample adds a second *mode* (in contact), in which the tip feels
k_s·(h − z2) − b_s·v2 from the sample; the ringing state, once excited at a
contact, adds M2·q to the tip. Everything is linear within a mode, so the exact
discrete propagator over a tick is the matrix exponential of the augmented matrix
[[A, B], [0, 0]]·T (Van Loan); mode switches are located inside a tick by the
kernel (see :mod:`device.sim.kernel`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from ..scene import Material, Ringing
from .params import DeviceParams, HandParams

__all__ = ["Plant", "build_plant", "zoh", "piece_propagators", "N_INPUTS"]

Z1, V1, Z2, V2, FA, Y, YD, FH, Q, QD = range(10)
U_CMD, U_HAND_RATE, U_ONE = range(3)
N_INPUTS = 3
N_LEVELS = 30  # bisection depth for locating a contact switch inside a substep


@dataclass
class Plant:
    """Continuous-time matrices per mode and what the kernel needs to switch modes.

    Attributes
    ----------
    A : ndarray, shape (n_modes, ns, ns)
    B : ndarray, shape (n_modes, ns, N_INPUTS)
    accel_row : ndarray, shape (n_modes, ns + N_INPUTS)
        True tip acceleration as a row over [x; u].
    ring_gain : float [1/s · rad/s]
        Added to qd per unit normal velocity at a contact (A·ω); 0 without ringing.
    contact_stiffness, contact_damping : float
        k_s [N/m], b_s [N·s/m] of the real sample (0 for virtual samples).
    n_sub : int
        Substeps per tick for contact-switch detection (1 without a real sample).
    """

    A: np.ndarray
    B: np.ndarray
    accel_row: np.ndarray
    ring_gain: float
    contact_stiffness: float
    contact_damping: float
    surface_height: float
    n_sub: int

    @property
    def n_states(self) -> int:
        return self.A.shape[1]

    @property
    def n_modes(self) -> int:
        return self.A.shape[0]


def _mode_matrices(dev: DeviceParams, hand: HandParams, ringing: Ringing | None,
                   contact: Material | None, h: float) -> tuple[np.ndarray, np.ndarray]:
    """A and B of one mode; ``contact`` is the sample touching the tip (None: free)."""
    ns = 10 if ringing is not None else 8
    m1 = dev.motor_mass
    m2 = dev.tip_mass + hand.mass
    A = np.zeros((ns, ns))
    B = np.zeros((ns, N_INPUTS))
    kl, bl = dev.link_stiffness, dev.link_damping
    A[Z1, V1] = 1.0
    A[V1, Z1], A[V1, Z2] = -kl / m1, kl / m1
    A[V1, V1], A[V1, V2] = -(bl + dev.motor_damping) / m1, bl / m1
    A[V1, FA] = 1.0 / m1
    A[Z2, V2] = 1.0
    A[V2, Z1], A[V2, Z2] = kl / m2, -(kl + hand.stiffness) / m2
    A[V2, V1], A[V2, V2] = bl / m2, -(bl + hand.damping) / m2
    A[V2, FH] = 1.0 / m2
    B[FH, U_HAND_RATE] = 1.0
    if contact is not None:
        A[V2, Z2] -= contact.stiffness / m2
        A[V2, V2] -= contact.damping / m2
        B[V2, U_ONE] = contact.stiffness * h / m2
    if ringing is not None:
        # The sample's vibration, once excited, keeps decaying in both modes and pushes
        # the tip with M2·q: it lasts ~1/B, shorter than a bounce, and is not gated by it.
        w = 2 * math.pi * ringing.frequency
        A[V2, Q] = 1.0
        A[Q, QD] = 1.0
        A[QD, Q] = -(ringing.decay**2 + w * w)
        A[QD, QD] = -2.0 * ringing.decay
    wa = 2 * math.pi * dev.amplifier_bandwidth_hz
    A[FA, FA] = -wa
    B[FA, U_CMD] = wa
    wy = 2 * math.pi * dev.accel_bandwidth_hz  # 2nd-order Butterworth on the tip acceleration
    A[Y, YD] = 1.0
    A[YD, :] += wy * wy * A[V2, :]
    B[YD, :] += wy * wy * B[V2, :]
    A[YD, Y] -= wy * wy
    A[YD, YD] -= math.sqrt(2.0) * wy
    return A, B


def build_plant(dev: DeviceParams, hand: HandParams, material: Material | None = None,
                surface_height: float = 0.0) -> Plant:
    """Assemble the continuous-time model for one scene.

    Only what the scene requires is modelled: a virtual scene has one mode and
    eight states; a real sample adds the contact mode, and ringing adds two states.
    """
    ringing = material.ringing if material is not None else None
    modes = [_mode_matrices(dev, hand, ringing, None, surface_height)]
    ring_gain = 0.0
    n_sub = 1
    if material is not None:
        modes.append(_mode_matrices(dev, hand, ringing, material, surface_height))
        if ringing is not None:
            ring_gain = ringing.slope * 2 * math.pi * ringing.frequency
        wc = math.sqrt(material.stiffness / (dev.tip_mass + hand.mass))
        # substep <= 1/8 of the contact period: a contact cannot begin and end unseen
        n_sub = max(1, math.ceil(dev.dt / (2 * math.pi / wc / 8)))
    A = np.stack([m[0] for m in modes])
    B = np.stack([m[1] for m in modes])
    accel_row = np.concatenate([A[:, V2, :], B[:, V2, :]], axis=1)
    return Plant(A=A, B=B, accel_row=accel_row, ring_gain=ring_gain,
                 contact_stiffness=material.stiffness if material else 0.0,
                 contact_damping=material.damping if material else 0.0,
                 surface_height=surface_height, n_sub=n_sub)


def zoh(A: np.ndarray, B: np.ndarray, dt: float) -> np.ndarray:
    """Exact zero-order-hold propagator [Φ | Γ] over ``dt`` [s].

    x(t+dt) = Φ·x(t) + Γ·u with u held constant: Φ = e^(A·dt), Γ = ∫₀^dt e^(A·s) ds·B,
    both read off the exponential of the augmented matrix [[A, B], [0, 0]]·dt.

    Returns
    -------
    ndarray, shape (ns, ns + nu)
    """
    ns, nu = B.shape
    M = np.zeros((ns + nu, ns + nu))
    M[:ns, :ns] = A
    M[:ns, ns:] = B
    E = expm(M * dt)
    return np.ascontiguousarray(E[:ns, :])


def piece_propagators(A: np.ndarray, B: np.ndarray, h: float, levels: int = N_LEVELS) -> np.ndarray:
    """Propagators over h·2^(j−levels), j = 0..levels (the last one spans ``h``).

    Returns
    -------
    ndarray, shape (levels + 1, ns, ns + nu)
    """
    return np.stack([zoh(A, B, h * 2.0 ** (j - levels)) for j in range(levels + 1)])
