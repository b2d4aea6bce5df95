"""The ``emulator`` backend: a device emulated on a pseudo-terminal, started when it is opened.

``open_device("emulator")`` starts the Python emulator (:mod:`device.serial.emulator`) in a
process of its own, seeded with the ``seed`` it is opened with and paced at ``speed`` × real
time, and talks to it over the wire protocol as to any serial device; ``emulator:BUILD``
starts a build of the reference firmware instead (:data:`~device.serial.firmware.BUILDS`:
the host builds, QEMU, the bridges over the SDKs' stand-ins). Closing the device stops the
process. What the device is and can do comes over the wire as from any device (LIMITS):
simulated contact, seeded.

``hapticlab device emulate`` serves the same emulators until a signal, for a host elsewhere
to open as ``serial:PORT`` (:mod:`device.serial.serving`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from ..registry import AvailableDevice
from .backend import SerialDevice
from .firmware import BUILDS
from .serving import start_emulator

__all__ = ["EmulatedDevice"]


class EmulatedDevice(SerialDevice):
    """A device emulated in a process of its own, started when opened and stopped when
    closed (``emulator`` or ``emulator:BUILD``); otherwise a serial device like any other.
    """

    BACKEND = "emulator"

    @classmethod
    def from_spec(cls, arg: str | None = None, *, seed: int = 0, speed: float = 1.0,
                  live: bool = False, **options: Any) -> EmulatedDevice:
        """Start emulator ``arg`` (:data:`BUILDS`; default ``python``) with ``seed`` at
        ``speed`` × real time (it runs in real time whether or not ``live``), and open it.

        Raises
        ------
        DeviceSpecError
            No such emulator, or a speed it cannot run at.
        DeviceError
            It did not start (with what it said), or did not answer.
        """
        emu = start_emulator(arg or "python", seed=seed, speed=speed)
        try:
            dev = cls(emu.port, **options)
        except BaseException:
            emu.stop()
            raise
        dev.emulator = emu
        return dev

    def _close(self) -> None:
        try:
            super()._close()
        finally:
            self.emulator.stop()

    @classmethod
    def available(cls) -> list[AvailableDevice]:
        """The emulators, one entry: they need nothing but this computer."""
        builds = ", ".join(b for b in BUILDS if BUILDS[b] is not None)
        return [AvailableDevice("emulator", "an emulated device on a pseudo-"
                                "terminal, started when opened (emulator:BUILD for a firmware "
                                f"build, built on first use: {builds})")]

    @classmethod
    @contextmanager
    def conformance_opener(cls) -> Iterator[Callable[[], EmulatedDevice]]:
        """Each check opens (starts) an emulator of its own, as a session does."""
        yield lambda: cls.from_spec(None, seed=5)
