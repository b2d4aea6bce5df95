"""Protocols as typed, validated data (built by :mod:`protocols.loader`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from device import Scene

__all__ = ["Sample", "Window", "RatingScale", "Answer", "SaturationPolicy", "Limits", "Phase",
           "Protocol"]


@dataclass(frozen=True)
class Sample:
    """One thing a participant can tap.

    Attributes
    ----------
    id : str
        Unique within the protocol; recorded in every trial row.
    scene : device.Scene
        What the device renders (or, for a real sample, what is touched).
    placement : str or None
        The physical item the operator puts under the stylus: the sample itself for a
        real sample; None for virtual samples (the engine assigns a placeholder block).
    block : str or None
        Group the sample belongs to (the material of a factorial design).
    factors : mapping of str → str
        Factor levels (``"low"``/``"high"``) of a factorial design.
    params : mapping of str → float
        The parameter values behind the levels (e.g. ``frequency`` [Hz]).
    reference : str or None
        Id of the real sample to compare against (not itself rated).
    rated : bool
        False for reference samples that are only tapped on request.
    """

    id: str
    scene: Scene
    placement: str | None = None
    block: str | None = None
    factors: Mapping[str, str] = field(default_factory=dict)
    params: Mapping[str, float] = field(default_factory=dict)
    reference: str | None = None
    rated: bool = True

    @property
    def is_real(self) -> bool:
        return self.scene.is_real


@dataclass(frozen=True)
class Window:
    """Tapping window: ``duration`` [s] from the first impact; ``timeout`` [s] to wait for it."""

    duration: float = 5.0
    timeout: float = 30.0


@dataclass(frozen=True)
class RatingScale:
    """Integer rating scale shown after each rated window."""

    min: int
    max: int
    question: str
    anchors: Mapping[int, str] = field(default_factory=dict)

    @property
    def values(self) -> range:
        return range(self.min, self.max + 1)


@dataclass(frozen=True)
class Answer:
    """Identification answer: name each surface from ``choices``."""

    kind: str
    choices: tuple[str, ...]


@dataclass(frozen=True)
class SaturationPolicy:
    """What a saturated attempt does: ``redraw`` the item (up to ``max_attempts``) or ``keep``."""

    action: str = "redraw"
    tone: bool = True
    max_attempts: int = 3


@dataclass(frozen=True)
class Limits:
    """What the protocol may command: ``max_current`` [A]; ``design_speed`` [m/s] for checks."""

    max_current: float | None = None
    design_speed: float = 0.11


@dataclass(frozen=True)
class Phase:
    """A run of trials.

    Attributes
    ----------
    name : str
    kind : str
        ``rated`` (window then rating), ``free`` (tap until done; not rated) or
        ``identification`` (one item shows all samples as surfaces to name).
    samples : tuple of str
        Sample ids of the phase (references excluded).
    repetitions : int
        Times each item appears.
    order : str
        ``random`` or ``fixed`` within a block.
    blocks : str or None
        Group items by this sample attribute (``material`` → ``Sample.block``).
    block_order : str
        ``random``, ``fixed`` or ``williams`` (balanced Latin square over participants).
    """

    name: str
    kind: str = "rated"
    samples: tuple[str, ...] = ()
    repetitions: int = 1
    order: str = "random"
    blocks: str | None = None
    block_order: str = "random"


@dataclass(frozen=True)
class Protocol:
    """A whole protocol: samples, phases, window, response, saturation policy."""

    name: str
    title: str
    description: str
    source: str
    sha256: str
    samples: Mapping[str, Sample]
    phases: tuple[Phase, ...]
    window: Window
    rating: RatingScale | None
    answer: Answer | None
    saturation: SaturationPolicy
    placeholders: tuple[str, ...]
    limits: Limits
    cursor: bool = False

    def sample(self, sample_id: str) -> Sample:
        return self.samples[sample_id]
