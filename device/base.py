"""The :class:`HapticDevice` interface, its backend registry and the ``open_device`` factory.

Backends register a name and a factory (python-can style). The factory receives the
part of the spec after the colon (``"serial:/dev/ttyACM0"`` → ``"/dev/ttyACM0"``) and
keyword options. Registration may name a ``"module:attribute"`` string so that a
backend's heavy imports happen only when it is opened.
"""

from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

from .errors import UnknownBackendError
from .events import FaultEvent, WindowResult
from .scene import Scene

__all__ = ["DeviceInfo", "HapticDevice", "register_backend", "open_device", "backends"]


@dataclass(frozen=True)
class DeviceInfo:
    """What a device says about itself (the handshake of a real device).

    Attributes
    ----------
    backend : str
        Registered backend name.
    model, serial_number, firmware : str
        Identification.
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

    @property
    def max_force(self) -> float:
        """Largest force the amplifier can deliver [N]."""
        return self.current_limit * self.force_constant

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["max_force"] = self.max_force
        return d


class HapticDevice(ABC):
    """A force-feedback device that renders scenes and reports contacts.

    Use as a context manager: output is zero on every exit path.

    The life of a trial: :meth:`load_scene` → :meth:`home` → :meth:`run_window`
    (events and traces in a :class:`~device.events.WindowResult`). A latched fault
    (:meth:`estop`, watchdog) keeps output at zero until :meth:`clear_fault`.
    """

    # ---------------------------------------------------------------- identity
    @property
    @abstractmethod
    def info(self) -> DeviceInfo:
        """Static description of the device."""

    # ----------------------------------------------------------------- control
    @abstractmethod
    def load_scene(self, scene: Scene) -> None:
        """Prepare the device to render ``scene`` (uploads only what the scene needs)."""

    @abstractmethod
    def home(self, clearance: float = 0.02) -> None:
        """Move the stylus to rest ``clearance`` [m] above the surface and enable output."""

    @abstractmethod
    def run_window(self, duration: float = 5.0, *, from_first_contact: bool = True,
                   timeout: float = 30.0,
                   on_progress: Callable[[float, WindowResult], None] | None = None,
                   heartbeats: bool = True) -> WindowResult:
        """Render the loaded scene for one tapping window.

        Parameters
        ----------
        duration : float [s]
            Window length, counted from the first contact when ``from_first_contact``.
        timeout : float [s]
            Longest wait for a first contact; the result has ``timed_out`` set.
        on_progress : callable, optional
            Called as ``on_progress(t, partial_result)`` a few times per second of
            device time (live velocities, operator e-stop).
        heartbeats : bool
            Keep the host heartbeat going during the window (default). False makes the
            host go silent, which trips the watchdog: the device-safety test.
        """

    @abstractmethod
    def play_force(self, force, *, heartbeats: bool = True) -> WindowResult:
        """Play an open-loop force command [N per servo tick] while the hand holds still.

        The stylus is in free air; the command still passes the enable ramp, watchdog and
        current clamp. Used for system identification (swept sines) and for checking
        transients. Home again before the next tapping window.
        """

    @abstractmethod
    def heartbeat(self) -> None:
        """Tell the device the host is alive (resets the watchdog)."""

    @abstractmethod
    def estop(self) -> None:
        """Latched emergency stop: output to zero now and until :meth:`clear_fault`."""

    @abstractmethod
    def clear_fault(self) -> None:
        """Clear a latched fault; output resumes (ramped) at the next :meth:`home`."""

    @property
    @abstractmethod
    def fault(self) -> FaultEvent | None:
        """The latched fault, or None."""

    @property
    @abstractmethod
    def output_force(self) -> float:
        """Force [N] the device is commanding right now (0 when idle, zeroed or closed)."""

    @abstractmethod
    def zero(self) -> None:
        """Command zero output immediately (not latched)."""

    @abstractmethod
    def close(self) -> None:
        """Zero output and release the device. Idempotent."""

    # ----------------------------------------------------------- conveniences
    def __enter__(self) -> HapticDevice:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


_Factory = Callable[..., HapticDevice]
_BACKENDS: dict[str, _Factory | str] = {
    "sim": "device.sim.backend:SimDevice.from_spec",
    "serial": "device.serial.backend:SerialDevice.from_spec",
}


def register_backend(name: str, factory: _Factory | str) -> None:
    """Register ``factory(arg, **options) -> HapticDevice`` under ``name``.

    ``factory`` may be a ``"module:attr.path"`` string, imported on first use.
    """
    if not name or ":" in name:
        raise ValueError(f"backend name must be non-empty and contain no ':', got {name!r}")
    _BACKENDS[name] = factory


def backends() -> list[str]:
    """Registered backend names, sorted."""
    return sorted(_BACKENDS)


def _resolve(factory: _Factory | str) -> _Factory:
    if not isinstance(factory, str):
        return factory
    module, _, attr = factory.partition(":")
    obj: Any = importlib.import_module(module)
    for part in attr.split("."):
        obj = getattr(obj, part)
    return obj


def open_device(spec: str, **options: Any) -> HapticDevice:
    """Open a device from a spec string such as ``"sim"`` or ``"serial:/dev/ttyACM0"``.

    Raises
    ------
    UnknownBackendError
        When the backend name is not registered; the message lists those that are.
    """
    if not isinstance(spec, str) or not spec:
        raise UnknownBackendError(f"device spec must be a non-empty string, got {spec!r}")
    name, _, arg = spec.partition(":")
    if name not in _BACKENDS:
        raise UnknownBackendError(
            f"unknown device backend {name!r} in spec {spec!r}; available: {', '.join(backends())}")
    return _resolve(_BACKENDS[name])(arg or None, **options)
