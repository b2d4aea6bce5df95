"""Transients into tables for one device: the single place where this happens.

Every backend renders a :class:`~device.scene.TransientTable` (speeds × force per servo
tick) and nothing else; :func:`transient_table` turns any :class:`~device.scene.Transient`
into the table a given device plays. A parametric transient is sampled at the device's
servo rate (scaled by its effective mass where it is given in acceleration); an
acceleration-matched library is read from its file, which must have been built on that
very device (:func:`device.matching.library.find_library` finds it in the library store).
Building a library is an experiment of its own and never happens here.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .errors import SceneError
from .scene import MAX_TRANSIENT_S, LibraryTransient, Transient, TransientTable

if TYPE_CHECKING:
    from .info import DeviceInfo

__all__ = ["transient_table"]


def transient_table(transient: Transient, info: DeviceInfo) -> TransientTable:
    """The table a device described by ``info`` plays for ``transient``.

    Parameters
    ----------
    transient : Transient
    info : DeviceInfo
        The device's servo rate [Hz] and effective mass [kg] decide the table.

    Raises
    ------
    SceneError
        A library transient without a library file for this device (the message gives the
        command that builds one), or a library file that cannot be used on it.
    """
    if isinstance(transient, LibraryTransient):
        from .matching.library import LibraryError, TransientLibrary, find_library

        path = transient.path or find_library(info, transient)
        if path is None:
            raise SceneError(
                f"no library reproducing '{transient.source}' has been built on this device "
                f"({info.model}, serial {info.serial_number}, {info.servo_rate_hz:g} Hz); "
                f"build it with: hapticlab library build --device SPEC --source "
                f"{transient.source} (or name a file in the sample's 'path')", "path",
                where=f"transient 'library' of '{transient.source}'")
        try:
            lib = TransientLibrary.load(path, info)
        except LibraryError as exc:
            raise SceneError(str(exc), "path",
                             where=f"transient 'library' of '{transient.source}'") from None
        length = lib.forces.shape[1] / info.servo_rate_hz
        if not length <= MAX_TRANSIENT_S:
            raise SceneError(f"{path}: its transients last {length:.3g} s; at most "
                             f"{MAX_TRANSIENT_S:g} s", "path",
                             where=f"transient 'library' of '{transient.source}'")
        return lib.table(transient.attenuation, transient.blend)
    return transient.table(info.servo_rate_hz, info.effective_mass)
