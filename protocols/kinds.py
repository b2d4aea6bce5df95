"""Phase kinds, each declared once.

A phase's ``kind`` says how its trials run and what a participant gives back. Everything
that differs between kinds is stated here, in one :class:`PhaseKind` per kind, in the manner
of PsychoPy's hardware classes (which declare what they are once, and a manager finds
them): the protocol loader, the trial engine, the session runner, the participant's screen,
the simulated participant and the texts look a kind up by its name (:func:`phase_kind`) and
read its declaration; none of them compares kind names.

A kind is described by a few answers, each with a small fixed vocabulary that the code
reading it implements once (a new kind that reuses them needs no code elsewhere):

``items``
    How the phase's samples make its items: ``"each"`` (one item per sample, in blocks,
    in a drawn or fixed order), ``"all"`` (one item of all the samples, their order drawn
    per item), ``"pairs"`` (one item per ordered pair of samples: both orders of every
    pair, so the order a pair is felt in is balanced) or ``"adaptive"`` (the samples are
    standards; each trial pairs one with a comparison its track's procedure sets from the
    answers so far: :mod:`protocols.adaptive`).
``windows``
    How an item's device windows run: ``"each_sample"`` (one window per sample of the
    item, in order), ``"until_done"`` (windows on the item's one sample until the
    participant says they are done) or ``"surfaces"`` (one item holds all the phase's
    samples as surfaces; the participant goes between them, tapping each as often as
    they like).
``response``
    What the participant gives after the windows: the name of a declared
    :class:`~protocols.responses.Response` (``rating``: a point on the protocol's
    ``[rating]`` scale; ``answer``: a name from ``[answer]`` for each surface; ``choice``:
    which of the item's samples felt more real), or None (nothing: familiarization).

The trial row's response columns, the table a protocol must have, the analysis keys a
phase takes and how it is analysed follow from the response's declaration
(:mod:`protocols.responses`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from ._registry import Registry
from .responses import Response, response, responses

__all__ = ["PhaseKind", "RATED", "FREE", "IDENTIFICATION", "COMPARISON", "STAIRCASE",
           "QUESTPLUS", "REFERENCE", "PROCEDURES",
           "phase_kind", "phase_kinds", "register"]

#: the trial kind of a real reference block tapped between trials (the runner's, never a
#: phase's): its row has status ``reference`` and no response
REFERENCE = "reference"

ITEMS = ("each", "all", "pairs", "adaptive")
#: the adaptive procedures (a kind of items ``adaptive`` runs one; its phase's table of
#: the same name configures it)
PROCEDURES = ("staircase", "questplus")
WINDOWS = ("each_sample", "until_done", "surfaces")


@dataclass(frozen=True)
class PhaseKind:
    """What one kind of phase is.

    Attributes
    ----------
    name : str
        The ``kind`` a protocol file writes.
    summary : str
        One line on what a participant does (``protocol show``, error messages).
    items : str
        How the samples make items (module docstring): ``each``, ``all`` or ``pairs``.
    windows : str
        How an item's windows run: ``each_sample``, ``until_done`` or ``surfaces``.
    response : str or None
        What the participant gives after them: a declared response's name
        (:func:`~protocols.responses.responses`), or None.
    instructions : str
        The default instructions shown at the phase's start (``[texts.instructions]``
        replaces them per phase). ``{n}`` is the number of samples, ``{keys}`` their keys.
    redraws_saturated : bool
        Whether a trial whose window saturated the drive is redrawn under the protocol's
        ``redraw`` policy (familiarization is not measured, so it is not).
    references : bool
        Whether the phase's real reference blocks are tapped and offered during it.
    procedure : str or None
        Items ``adaptive``: the procedure its tracks run (:data:`PROCEDURES`).
    """

    name: str
    summary: str
    windows: str
    response: str | None
    instructions: str
    redraws_saturated: bool = True
    references: bool = True
    items: str = "each"
    procedure: str | None = None

    def __post_init__(self) -> None:
        if self.items not in ITEMS:
            raise ValueError(f"phase kind {self.name!r}: items must be one of {ITEMS}, "
                             f"got {self.items!r}")
        if (self.items == "all") != (self.windows == "surfaces"):
            raise ValueError(f"phase kind {self.name!r}: an item of all the samples is "
                             "felt as surfaces, and only such an item is")
        if (self.items == "adaptive") != (self.procedure in PROCEDURES):
            raise ValueError(f"phase kind {self.name!r}: an adaptive kind names its procedure "
                             f"({', '.join(PROCEDURES)}), and only such a kind does")
        if self.windows not in WINDOWS:
            raise ValueError(f"phase kind {self.name!r}: windows must be one of {WINDOWS}, "
                             f"got {self.windows!r}")
        if self.response is not None and self.response not in responses():
            raise ValueError(f"phase kind {self.name!r}: response must be one of "
                             f"{responses()} or None, got {self.response!r}")

    @property
    def surfaces(self) -> bool:
        """One item holds all the phase's samples as surfaces (no placement, no per-sample
        order: the order of surfaces is drawn per item)."""
        return self.windows == "surfaces"

    @property
    def asks(self) -> Response | None:
        """The declaration of its response (None: nothing is asked)."""
        return None if self.response is None else response(self.response)

    @property
    def needs(self) -> str | None:
        """The protocol table the kind needs: ``rating``, ``answer`` or None."""
        return None if self.asks is None else self.asks.needs

    @property
    def dv(self) -> str:
        """What the phase measures for analysis (its response's), or ``none``."""
        return "none" if self.asks is None else self.asks.dv

    @property
    def columns(self) -> tuple[str, ...]:
        """The trial row's columns a valid trial of this kind fills beyond every row's."""
        return () if self.asks is None else self.asks.columns

    @property
    def default_references(self) -> str:
        """When the real blocks are tapped unless the phase says (given it has some):
        ``block`` (each sample's own, at its block's start) or ``start`` (all of them at
        the phase's start: a surfaces item shows every block's sample at once)."""
        return "start" if self.surfaces else "block"


_KINDS: Registry[PhaseKind] = Registry("phase kind", "kinds", reserved=(REFERENCE,))


def register(kind: PhaseKind) -> PhaseKind:
    """Make ``kind`` known by its name (a second kind of the same name is refused)."""
    return _KINDS.add(kind)


def phase_kinds() -> tuple[str, ...]:
    """The names of the declared kinds, in declaration order."""
    return tuple(_KINDS)


def phase_kind(name: str) -> PhaseKind:
    """The declaration of kind ``name`` (KeyError naming the declared kinds)."""
    return _KINDS.find(name)


RATED = register(PhaseKind(
    name="rated",
    summary="a window per sample, then a rating on the protocol's scale",
    windows="each_sample", response="rating",
    instructions="You will tap on a series of samples, one at a time, and rate each one.\n\n"
                 "Press SPACE to begin."))

FREE = register(PhaseKind(
    name="free",
    summary="windows on one sample until the participant is done; not rated",
    windows="until_done", response=None, redraws_saturated=False, references=False,
    instructions="Tap freely on the sample in front of you.\n\nTake your time. When you "
                 "are done, press ENTER.\n\nPress SPACE to begin."))

IDENTIFICATION = register(PhaseKind(
    name="identification",
    summary="one scene of all the phase's samples as surfaces, each then named from the "
            "protocol's answers",
    items="all", windows="surfaces", response="answer",
    instructions="One scene, {n} surfaces. Press {keys} to choose a surface and tap it;\n"
                 "press another number at any time to go to that surface.\n"
                 "When you have tapped them all, press N to name each one.\n\n"
                 "Press SPACE to begin."))

COMPARISON = register(PhaseKind(
    name="comparison",
    summary="two samples felt one after the other, then which felt more like real contact "
            "(two-alternative forced choice)",
    items="pairs", windows="each_sample", response="choice", references=False,
    instructions="You will tap on two samples, one after the other, and say which felt "
                 "more like touching a real object: press 1 for the first, 2 for the "
                 "second. You must choose one, even when they feel alike.\n\n"
                 "Press SPACE to begin."))

STAIRCASE = register(PhaseKind(
    name="staircase",
    summary="a standard and a comparison felt one after the other, then which was larger "
            "(two-interval forced choice); the comparison set by a transformed up-down "
            "staircase from the answers so far",
    items="adaptive", procedure="staircase", windows="each_sample", response="forced_choice",
    references=False,
    instructions="You will tap on two samples, one after the other, and say which of the "
                 "two had more of what the question asks: press 1 for the first, 2 for the "
                 "second. You must choose one, even when they feel alike; guess then.\n\n"
                 "Press SPACE to begin."))

QUESTPLUS = register(dataclasses.replace(
    STAIRCASE, name="questplus", procedure="questplus",
    summary="a standard and a comparison felt one after the other, then which was larger "
            "(two-interval forced choice); the comparison chosen by QUEST+ from the answers "
            "so far"))
