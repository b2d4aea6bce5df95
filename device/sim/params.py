"""Parameters of the simulated device, the hand holding it and its sensors.

Defaults describe a Phantom-class stylus device with linear current amplifiers, as
in the contact-realism study (SPEC §1): 10 kHz servo, 1.4 A amplifier limit,
±50 g accelerometer with 1 kHz bandwidth. Mechanical values are chosen so that the
hand-held force→acceleration response resonates near 130 Hz and the whole model is
7th order with relative degree 4, like the model fitted in the paper.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

__all__ = ["DeviceParams", "HandParams"]

G = 9.80665  # standard gravity [m/s²]


@dataclass(frozen=True)
class DeviceParams:
    """The device (hardware) part of the simulation.

    Attributes
    ----------
    servo_rate_hz : float [Hz]
        Servo and sampling rate, 1–20 kHz (ADC, encoder and command all at this rate).
    motor_mass : float [kg]
        Reflected inertia of motor, capstan and proximal links at the tip.
    tip_mass : float [kg]
        Distal link and stylus.
    link_stiffness : float [N/m]
        Transmission (cable and link) compliance between motor side and tip.
    link_damping : float [N·s/m]
        Damping of that compliance.
    motor_damping : float [N·s/m]
        Viscous friction on the motor side.
    force_constant : float [N/A]
        Force at the tip per ampere of motor current.
    current_limit : float [A]
        Amplifier limit; commands above are clamped and reported as saturation.
    amplifier_bandwidth_hz : float [Hz]
        First-order current-loop bandwidth (flat to 1 kHz).
    encoder_resolution : float [m]
        Position quantum at the tip (encoder on the motor shaft).
    velocity_window_s : float [s]
        Span of the least-squares slope over encoder samples used to estimate the
        incoming velocity at contact.
    contact_hysteresis : float [m]
        How far above the surface the encoder must go before another contact counts.
    accel_range : float [m/s²]
        Accelerometer full scale (±).
    accel_bandwidth_hz : float [Hz]
        Accelerometer −3 dB bandwidth (2nd-order Butterworth).
    accel_noise_rms : float [m/s²]
        White measurement noise.
    accel_bits : int
        ADC resolution over the full range.
    watchdog_s : float [s]
        Host-silence period after which output is zeroed and a fault latched.
    ramp_s : float [s]
        Output ramp from zero to full scale after enabling.
    """

    servo_rate_hz: float = 10_000.0
    motor_mass: float = 0.045
    tip_mass: float = 0.010
    link_stiffness: float = 21_000.0
    link_damping: float = 4.0
    motor_damping: float = 0.3
    force_constant: float = 2.15
    current_limit: float = 1.4
    amplifier_bandwidth_hz: float = 5_000.0
    encoder_resolution: float = 1.0e-5
    velocity_window_s: float = 1.0e-3
    contact_hysteresis: float = 2.0e-4
    accel_range: float = 50 * G
    accel_bandwidth_hz: float = 1_000.0
    accel_noise_rms: float = 0.3
    accel_bits: int = 12
    watchdog_s: float = 0.1
    ramp_s: float = 0.05

    def __post_init__(self) -> None:
        if not 1_000.0 <= self.servo_rate_hz <= 100_000.0:
            raise ValueError("servo_rate_hz must be within 1,000–100,000 Hz (up to 20 kHz for "
                             "use, 100 kHz for reference runs), got "
                             f"{self.servo_rate_hz!r}")
        for name in ("motor_mass", "tip_mass", "link_stiffness", "force_constant", "current_limit",
                     "amplifier_bandwidth_hz", "encoder_resolution", "velocity_window_s",
                     "accel_range", "accel_bandwidth_hz", "watchdog_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"device parameter {name} must be finite and > 0, got {v!r}")
        for name in ("link_damping", "motor_damping", "contact_hysteresis", "accel_noise_rms",
                     "ramp_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"device parameter {name} must be finite and >= 0, got {v!r}")

    @property
    def dt(self) -> float:
        """Servo period [s]."""
        return 1.0 / self.servo_rate_hz

    @property
    def effective_mass(self) -> float:
        """Device moving mass at the tip, without the hand [kg]."""
        return self.motor_mass + self.tip_mass

    @property
    def max_force(self) -> float:
        """Force at the current limit [N]."""
        return self.force_constant * self.current_limit

    def with_rate(self, rate_hz: float) -> DeviceParams:
        return replace(self, servo_rate_hz=float(rate_hz))

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class HandParams:
    """The hand holding the stylus, as a mass–spring–damper pulled by the intended motion.

    Attributes
    ----------
    mass : float [kg]
        Fingers and hand moving with the stylus.
    stiffness : float [N/m]
        Grip/arm stiffness towards the intended (reference) position.
    damping : float [N·s/m]
        Grip/arm damping towards the intended velocity.
    """

    mass: float = 0.10
    stiffness: float = 300.0
    damping: float = 4.0

    def __post_init__(self) -> None:
        for name in ("mass", "stiffness", "damping"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"hand parameter {name} must be finite and >= 0, got {v!r}")
        if self.mass <= 0:
            raise ValueError(f"hand mass must be > 0 kg, got {self.mass!r}")
