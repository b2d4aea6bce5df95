"""Device backends, found through the ``hapticlab.backends`` entry-point group.

A backend is a :class:`~device.base.HapticDevice` subclass named by an entry point (python-can
finds its interfaces the same way)::

    [project.entry-points."hapticlab.backends"]
    mylab = "mylab_haptics:MyLabDevice"

hapticlab's own backends (``sim``, ``serial``, ``emulator``) are registered so in its
``pyproject.toml``, and a backend in another distribution is found by installing it: nothing
in hapticlab names it. A backend says what a device is and can do in its
:class:`~device.info.DeviceInfo` (simulated contact, seeded, virtual time, accelerometer,
servo rate), never through its name, and answers three class methods (and a fourth,
``none_found()``, when it has something to say):

``from_spec(arg, **options)``
    Opens the device of the spec ``NAME:arg`` (``arg`` None for ``NAME`` alone). Every
    backend accepts the options ``seed`` (a simulation's seed), ``live`` (pace a
    virtual-time simulation to the wall clock: a person sits at it) and ``speed`` (device
    seconds per wall second where the device's clock is paced), using those that apply and
    ignoring the others; other options are the backend's own.
``available()``
    The devices of this backend that this computer offers, found without opening any (opening
    a serial port can reset a board): what ``hapticlab device list`` prints.
``conformance_opener()``
    A context manager giving a zero-argument opener of a device of this backend that the
    conformance suite (:mod:`device.suite`) runs against on a computer without the hardware.
``none_found()``
    What to check when ``available()`` finds nothing, in words ("" by default): the serial
    backend names the dialout group. ``hapticlab device list`` prints it.

Loading is lazy: importing :mod:`device` imports no backend, and a backend's module is imported
when it is first opened or asked. The entry points are read each time they are asked for (a few
milliseconds), so a distribution installed while a process runs is seen.
"""

from __future__ import annotations

import importlib
import importlib.metadata
from dataclasses import dataclass, replace
from typing import Any

from .errors import BackendError, UnknownBackendError

__all__ = ["ENTRY_POINT_GROUP", "AvailableDevice", "register_backend", "backends", "backend",
           "open_device", "available_devices", "broken_backends", "none_found_hints"]

#: the entry-point group backends are registered in
ENTRY_POINT_GROUP = "hapticlab.backends"

#: backends registered at run time (:func:`register_backend`), by name: a class, or a
#: ``"module:Class"`` reference imported on first use
_REGISTERED: dict[str, Any] = {}


@dataclass(frozen=True)
class AvailableDevice:
    """A device this computer offers, found without opening it.

    Attributes
    ----------
    spec : str
        What opens it (``open_device(spec)``, ``--device SPEC``).
    description : str
        What it is, in words (the system's description of a serial port, ...).
    details : str
        What identifies it further (a USB port's vendor and product ids), or "".
    backend : str
        The name its backend is registered as (:func:`available_devices` fills it in).
    """

    spec: str
    description: str
    details: str = ""
    backend: str = ""

    def to_dict(self) -> dict[str, str]:
        return {"spec": self.spec, "backend": self.backend, "description": self.description,
                "details": self.details}


def register_backend(name: str, device_class: Any) -> None:
    """Register a backend for this process: ``device_class`` (a
    :class:`~device.base.HapticDevice` subclass, or a ``"module:Class"`` reference imported
    on first use) under ``name``, before any entry point of that name.

    A backend in a distribution registers through the ``hapticlab.backends`` entry-point
    group instead; this is for a backend a program defines itself (a test's stand-in).

    Raises
    ------
    ValueError
        An empty name, or one holding ``:``.
    """
    if not isinstance(name, str) or not name or ":" in name:
        raise ValueError(f"backend name must be non-empty and contain no ':', got {name!r}")
    _REGISTERED[name] = device_class


def _entry_points() -> dict[str, importlib.metadata.EntryPoint]:
    """The group's entry points by name (the first installed wins, as Python's path does)."""
    out: dict[str, importlib.metadata.EntryPoint] = {}
    for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        out.setdefault(ep.name, ep)
    return out


def _check_installed(names: set[str]) -> None:
    """hapticlab's own backends are entry points too: none at all means hapticlab's
    installed metadata predates them (an editable install made before), said as such."""
    if not names:
        raise BackendError(
            f"no device backend is registered in the {ENTRY_POINT_GROUP!r} entry-point group, "
            "not even hapticlab's own (sim, serial, emulator): hapticlab's installed metadata "
            "predates them; install it again (pip install -e . in a checkout)")


def backends() -> list[str]:
    """The registered backends' names, sorted: every entry point of the
    ``hapticlab.backends`` group and every :func:`register_backend` of this process.

    Raises
    ------
    BackendError
        Not one is registered (hapticlab's installed metadata predates its entry points).
    """
    names = set(_entry_points()) | set(_REGISTERED)
    _check_installed(names)
    return sorted(names)


