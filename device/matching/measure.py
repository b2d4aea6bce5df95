"""One measurement at a time: what a fault costs, and how far a long job has come.

System identification and library builds are sequences of measurements (a swept sine, a tapping
window) of a few seconds each. A fault during one (the watchdog, an e-stop, the device's
own button) spoils that measurement only: :func:`measured` hands it to the caller's
``on_fault``, which tells the operator what happened and clears the fault on their word,
and then measures again; without ``on_fault`` (or when the operator stops) it raises
:class:`MeasurementFault`, and whatever was measured before is the caller's to keep.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from ..errors import DeviceError, DeviceFaultError
from ..events import FaultEvent, WindowResult

__all__ = ["MeasurementFault", "Step", "Pace", "measured", "OnFault", "OnStep"]


class MeasurementFault(DeviceError):
    """A fault latched during a measurement and was not cleared (no operator, or the
    operator stopped); ``fault`` is the device's :class:`~device.events.FaultEvent` and
    ``what`` names the measurement."""

    def __init__(self, fault: FaultEvent | None, what: str):
        code = fault.code if fault is not None else "latched"
        why = f" ({fault.message})" if fault is not None else ""
        super().__init__(f"{code} fault during {what}{why}")
        self.fault = fault
        self.what = what


@dataclass(frozen=True)
class Step:
    """Where a long job stands, after a measurement (or before the computation that ends it).

    Attributes
    ----------
    done, total : int
        Measurements finished (kept from an earlier run included) and in all.
    what : str
        The one just finished, e.g. ``"sweep 1 N, repeat 2 of 4"``.
    seconds_left : float or None [s]
        The measurements still to do, at the pace measured so far (None before any).
    """

    done: int
    total: int
    what: str
    seconds_left: float | None


#: ``on_fault(fault, what) -> bool``: True when the fault was cleared and the measurement may
#: run again, False to stop
OnFault = Callable[[FaultEvent | None, str], bool]
#: ``on_step(step)``: progress after each measurement
OnStep = Callable[[Step], None]


class Pace:
    """Counts a job's measurements and says how long the rest will take.

    Parameters
    ----------
    nominal : list of float [s]
        Each measurement's device time, in order (a sweep's length, a window's).
    done : int
        Finished before (kept from an earlier run): the first ``done`` of ``nominal``.
    on_step : callable, optional
        Called with a :class:`Step` after each measurement.
    """

    def __init__(self, nominal: list[float], done: int = 0, on_step: OnStep | None = None):
        self.nominal = list(nominal)
        self.done = done
        self.on_step = on_step
        self._wall = 0.0  # wall time of the measurements made in this run [s]
        self._device = 0.0  # their device time [s]

    @property
    def total(self) -> int:
        return len(self.nominal)

    def did(self, what: str, wall_s: float) -> None:
        """One more measurement finished, in ``wall_s`` [s] of wall time."""
        self._device += self.nominal[min(self.done, self.total - 1)]
        self._wall += wall_s
        self.done += 1
        left = sum(self.nominal[self.done:])
        ratio = self._wall / self._device if self._device > 0 else None
        if self.on_step is not None:
            self.on_step(Step(self.done, self.total, what,
                              None if ratio is None else left * ratio))


def measured(device, run: Callable[[], WindowResult], what: str,
             on_fault: OnFault | None = None) -> WindowResult:
    """``run()`` on ``device`` until it completes without a fault.

    A fault latched before it starts (:class:`~device.errors.DeviceFaultError`) or during
    it (in the result's ``faults``) goes to ``on_fault``; True (the operator cleared it)
    runs the measurement again, False or no ``on_fault`` raises.

    Raises
    ------
    MeasurementFault
        The fault stays: nothing of this measurement is kept.
    """
    while True:
        try:
            res = run()
        except DeviceFaultError:
            fault = device.fault
        else:
            if not res.faults:
                return res
            fault = res.faults[0]
        if on_fault is None or not on_fault(fault, what):
            raise MeasurementFault(fault, what)
