"""Typed errors raised by the device layer."""

__all__ = [
    "DeviceError",
    "SceneError",
    "UnknownBackendError",
    "DeviceFaultError",
]


class DeviceError(Exception):
    """Base class of every error raised by :mod:`device`."""


class SceneError(DeviceError, ValueError):
    """A scene description is invalid; the message names the field, value and what is allowed.

    Attributes
    ----------
    part : tuple of str
        Where in the scene the field sits, e.g. ``("transient",)`` or ``("material", "ringing")``.
    field : str or None
        The offending field's name.
    """

    def __init__(self, message: str, field: str | None = None, part: tuple[str, ...] = ()):
        super().__init__(message)
        self.field = field
        self.part = tuple(part)


class UnknownBackendError(DeviceError, ValueError):
    """``open_device`` was given a spec whose backend is not registered."""


class DeviceFaultError(DeviceError):
    """The device has a latched fault (e-stop, watchdog) and will not drive output until cleared."""
