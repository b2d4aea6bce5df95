"""Haptic devices: the interface, scenes, events, and backends (``sim``; ``serial`` later).

Importing this package does no I/O and imports no backend; ``open_device`` imports
the backend it is asked for.
"""

from .base import (
    MAX_WINDOW_TICKS,
    DeviceInfo,
    HapticDevice,
    SimulatedHand,
    backends,
    max_spring,
    open_device,
    register_backend,
)
from .codes import Blend, SceneKind
from .errors import (
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
    "backends",
    "open_device", "max_spring",
    "register_backend",
    "register_transient",
    "transient_kinds",
]
