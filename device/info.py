"""What a device says about itself: :class:`DeviceInfo` (the handshake of a real device)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

__all__ = ["DeviceInfo"]


@dataclass(frozen=True)
class DeviceInfo:
    """What a device is and can do, as it says itself (the handshake of a real device).

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
    simulated_contact : bool
        The stylus and what it touches are simulated (the simulated device, the emulator,
        the firmware's builds with their simulated plant, the bridges over the SDKs'
        stand-ins): nobody touches a physical surface. False (the safe default) for a
        device that does not say.
    seeded : bool
        That simulation draws its randomness from a seed fixed when the device was opened
        or started: the same seed gives the same run.
    virtual_time : bool
        The device's clock is simulated, not the world's: it runs as fast as the computer
        can (paced to the wall clock only when opened ``live``), so a window of seconds may
        take milliseconds.

    Code outside a backend asks these, never :attr:`backend` or :attr:`firmware`: they
    name a device for people and for the records, and decide nothing.
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
    simulated_contact: bool = False
    seeded: bool = False
    virtual_time: bool = False

    def ceiling(self, amps: float) -> float:
        """The current limit [A] a request of ``amps`` [A] sets on this device: ``amps``, never
        above the rating (a request equal to the rating up to rounding, 1e-12 of it, is
        the rating). The one place that decides it: a device's
        :meth:`~device.HapticDevice.set_current_limit`, the preflight and the session all
        go through it.

        Raises
        ------
        CurrentLimitError
            ``amps`` is above the rating.
        """
        from .errors import CurrentLimitError

        if amps > self.current_limit * (1 + 1e-12):
            raise CurrentLimitError(f"a current limit of {amps:g} A is above this device's "
                                    f"rating of {self.current_limit:g} A")
        return min(amps, self.current_limit)

    @property
    def max_force(self) -> float:
        """Largest force the amplifier can deliver [N]."""
        return self.current_limit * self.force_constant

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["max_force"] = self.max_force
        return d
