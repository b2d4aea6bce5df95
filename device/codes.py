"""Codes shared by the scene model, the simulator's servo loop, the wire protocol and the emulator.

Defined once here; every other place derives its integers from these enums (the servo
loop as module constants, the wire as field values, the firmware test vectors as data).
"""

from __future__ import annotations

from enum import IntEnum

__all__ = ["SceneKind", "Blend"]


class SceneKind(IntEnum):
    """What a device does with a scene (``SCENE_BEGIN.kind`` on the wire)."""

    REAL = 0  #: a real sample: no rendering, contact detection only
    SPRING = 1  #: a virtual penetration spring
    TABLE = 2  #: a virtual spring plus a transient table played at each contact


class Blend(IntEnum):
    """How a contact at speed v uses the rows of a transient table (``SCENE_BEGIN.blend``).

    ``SCALE``: row 0 × v/v₀. ``NEAREST``: the row of the nearest speed × v/vᵢ. ``LINEAR``:
    the two rows bracketing v weighted linearly; outside the range the end row × v/v_end.
    """

    SCALE = 0
    NEAREST = 1
    LINEAR = 2

    @property
    def label(self) -> str:
        """The name used in protocol files (``scale``, ``nearest``, ``linear``)."""
        return self.name.lower()

    @classmethod
    def parse(cls, value: Blend | str) -> Blend:
        """A Blend from itself or its label; ValueError naming the allowed labels."""
        if isinstance(value, Blend):
            return value
        if isinstance(value, str) and value.upper() in cls.__members__:
            return cls[value.upper()]
        raise ValueError(f"must be one of {', '.join(b.label for b in cls)}, got {value!r}")
