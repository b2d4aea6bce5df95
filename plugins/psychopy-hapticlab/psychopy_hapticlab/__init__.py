"""psychopy-hapticlab: a hapticlab force-feedback device in any PsychoPy experiment.

- :class:`HapticlabDevice` (:mod:`.device`): the device in PsychoPy's DeviceManager
  (entry point ``psychopy.hardware``), its reports as response objects (:mod:`.responses`),
  a latched fault as :class:`HapticFaultError`.
- :class:`HapticContact` and :class:`HapticCheck`: what the Builder components Haptic
  contact and Haptic device check drive (entry points ``psychopy.experiment.components``),
  usable from Coder as they are.

Importing it opens nothing and writes nothing; it imports PsychoPy's hardware base classes.
"""

from .check import HapticCheck
from .contact import HapticContact
from .device import HapticFaultError, HapticlabDevice, WindowRecord
from .responses import (
    ContactResponse,
    FaultResponse,
    HapticResponse,
    SaturationResponse,
    WindowResponse,
)

__all__ = ["HapticlabDevice", "HapticFaultError", "WindowRecord", "HapticContact",
           "HapticCheck", "HapticResponse", "ContactResponse", "SaturationResponse",
           "FaultResponse", "WindowResponse"]
