"""What a protocol asks of a device, checked against one (:func:`protocols.load_protocol`
with ``device``)."""

from __future__ import annotations

import numpy as np

from device import MAX_WINDOW_TICKS, DeviceInfo, LibraryTransient, SceneError, max_spring

from ._adaptive_loader import extreme_samples
from .model import Protocol

__all__ = ["check_device"]


def check_device(cx, proto: Protocol, device: DeviceInfo) -> None:
    """Refuse, naming the field, what ``device`` cannot do of ``proto``: a window longer
    than it records, a current above its rating, a spring stiffer than it renders, a
    transient (a sample's, or one an adaptive phase may come to) it cannot render at its
    servo rate or whose peak at the design speed exceeds the force it delivers."""
    w = proto.window
    most = MAX_WINDOW_TICKS / device.servo_rate_hz
    if w.duration + w.timeout > most:
        raise cx.error(("window", "timeout"),
                       f"a window of {w.duration:g} s after a wait of up to {w.timeout:g} s "
                       f"spans {w.duration + w.timeout:g} s, longer than the device "
                       f"'{device.backend}' records in one window at "
                       f"{device.servo_rate_hz:g} Hz: {most:g} s ({MAX_WINDOW_TICKS} ticks, "
                       "each kept in memory)")
    limit = device.current_limit
    if proto.limits.max_current is not None:
        if proto.limits.max_current > limit:
            raise cx.error(("limits", "max_current"),
                           f"{proto.limits.max_current:g} A exceeds the rating of the device "
                           f"'{device.backend}' ({limit:g} A)")
        limit = proto.limits.max_current
    f_max = limit * device.force_constant
    v = proto.limits.design_speed
    k_max = max_spring(device)
    for i, s in enumerate(proto.samples.values()):
        if s.scene.spring is not None and s.scene.spring > k_max:
            raise cx.error(("samples", i, "scene", "spring"),
                           f"sample '{s.id}': {s.scene.spring:g} N/m is above the stiffest "
                           f"spring the device '{device.backend}' renders, {k_max:.3g} N/m "
                           "(full force within one encoder count, or the sampled spring "
                           "unstable on the moving mass)")
        _check_transient(cx, ("samples", i, "scene", "transient"), f"sample '{s.id}'",
                         s.scene.transient, device, v, f_max, limit)
    for i, phase in enumerate(proto.phases):  # what an adaptive phase may come to render
        if phase.adaptive is not None:
            for what, s in extreme_samples(phase.adaptive, proto.samples):
                _check_transient(cx, ("phases", i), f"phase '{phase.name}', {what}",
                                 s.scene.transient, device, v, f_max, limit)


def _check_transient(cx, path: tuple, what: str, tr, device: DeviceInfo, v: float,
                     f_max: float, limit: float) -> None:
    """Refuse a transient the device cannot render at its servo rate, or whose peak at the
    design speed ``v`` [m/s] exceeds the force it can deliver ``f_max`` [N]."""
    if tr is None or isinstance(tr, LibraryTransient):
        return  # a library's forces exist only once it is built on the device
    try:
        tr.check_for(device.servo_rate_hz)
    except SceneError as exc:
        raise cx.error((*path, exc.field) if exc.field and path[0] == "samples" else path,
                       f"{what}: {exc.reason}") from None
    # what is played at the design speed (a table's rows, blend and attenuation)
    table = tr.table(device.servo_rate_hz, device.effective_mass)
    peak = float(np.max(np.abs(table.force_at(v))))
    if not peak <= f_max:  # a NaN peak fails this too
        raise cx.error(path, f"{what}: transient peak {peak:.2f} N at {v:g} m/s "
                       f"exceeds the {f_max:.2f} N the device can deliver ({limit:g} A × "
                       f"{device.force_constant:g} N/A)")
