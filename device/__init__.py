"""Haptic devices: the interface, scenes, events, and backends (``sim``; ``serial`` later).

Importing this package does no I/O and imports no backend; ``open_device`` imports
the backend it is asked for.
"""

from .base import DeviceInfo, HapticDevice, backends, open_device, register_backend
from .errors import DeviceError, DeviceFaultError, SceneError, UnknownBackendError
from .events import (
    TRACE_CHANNELS,
    ContactEvent,
    FaultEvent,
    Flags,
    SaturationEvent,
    WindowResult,
)
from .scene import (
    AccelSinusoid,
    ForceSinusoid,
    LibraryTransient,
    Material,
    Pulse,
    Ringing,
    Scene,
    Transient,
    TransientTable,
    register_transient,
    transient_kinds,
)

__all__ = [
    "AccelSinusoid",
    "ContactEvent",
    "DeviceError",
    "DeviceFaultError",
    "DeviceInfo",
    "FaultEvent",
    "Flags",
    "ForceSinusoid",
    "HapticDevice",
    "LibraryTransient",
    "TransientTable",
    "Material",
    "Pulse",
    "Ringing",
    "SaturationEvent",
    "Scene",
    "SceneError",
    "TRACE_CHANNELS",
    "Transient",
    "UnknownBackendError",
    "WindowResult",
    "backends",
    "open_device",
    "register_backend",
    "register_transient",
    "transient_kinds",
]
