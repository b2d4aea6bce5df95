"""Haptic devices: the interface, scenes, events, and the backends that implement them.

Backends are found through the ``hapticlab.backends`` entry-point group
(:mod:`device.registry`): :func:`backends` names them, :func:`available_devices` lists the
devices this computer offers, :func:`open_device` opens one from its spec. Importing this
package does no I/O and imports no backend; ``open_device`` imports the backend it is asked
for.
"""

from .base import (
    MAX_WINDOW_TICKS,
    DeviceInfo,
    HapticDevice,
    SimulatedHand,
    max_spring,
)
from .codes import Blend, SceneKind
from .errors import (
    BackendError,
    CurrentLimitError,
    DeviceError,
    DeviceFaultError,
    DeviceSpecError,
    HapticlabError,
    SceneError,
    UnknownBackendError,
)
from .events import (
    TRACE_CHANNELS,
    ContactEvent,
    FaultEvent,
    Flags,
    HostClock,
    SaturationEvent,
    WindowResult,
)
from .registry import (
    AvailableDevice,
    available_devices,
    backend,
    backends,
    broken_backends,
    none_found_hints,
    open_device,
    register_backend,
)
from .scene import (
    AccelSinusoid,
    ForceSinusoid,
    LibraryTransient,
    Material,
    Pulse,
    Ringing,
    Scene,
    Support,
    Transient,
    TransientTable,
    register_transient,
    transient_kinds,
)

__all__ = [
    "MAX_WINDOW_TICKS",
    "AccelSinusoid",
    "AvailableDevice",
    "BackendError",
    "CurrentLimitError",
    "Blend",
    "HapticlabError",
    "SceneKind",
    "SimulatedHand",
    "ContactEvent",
    "DeviceError",
    "DeviceFaultError",
    "DeviceSpecError",
    "DeviceInfo",
    "FaultEvent",
    "Flags",
    "ForceSinusoid",
    "HapticDevice",
    "HostClock",
    "LibraryTransient",
    "TransientTable",
    "Material",
    "Pulse",
    "Ringing",
    "SaturationEvent",
    "Scene",
    "SceneError",
    "Support",
    "TRACE_CHANNELS",
    "Transient",
    "UnknownBackendError",
    "WindowResult",
    "available_devices",
    "backend",
    "backends",
    "broken_backends",
    "none_found_hints",
    "open_device", "max_spring",
    "register_backend",
    "register_transient",
    "transient_kinds",
]
