"""Typed errors raised by the device layer, and the root of every hapticlab error.

:class:`HapticlabError` is the one root: every error hapticlab raises for a bad input, a file
it cannot use or a device that fails derives from it, and the command line prints it on one
line (exit 2). It lives here, in the lowest package, so that :mod:`protocols` and :mod:`app`
can derive from it; :mod:`analysis` imports nothing of ours and keeps ``ValueError``
subclasses (in the manner of pingouin), which the application wraps at its boundary.
"""

from __future__ import annotations

__all__ = [
    "HapticlabError",
    "DeviceError",
    "SceneError",
    "UnknownBackendError",
    "BackendError",
    "CurrentLimitError",
    "DeviceSpecError",
    "DeviceFaultError",
]


class HapticlabError(Exception):
    """Root of every error hapticlab raises on purpose (bad input, unusable files, devices)."""


class DeviceError(HapticlabError):
    """Base class of every error raised by :mod:`device`.

    Attributes
    ----------
    partial : WindowResult or None
        When a window failed part way: what it had delivered (contacts, saturations), so
        nothing received is lost.
    """

    partial = None


class SceneError(DeviceError, ValueError):
    """A scene description is invalid.

    The message is ``where: field: reason``. A caller that knows the place better (the
    protocol loader knows the file and line) uses :attr:`reason`, :attr:`part` and
    :attr:`field` and writes its own place in front.

    Parameters
    ----------
    reason : str
        What is wrong and what is allowed, without any place (``must be > 0, got -1``).
    field : str or None
        The offending field's name.
    part : tuple of str
        Where in the scene the field sits, e.g. ``("transient",)`` or ``("material",
        "ringing")``.
    where : str
        Human name of the place (``scene 'wood'``, ``transient 'pulse'``).
    """

    def __init__(self, reason: str, field: str | None = None, part: tuple[str, ...] = (),
                 where: str = ""):
        self.reason = reason
        self.field = field
        self.part = tuple(part)
        self.where = where
        super().__init__(": ".join(x for x in (where, field, reason) if x))

    def within(self, part: tuple[str, ...] = (), where: str | None = None) -> SceneError:
        """The same error placed one level further out (``part`` is prepended)."""
        return SceneError(self.reason, self.field, (*part, *self.part),
                          self.where if where is None else where)


class DeviceSpecError(DeviceError, ValueError):
    """A device spec or option that cannot be used (the message says what is allowed)."""


class UnknownBackendError(DeviceSpecError):
    """``open_device`` was given a spec whose backend is not registered."""


class BackendError(DeviceError):
    """A registered backend cannot be used: its module fails to import, its entry point
    names nothing or something that is not a device class (the message names the backend,
    the entry point and the distribution it came from)."""


class CurrentLimitError(DeviceError):
    """A current limit above the device's rating was asked for
    (:meth:`device.info.DeviceInfo.ceiling`, the one place that decides it)."""


class DeviceFaultError(DeviceError):
    """The device has a latched fault (e-stop, watchdog) and will not drive output until cleared."""
