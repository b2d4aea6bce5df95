"""Protocols as typed, validated data (built by :mod:`protocols.loader`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from device import Scene

from .adaptive import AdaptiveDesign
from .kinds import RATED, phase_kind

__all__ = ["Sample", "Window", "RatingScale", "Answer", "SaturationPolicy", "Attempts", "Limits",
           "Phase", "PhaseDesign", "Protocol", "ROLES", "ENTRIES", "NORMALIZATIONS", "SCORINGS",
           "SESSION_POLICIES", "REFERENCES"]

#: when a phase's real reference blocks are tapped: never, at the start of each block, or
#: all of them once at the start of the phase (and, whenever it has them, on request)
REFERENCES = ("none", "block", "start")

#: what a phase is for: analysed, practice (rated but not analysed), or none (not rated)
ROLES = ("analysed", "practice", "none")
#: how ratings are normalised before a factorial analysis
NORMALIZATIONS = ("none", "zscore", "zscore_block")
#: how identification answers are scored: a repetition is right only when every surface is
#: named right (the paper), or each surface counts on its own
SCORINGS = ("all_correct", "per_surface")
#: which sessions of a participant with several are analysed
SESSION_POLICIES = ("first", "all")


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
        Group the sample belongs to (the material of a factorial design); a phase with
        ``blocks = "block"`` runs its items block by block.
    factors : mapping of str → str
        The sample's level of each factor of a crossed design (``"low"``/``"high"`` in a
        factorial design; any labels in ``[[samples]]``).
    params : mapping of str → float
        The parameter values behind the levels (e.g. ``frequency`` [Hz]).
    reference : str or None
        Id of the real sample to compare against (not itself rated): the operator places it
        at the start of each block (or of the phase) and whenever the participant asks.
    rated : bool
        False for reference samples (real blocks tapped for comparison, not rated).
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


#: how a participant enters a rating: one number key, digits typed and confirmed with ENTER,
#: or a slider (arrow keys or the mouse, ENTER); ``auto`` is one key when every value is a
#: single digit, typed otherwise
ENTRIES = ("auto", "keys", "typed", "slider")


@dataclass(frozen=True)
class RatingScale:
    """Integer rating scale shown after each rated window."""

    min: int
    max: int
    question: str
    anchors: Mapping[int, str] = field(default_factory=dict)
    entry: str = "auto"

    @property
    def values(self) -> range:
        return range(self.min, self.max + 1)

    @property
    def entry_mode(self) -> str:
        """``keys``, ``typed`` or ``slider`` (``auto`` resolved)."""
        if self.entry != "auto":
            return self.entry
        return "keys" if 0 <= self.min and self.max <= 9 else "typed"

    def key_map(self) -> dict[str, int]:
        """For one-key entry: the keys (PsychoPy's names, top row and keypad) that give each
        point. Only single digits have a key; a point without one cannot be answered."""
        return {f"{pre}{v}": v for v in self.values if 0 <= v <= 9 for pre in ("", "num_")}


#: how many choices number keys can name (1–9)
MAX_CHOICES = 9


def choice_keys(choices) -> dict[str, str]:
    """The number keys (top row and keypad) that name each choice, 1 for the first; choices
    beyond :data:`MAX_CHOICES` have none."""
    return {f"{pre}{i + 1}": c for i, c in enumerate(tuple(choices)[:MAX_CHOICES])
            for pre in ("", "num_")}


@dataclass(frozen=True)
class Answer:
    """Identification answer: name each surface from ``choices``."""

    kind: str
    choices: tuple[str, ...]

    def key_map(self) -> dict[str, str]:
        """The number keys that name each choice (:func:`choice_keys`)."""
        return choice_keys(self.choices)


@dataclass(frozen=True)
class SaturationPolicy:
    """What a saturated attempt does: ``redraw`` the item (up to ``max_attempts``
    saturations, or without a cap when None — the paper's redraw, with the engine's safety
    stop) or ``keep`` it."""

    action: str = "redraw"
    tone: bool = True
    max_attempts: int | None = 3


@dataclass(frozen=True)
class Attempts:
    """How often an item may time out (nobody tapped) or fail on the device before it is
    excluded, so a session always ends."""

    max_timeouts: int = 3
    max_device_failures: int = 3


@dataclass(frozen=True)
class Limits:
    """What the protocol may command: ``max_current`` [A]; ``design_speed`` [m/s] for checks."""

    max_current: float | None = None
    design_speed: float = 0.11


@dataclass(frozen=True)
class PhaseDesign:
    """How a phase is analysed: declared in the protocol, read by the analysis from the
    protocol copy recorded with each session (never from the phase's or protocol's name).

    Attributes
    ----------
    role : str
        ``analysed``, ``practice`` (rated or answered, not analysed) or ``none`` (a free
        phase: nothing to analyse).
    dv : str
        The dependent variable: ``rating``, ``answer`` or ``none``.
    within : tuple of str
        Within-subject factors: ``("sample",)`` for a one-way design over the phase's
        samples, or factor names every sample of the phase carries a level of (crossed).
    by : str or None
        ``block``: one analysis per block (a factorial design's material).
    normalize : str
        ``none``; ``zscore``: ratings z-scored within each participant over the phase;
        ``zscore_block``: within each participant and block (the reality-based models
        normalised each subject's ratings of one material's sets).
    scoring : str or None
        Identification answers: ``all_correct`` or ``per_surface``.
    fit : mapping or None
        An adaptive phase's psychometric fit: ``criterion`` (the proportion correct its
        thresholds are read at), ``function`` (``weibull``, ``normal`` or ``logistic``)
        and ``lapse_max`` (the bound of the free lapse rate).
    """

    role: str = "analysed"
    dv: str = "rating"
    within: tuple[str, ...] = ("sample",)
    by: str | None = None
    normalize: str = "none"
    scoring: str | None = None
    fit: Mapping[str, object] | None = None

    @property
    def analysed(self) -> bool:
        return self.role == "analysed"

    def to_dict(self) -> dict:
        return {"role": self.role, "dv": self.dv, "within": list(self.within), "by": self.by,
                "normalize": self.normalize, "scoring": self.scoring,
                **({"fit": dict(self.fit)} if self.fit is not None else {})}


@dataclass(frozen=True)
class Phase:
    """A run of trials.

    Attributes
    ----------
    name : str
    kind : str
        The name of its :class:`~protocols.kinds.PhaseKind` (``rated``: a window then a
        rating; ``free``: tap until done, not rated; ``identification``: one item shows
        all samples as surfaces to name).
    samples : tuple of str
        Sample ids of the phase (references excluded).
    repetitions : int
        Times each item appears.
    order : str
        ``random`` or ``fixed`` within a block.
    blocks : str or None
        ``block``: run the items block by block (each sample's ``block``).
    block_order : str
        ``random``, ``fixed`` or ``williams`` (balanced Latin square over participants).
    no_repeat : bool
        With ``order = "random"``: never the same sample on two trials in a row, in the
        drawn order (also across the phase's start and its blocks' boundaries) and where a
        redrawn trial goes back, wherever the remaining trials leave a place for it.
    design : PhaseDesign
        What the phase measures and how it is analysed.
    """

    name: str
    kind: str = RATED.name
    samples: tuple[str, ...] = ()
    repetitions: int = 1
    order: str = "random"
    blocks: str | None = None
    block_order: str = "random"
    no_repeat: bool = False
    design: PhaseDesign = field(default_factory=PhaseDesign)
    references: str = "none"  #: when the real reference blocks are tapped: none | block | start
    #: an adaptive kind's phase: its parameter, units, procedure and tracks
    adaptive: AdaptiveDesign | None = None


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
    attempts: Attempts = field(default_factory=Attempts)
    texts: Mapping[str, object] = field(default_factory=dict)
    participant_fields: Mapping[str, object] = field(default_factory=dict)
    sessions: str = "first"
    text: str = ""

    def sample(self, sample_id: str) -> Sample:
        return self.samples[sample_id]

    def design(self) -> dict:
        """The study design as plain data: what the session records beside the protocol copy
        and what the analysis reads (scale, answers, sessions policy, each phase's design,
        samples and response — its cells, their rules and its export cells, which the
        analysis applies from the record alone — each sample's block, factor levels and
        kind)."""
        return {
            "protocol": self.name, "title": self.title, "sha256": self.sha256,
            "scale": None if self.rating is None else {"min": self.rating.min,
                                                       "max": self.rating.max,
                                                       "question": self.rating.question},
            "answer_choices": None if self.answer is None else list(self.answer.choices),
            "sessions": self.sessions,
            "phases": [{"name": p.name, "kind": p.kind, "samples": list(p.samples),
                        "repetitions": p.repetitions, "blocks": p.blocks,
                        **p.design.to_dict(), "response": _recorded(p),
                        **({"adaptive": p.adaptive.to_dict()} if p.adaptive else {})}
                       for p in self.phases],
            "samples": {sid: {"block": s.block, "factors": dict(s.factors),
                              "real": s.is_real, "rated": s.rated, "reference": s.reference,
                              "params": dict(s.params)}
                        for sid, s in self.samples.items()},
        }


def _recorded(phase: Phase) -> dict | None:
    """What a session records of the response ``phase`` asks (None: nothing is asked)."""
    asks = phase_kind(phase.kind).asks
    return None if asks is None else asks.record()
