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
    """A scene description is invalid; the message names the field, value and what is allowed."""


class UnknownBackendError(DeviceError, ValueError):
    """``open_device`` was given a spec whose backend is not registered."""


class DeviceFaultError(DeviceError):
    """The device has a latched fault (e-stop, watchdog) and will not drive output until cleared."""
