"""Events and per-window records a device reports."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntFlag

import numpy as np

__all__ = [
    "ContactEvent",
    "SaturationEvent",
    "FaultEvent",
    "Flags",
    "WindowResult",
    "TRACE_CHANNELS",
    "HostClock",
]


@dataclass(frozen=True)
class ContactEvent:
    """A contact detected by the device (position threshold crossing).

    Parameters
    ----------
    t : float [s]
        Device time of the contact.
    velocity : float [m/s]
        Incoming speed into the surface as the device estimated it from its encoder.
    """

    t: float
    velocity: float


@dataclass(frozen=True)
class SaturationEvent:
    """A run of servo ticks where the commanded current exceeded the amplifier limit.

    Parameters
    ----------
    t : float [s]
        Device time when the saturation began.
    peak_current : float [A]
        Largest commanded current magnitude during the run (before clamping).
    duration : float [s]
        Length of the run.
    """

    t: float
    peak_current: float
    duration: float


@dataclass(frozen=True)
class FaultEvent:
    """A latched fault: output is zero until cleared.

    Parameters
    ----------
    t : float [s]
        Device time at which output was zeroed.
    code : str
        ``watchdog``, ``estop``, or a backend-specific code.
    message : str
        Human-readable explanation.
    """

    t: float
    code: str
    message: str


@dataclass(frozen=True)
class HostClock:
    """Where a device's clock lies on this computer's: device time ``t`` [s] happened at
    ``offset_s + rate * t`` on :func:`time.perf_counter`'s clock, within ± ``uncertainty_s``.

    Attributes
    ----------
    offset_s : float [s]
        Host time of device time 0.
    rate : float [1]
        Host seconds per device second (a simulated device on a busy computer, or an
        emulated board, runs slow; a crystal differs by parts per million).
    uncertainty_s : float [s]
        Half-width of the interval the true host time lies in.
    round_trip_s : float or None [s]
        The link's fastest round trip (None: a device without a link); the uncertainty
        rests on it only where no command bounds the time from below (an estimate then).
    pairs : int
        Clock readings the mapping was fitted to.
    """

    offset_s: float
    rate: float
    uncertainty_s: float
    round_trip_s: float | None
    pairs: int

    def on_host(self, t: float) -> float:
        """Host time [s, perf_counter] of device time ``t`` [s]."""
        return self.offset_s + self.rate * t


class Flags(IntFlag):
    """Per-tick status bits in ``WindowResult.traces['flags']``."""

    CONTACT = 1  #: the device considers the stylus in contact (encoder below the surface)
    SATURATED = 2  #: commanded current clamped at the amplifier limit
    TRANSIENT = 4  #: an open-loop transient is playing
    ZEROED = 8  #: output forced to zero by a latched fault
    RAMP = 16  #: output ramp after enable still below full scale
    ACCEL_CLIPPED = 32  #: accelerometer reading at its range limit


#: name → (unit, description) of the channels every backend records per servo tick.
TRACE_CHANNELS: dict[str, tuple[str, str]] = {
    "t": ("s", "device time"),
    "position": ("m", "encoder position (quantized)"),
    "velocity": ("m/s", "velocity estimated from encoder positions"),
    "force_cmd": ("N", "commanded force before the current clamp"),
    "force_out": ("N", "force delivered by the amplifier and actuator"),
    "current": ("A", "amplifier current after the clamp"),
    "accel": ("m/s^2", "accelerometer reading"),
    "flags": ("1", "bit field of Flags"),
}


@dataclass
class WindowResult:
    """Everything a device reports for one tapping window.

    Attributes
    ----------
    rate_hz : float [Hz]
        Rate of the traces: the servo rate, or the servo rate / decimation when the
        device's link is too narrow to stream every tick (a 1-Mbaud UART).
    t_first_contact : float or None [s]
        Device time of the first contact (the window is measured from it).
    contacts, saturations, faults : list
        Events in time order.
    traces : dict of str → ndarray
        Channels of :data:`TRACE_CHANNELS`, one sample per record (``rate_hz``); backends may
        add more (the simulator adds ``true_*`` channels).
    timed_out : bool
        True when no contact happened before the wait limit.
    timing : dict
        Backend timing report (e.g. achieved loop rate and jitter in live mode).
    energy : dict
        Work across the stylus's ports over the window [J], from backends that can know it
        (the simulator): ``in`` the stylus did on the actuator and on a real sample, ``out``
        they did on the stylus. A passive sample never gives out more than it took in.
    warnings : list of str
        What the backend could not do as asked, in words (see :attr:`warnings`).
    """

    rate_hz: float
    t_first_contact: float | None
    contacts: list[ContactEvent] = field(default_factory=list)
    saturations: list[SaturationEvent] = field(default_factory=list)
    faults: list[FaultEvent] = field(default_factory=list)
    traces: dict[str, np.ndarray] = field(default_factory=dict)
    timed_out: bool = False
    timing: dict[str, float] = field(default_factory=dict)
    energy: dict[str, float] = field(default_factory=dict)
    live_height: float | None = None  #: in progress callbacks: stylus above the surface [m]
    #: what the backend could not do as asked, one sentence each (the simulator: a contact
    #: that chattered, contact changes it could not locate)
    warnings: list[str] = field(default_factory=list)

    @property
    def velocities(self) -> np.ndarray:
        """Incoming speeds [m/s] of the window's contacts."""
        return np.array([c.velocity for c in self.contacts], dtype=float)

    @property
    def saturated(self) -> bool:
        """True when any tick of the window saturated."""
        return bool(self.saturations)

    @property
    def peak_current(self) -> float:
        """Largest commanded current [A] of the window (0 when nothing was commanded)."""
        if "force_cmd" not in self.traces or "current" not in self.traces:
            return 0.0
        peaks = [s.peak_current for s in self.saturations]
        cur = self.traces["current"]
        return float(max([float(np.max(np.abs(cur))) if cur.size else 0.0, *peaks]))
