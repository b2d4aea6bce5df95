"""Protocols as validated data (``*.toml`` beside this file) and the pure session engine.

Imports only :mod:`device` types (scenes, device ratings); no I/O at import time.
"""

from .engine import (
    DONE,
    FINAL_STATUSES,
    PAUSED,
    RNG_ALGORITHM,
    STATUSES,
    Attempt,
    Done,
    LogMismatch,
    Paused,
    ResumeMismatch,
    SessionEngine,
    SessionSetupError,
    Trial,
    is_reference,
    reference_item,
    seed_from_entropy,
)
from .kinds import REFERENCE, PhaseKind, phase_kind, phase_kinds
from .loader import BUILTIN, ProtocolError, load_protocol, parse_protocol, protocol_text
from .model import (
    Answer,
    Attempts,
    Limits,
    Phase,
    PhaseDesign,
    Protocol,
    RatingScale,
    Sample,
    SaturationPolicy,
    Window,
)
from .statuses import TrialStatus
from .williams import williams_square

__all__ = [
    "PhaseKind", "phase_kind", "phase_kinds", "REFERENCE",
    "is_reference", "reference_item",
    "Answer", "Attempt", "Attempts", "BUILTIN", "DONE", "Done", "FINAL_STATUSES", "Limits",
    "LogMismatch",
    "PAUSED", "Paused", "Phase", "PhaseDesign", "Protocol", "ProtocolError", "RNG_ALGORITHM",
    "RatingScale", "ResumeMismatch", "STATUSES", "Sample", "SaturationPolicy", "SessionEngine",
    "SessionSetupError", "Trial", "TrialStatus", "Window", "load_protocol", "parse_protocol",
    "protocol_text",
    "seed_from_entropy", "williams_square",
]
