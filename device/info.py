"""What a device says about itself: :class:`DeviceInfo` (the handshake of a real device)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

__all__ = ["DeviceInfo"]


@dataclass(frozen=True)
class DeviceInfo:
    """What a device says about itself (the handshake of a real device).

    Attributes
    ----------
    backend : str
        Registered backend name.
    model, serial_number, firmware : str
        What the device says it is.
    servo_rate_hz : float [Hz]
        Servo and sampling rate.
    current_limit : float [A]
        Amplifier current limit; commands above it are clamped and reported.
    force_constant : float [N/A]
        Force at the stylus tip per ampere.
    effective_mass : float [kg]
        Moving mass of the device at the tip (without the hand); scales
        acceleration-specified transients into force.
    watchdog_s : float [s]
        Host-silence period after which output is zeroed and a fault latched.
    encoder_resolution : float [m]
        Position quantum at the tip.
    accel_range : float [m/s²]
        Accelerometer full scale (±).
    accelerometer : bool
        Whether the stylus has an accelerometer (the commercial devices' bridges have none:
        no ``accel`` trace, no acceleration matching).
    tick_p99_s, tick_max_s : float or None [s]
        The 99th percentile and the longest of the servo's tick periods since the device
        started, where its servo follows a computer's clock (the bridges to commercial
        devices, the host builds: LIMITS); None where not measured.
    """

    backend: str
    model: str
    serial_number: str
    firmware: str
    servo_rate_hz: float
    current_limit: float
    force_constant: float
    effective_mass: float
    watchdog_s: float
    encoder_resolution: float
    accel_range: float
    accelerometer: bool = True
    tick_p99_s: float | None = None
    tick_max_s: float | None = None

    @property
    def max_force(self) -> float:
        """Largest force the amplifier can deliver [N]."""
        return self.current_limit * self.force_constant

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["max_force"] = self.max_force
        return d
