"""What a hapticlab device reports to PsychoPy, as PsychoPy's response objects.

Each is a :class:`psychopy.hardware.base.BaseResponse` whose ``fields`` list what it
carries (PsychoPy serialises them with :meth:`~psychopy.hardware.base.BaseResponse.getJSON`
and prints them in its log). ``t`` is on PsychoPy's time base (``psychopy.clock.getTime()``,
the one every ``core.Clock`` counts from) when the device's clock is known on this
computer's (:attr:`HapticResponse.onHostClock`); a simulated device in virtual time has no
such clock, and its responses are stamped when PsychoPy learned of them.
"""

from __future__ import annotations

from psychopy.hardware.base import BaseResponse

__all__ = ["HapticResponse", "ContactResponse", "SaturationResponse", "FaultResponse",
           "WindowResponse"]


class HapticResponse(BaseResponse):
    """Base of a hapticlab device's responses (a device's ``responseClass``).

    Parameters
    ----------
    t : float [s]
        PsychoPy time of the event.
    value
        The event's main value (each subclass says which).
    tDevice : float or None [s]
        The device's own time of the event (None for host events).
    onHostClock : bool
        True when ``t`` comes from the device's clock mapped onto this computer's; False
        when it is the time PsychoPy learned of the event (a simulation in virtual time).
    """

    kind = "event"
    fields = ["t", "value", "tDevice", "onHostClock"]

    def __init__(self, t, value, tDevice=None, onHostClock=False, device=None):
        super().__init__(t, value, device=device)
        self.tDevice = tDevice
        self.onHostClock = onHostClock


class ContactResponse(HapticResponse):
    """The stylus touched the surface; ``value`` (and ``speed``) is the incoming speed
    [m/s] the device measured, ``peakAccel`` the largest acceleration magnitude [m/s²]
    the stylus met in the 50 ms after (None without an accelerometer)."""

    kind = "contact"
    fields = ["t", "value", "speed", "peakAccel", "tDevice", "onHostClock"]

    def __init__(self, t, value, tDevice=None, onHostClock=False, peakAccel=None, device=None):
        super().__init__(t, value, tDevice, onHostClock, device=device)
        self.speed = value
        self.peakAccel = peakAccel


class SaturationResponse(HapticResponse):
    """The amplifier clamped the commanded current: ``value`` (and ``peakCurrent``) is the
    largest current asked [A], ``duration`` how long it was clamped [s]."""

    kind = "saturation"
    fields = ["t", "value", "peakCurrent", "duration", "tDevice", "onHostClock"]

    def __init__(self, t, value, tDevice=None, onHostClock=False, duration=0.0, device=None):
        super().__init__(t, value, tDevice, onHostClock, device=device)
        self.peakCurrent = value
        self.duration = duration


class FaultResponse(HapticResponse):
    """A latched fault zeroed the output: ``value`` (and ``code``) is ``estop`` (the
    keyboard's e-stop, or the device's own button) or another fault code (``watchdog``…),
    ``message`` the device's words."""

    kind = "fault"
    fields = ["t", "value", "code", "message", "tDevice", "onHostClock"]

    def __init__(self, t, value, tDevice=None, onHostClock=False, message="", device=None):
        super().__init__(t, value, tDevice, onHostClock, device=device)
        self.code = value
        self.message = message


class WindowResponse(HapticResponse):
    """A tapping window ended: ``value`` (and ``nContacts``) is its number of contacts,
    ``peakAccel`` the largest acceleration magnitude of the window [m/s²] (None without an
    accelerometer), ``saturated`` whether any tick saturated, ``timedOut`` whether no
    contact came before the wait ran out."""

    kind = "window"
    fields = ["t", "value", "nContacts", "peakAccel", "saturated", "timedOut", "tDevice",
              "onHostClock"]

    def __init__(self, t, value, tDevice=None, onHostClock=False, peakAccel=None,
                 saturated=False, timedOut=False, device=None):
        super().__init__(t, value, tDevice, onHostClock, device=device)
        self.nContacts = value
        self.peakAccel = peakAccel
        self.saturated = saturated
        self.timedOut = timedOut