def _where(name: str, ep: importlib.metadata.EntryPoint | None) -> str:
    if ep is None:
        return f"backend {name!r} ({_REGISTERED[name]!r}, registered at run time)"
    dist = getattr(ep, "dist", None)
    by = f" of {dist.name} {dist.version}" if dist is not None else ""
    return f"backend {name!r} (entry point {ep.value!r}{by})"


def backend(name: str) -> type:
    """The device class registered as ``name``, its module imported.

    Raises
    ------
    UnknownBackendError
        No backend of that name is registered; the message lists those that are.
    BackendError
        The backend cannot be loaded: its module fails to import, it names nothing there, or
        what it names is not a :class:`~device.base.HapticDevice` subclass (each named, with
        the distribution it came from).
    """
    from .base import HapticDevice

    eps = _entry_points()
    if name in _REGISTERED:
        ref, ep = _REGISTERED[name], None
    elif name in eps:
        ref, ep = eps[name].value, eps[name]
    else:
        raise UnknownBackendError(f"no device backend named {name!r} (registered: "
                                  f"{', '.join(backends())})")
    where = _where(name, ep)
    obj = ref
    if isinstance(ref, str):
        module, _, attr = ref.partition(":")
        try:
            obj = importlib.import_module(module.strip())
            for part in attr.strip().split(".") if attr.strip() else ():
                obj = getattr(obj, part)
        except Exception as exc:  # noqa: BLE001 - any failure of a plugin's import is named
            raise BackendError(f"{where} cannot be loaded: {type(exc).__name__}: "
                               f"{exc}") from exc
    if not (isinstance(obj, type) and issubclass(obj, HapticDevice)):
        raise BackendError(f"{where} names {obj!r}, not a HapticDevice subclass "
                           "(device.HapticDevice)")
    return obj


def open_device(spec: str, **options: Any):
    """Open a device from a spec ``NAME`` or ``NAME:ARG`` (``"sim"``,
    ``"serial:/dev/ttyACM0"``, ``"emulator:host"``): the backend registered as ``NAME``
    opens ``ARG`` with ``options`` (``seed``, ``live`` and ``speed`` taken by every backend).

    Raises
    ------
    UnknownBackendError
        The spec is not a string, or names no registered backend (the message lists those
        that are, and suggests ``serial:PORT`` for what looks like a port).
    BackendError
        The backend cannot be loaded.
    DeviceError
        The backend cannot open the device (its own message).
    """
    if not isinstance(spec, str) or not spec:
        raise UnknownBackendError(f"device spec must be a non-empty string, got {spec!r}")
    name, _, arg = spec.partition(":")
    if name not in _REGISTERED and name not in _entry_points():
        port = spec.startswith(("/", "COM", "com", "\\\\.\\")) or name.startswith("tty")
        hint = f": did you mean serial:{spec}?" if port else ""
        raise UnknownBackendError(
            f"unknown device backend {name!r} in spec {spec!r}{hint} (available: "
            f"{', '.join(backends())}; a port is given as serial:PORT)")
    return backend(name).from_spec(arg or None, **options)


def available_devices() -> list[AvailableDevice]:
    """Every device the registered backends find on this computer, without opening any
    (each backend's ``available()``), in the order of the backends' names. A backend that
    cannot be loaded, or whose search fails, adds nothing here and is named by
    :func:`broken_backends`.

    Examples
    --------
    >>> from device import available_devices
    >>> "sim" in [d.spec for d in available_devices()]
    True
    """
    out: list[AvailableDevice] = []
    for name in backends():
        try:
            found = backend(name).available()
        except Exception:  # noqa: BLE001 - broken_backends() says why
            continue
        out += [replace(d, backend=name) for d in found]  # the name it is registered as
    return out


def none_found_hints() -> dict[str, str]:
    """What to check, by backend name, for each usable backend that finds no device on this
    computer and has something to say (its ``none_found()``: the serial backend's dialout
    group); what ``hapticlab device list`` says after the devices. A backend that cannot be
    used is :func:`broken_backends`' to name, not this."""
    out: dict[str, str] = {}
    for name in backends():
        try:
            cls = backend(name)
            hint = "" if cls.available() else cls.none_found()
        except Exception:  # noqa: BLE001 - broken_backends() says why
            continue
        if hint:
            out[name] = hint
    return out


def broken_backends() -> dict[str, str]:
    """The registered backends that cannot be used, each with why: it cannot be loaded
    (:class:`BackendError`'s message), or its search for devices fails."""
    out: dict[str, str] = {}
    for name in backends():
        try:
            backend(name).available()
        except BackendError as exc:
            out[name] = str(exc)
        except Exception as exc:  # noqa: BLE001 - a plugin's failure, named
            out[name] = f"backend {name!r}: its available() failed: {type(exc).__name__}: {exc}"
    return out
