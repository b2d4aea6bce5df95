"""Responses, each declared once: what a participant gives back after a trial's windows.

As phase kinds are (:mod:`protocols.kinds`), every kind of answer is one :class:`Response`:
the trial row's columns it fills, what a recorded value must be to count (its validity
rule), how an export makes a participant's cells of it, the texts its screen shows, how a
scripted responder and the simulated participant answer it, and how whoever answers is
asked. The runner, the responders, the loader, the texts and the analysis read the
declaration; none of them compares response names. A new kind of answer is a declaration
here, the screen that asks it (a method of :class:`app.screen.PsychoPyScreen`, called by
:attr:`Response.ask`) and its tests.

The analysis reads files, never this module: a session records, with each phase's design,
the declaration's data (:meth:`Response.record`: the cells with their units, meanings and
rules, and the export's cell), and :mod:`analysis.cells` applies the rules from there. The
rules are a small vocabulary (:class:`Cell`) that the analysis implements once, as the
phase kinds' ``items`` and ``windows`` are: a new response that reuses it needs no code in
the analysis.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from ._registry import Registry

__all__ = ["Cell", "Wide", "Question", "Response", "response", "responses",
           "register_response", "RATING", "ANSWER", "CHOICE", "FORCED_CHOICE", "CELL_TYPES",
           "WIDE_BY"]

#: what a cell's text must be: a whole number, a number, any text, or names joined by
#: ``sep`` (one per sample felt when ``count = "samples"``)
CELL_TYPES = ("integer", "number", "text", "names")
#: what a cell's value may be drawn from besides a list: the samples the trial felt, or the
#: protocol's answer choices (recorded in the design)
AMONG = ("samples", "answer_choices")
#: how an export makes one participant's cells of a response (one column per cell): per
#: ``sample`` (the mean of ``value`` over the sample's repetitions), per ``repetition`` (the
#: mean over the samples of one repetition), per sample felt, ``chosen`` (the share of
#: that sample's trials in which ``value`` named it), or per ``track`` of an adaptive phase
#: (its threshold at the phase's criterion, fitted to ``value``: analysis.psychometric)
WIDE_BY = ("sample", "repetition", "chosen", "track")


@dataclass(frozen=True)
class Cell:
    """One trial-row column a response fills, and the rule a recorded value must meet.

    Attributes
    ----------
    column : str
        The trials.tsv column (:data:`analysis.session_format.COLUMNS`).
    unit : str
        Its unit, for codebooks ('' for none).
    meaning : str
        What the value is, for codebooks and sidecars.
    type : str
        ``integer``, ``number``, ``text`` or ``names`` (:data:`CELL_TYPES`).
    noun : str
        What an error message calls the value (default: the column).
    among : tuple or str or None
        The values it may take: a tuple, or ``samples`` / ``answer_choices``
        (:data:`AMONG`).
    range : tuple, or "scale", or None
        Inclusive bounds of a number (None: open on that side), or the protocol's rating
        scale.
    count : str or None
        ``samples``: a ``names`` cell names one per sample felt.
    sep : str
        What joins the names of a ``names`` cell.
    required : bool
        A valid trial has a value.
    labels : mapping
        A label for each value (SPSS value labels).
    """

    column: str
    unit: str
    meaning: str
    type: str = "text"
    noun: str = ""
    among: tuple | str | None = None
    range: tuple[float | None, float | None] | str | None = None
    count: str | None = None
    sep: str = ","
    required: bool = True
    labels: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.type not in CELL_TYPES:
            raise ValueError(f"cell {self.column!r}: type must be one of {CELL_TYPES}, "
                             f"got {self.type!r}")
        if isinstance(self.among, str) and self.among not in AMONG:
            raise ValueError(f"cell {self.column!r}: among must be a tuple or one of "
                             f"{AMONG}, got {self.among!r}")
        if isinstance(self.range, str) and self.range != "scale":
            raise ValueError(f"cell {self.column!r}: range must be (low, high) or 'scale', "
                             f"got {self.range!r}")

    def to_dict(self) -> dict:
        """The cell as plain data (recorded with the session's design)."""
        out: dict[str, Any] = {"unit": self.unit, "meaning": self.meaning, "type": self.type}
        if self.noun:
            out["noun"] = self.noun
        if self.among is not None:
            out["among"] = self.among if isinstance(self.among, str) else list(self.among)
        if self.range is not None:
            out["range"] = self.range if isinstance(self.range, str) else list(self.range)
        if self.count is not None:
            out["count"] = self.count
        if self.type == "names":
            out["sep"] = self.sep
        if not self.required:
            out["required"] = False
        if self.labels:
            out["labels"] = dict(self.labels)
        return out


@dataclass(frozen=True)
class Wide:
    """How an export makes one participant's cells of a response (:data:`WIDE_BY`).

    ``name`` and ``meaning`` are templates of ``{cell}`` (the sample or repetition)."""

    value: str
    by: str
    unit: str
    meaning: str
    name: str = "{cell}"

    def __post_init__(self) -> None:
        if self.by not in WIDE_BY:
            raise ValueError(f"wide cells by {self.by!r}: must be one of {WIDE_BY}")

    def to_dict(self) -> dict:
        return {"value": self.value, "by": self.by, "unit": self.unit,
                "meaning": self.meaning, "name": self.name}


@dataclass(frozen=True)
class Question:
    """What a participant is asked after a trial's windows.

    Attributes
    ----------
    trial : protocols.Trial
    protocol : protocols.Protocol
    results : list of WindowResult
        The windows the participant is judged on, in the order of ``trial.samples``.
    after : callable (bool) -> dict, optional
        An adaptive trial: its procedure's state after a right (True) or wrong answer
        (:meth:`protocols.SessionEngine.state_after`), which its row records.
    """

    trial: Any
    protocol: Any
    results: list
    after: Callable[[bool], dict] | None = None

    @property
    def phase(self):
        return next(p for p in self.protocol.phases if p.name == self.trial.phase)


#: (responder, question, rng) -> (value, response time [s])
Asker = Callable[[Any, Question, Any], tuple[Any, float]]


@dataclass(frozen=True)
class Response:
    """One kind of answer.

    Attributes
    ----------
    name : str
        What a phase kind's ``response`` names.
    summary : str
        One line on what the participant gives.
    dv : str
        The dependent variable an analysis type is matched by (recorded in the phase
        design).
    cells : tuple of Cell
        The trial-row columns a valid trial of it fills, ``response_time`` among them.
    wide : Wide
        A participant's cells in a wide export.
    ask : callable (responder, Question, rng) -> (value, response time [s])
        How a person's screen is asked: the call of its method for this response
        (:class:`app.screen.PsychoPyScreen`).
    row : callable (value, Question) -> dict
        The row's cells for a value (``response_time`` apart); a value that cannot be one
        raises ValueError saying why.
    scripted : callable (Question, rng) -> (value, response time [s])
        A dry run's answer: at random, not a model of anyone.
    simulated : callable (participant, Question, rng) -> (value, response time [s])
        The simulated participant's answer, from what it can perceive and remember
        (:class:`app.participant_model.SimulatedParticipant`'s public methods).
    needs : str or None
        The protocol table a phase of it needs: ``rating`` (a scale) or ``answer`` (the
        names to choose from), or None.
    options : tuple of str
        The phase ``analysis`` keys it takes besides ``role``.
    analysed : str
        How its phases are analysed, in words (completes "a <kind> phase is analysed …"
        when a phase sets an analysis key it does not take).
    texts : mapping of str to str
        The default texts its screen shows (:mod:`protocols.texts`), English.
    shown_when : mapping of str to str
        For a text shown only under a condition other than this response being asked (a
        rating entry mode), that condition (see :func:`protocols.texts.left_in_english`).
    marker : tuple of str
        The cells the ``response`` marker carries.
    """

    name: str
    summary: str
    dv: str
    cells: tuple[Cell, ...]
    wide: Wide
    ask: Asker
    row: Callable[[Any, Question], dict]
    scripted: Callable[[Question, Any], tuple[Any, float]]
    simulated: Callable[[Any, Question, Any], tuple[Any, float]]
    needs: str | None = None
    options: tuple[str, ...] = ()
    analysed: str = ""
    texts: Mapping[str, str] = field(default_factory=dict)
    shown_when: Mapping[str, str] = field(default_factory=dict)
    marker: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        cols = [c.column for c in self.cells]
        if "response_time" not in cols or len(set(cols)) != len(cols):
            raise ValueError(f"response {self.name!r}: its cells name each column once, "
                             f"response_time among them; got {cols}")
        unknown = set(self.shown_when) - set(self.texts)
        if unknown:
            raise ValueError(f"response {self.name!r}: shown_when names texts it does not "
                             f"declare: {sorted(unknown)}")

    @property
    def columns(self) -> tuple[str, ...]:
        """The trial row's columns a valid trial of it fills."""
        return tuple(c.column for c in self.cells)

    def cell(self, column: str) -> Cell:
        return next(c for c in self.cells if c.column == column)

    def answer_row(self, value: Any, rt: float, question: Question) -> dict:
        """The row's response cells for ``value`` given in ``rt`` seconds.

        Raises
        ------
        ValueError
            When ``value`` is not an answer to ``question`` (saying why).
        """
        if isinstance(rt, bool) or not (isinstance(rt, numbers.Real) and math.isfinite(rt)
                                         and rt >= 0):
            raise ValueError(f"a response time of {rt!r} s")
        return {**self.row(value, question), "response_time": round(float(rt), 3)}

    def record(self) -> dict:
        """What a session records of it with each phase's design, for an analysis that
        reads files only (:mod:`analysis.cells`)."""
        return {"name": self.name, "cells": {c.column: c.to_dict() for c in self.cells},
                "wide": self.wide.to_dict()}


_RESPONSES: Registry[Response] = Registry("response", "responses")


def register_response(r: Response) -> Response:
    """Make ``r`` known by its name (a second of the same name is refused)."""
    return _RESPONSES.add(r)


def responses() -> tuple[str, ...]:
    """The names of the declared responses, in declaration order."""
    return tuple(_RESPONSES)


def response(name: str) -> Response:
    """The declaration of response ``name`` (KeyError naming the declared responses)."""
    return _RESPONSES.find(name)


# ---------------------------------------------------------------------- the declarations
_RT = Cell("response_time", "s", "from the answer screen's onset to the answer",
           type="number", noun="response time", range=(0.0, None), required=False)


def _rating_row(value: Any, q: Question) -> dict:
    scale = q.protocol.rating
    if isinstance(value, bool) or not isinstance(value, numbers.Real) \
            or not scale.min <= value <= scale.max or value != int(value):
        raise ValueError(f"rating {value!r}, not a point of the scale {scale.min}–{scale.max}")
    return {"rating": int(value)}


RATING = register_response(Response(
    name="rating", dv="rating",
    summary="a point on the protocol's [rating] scale",
    cells=(Cell("rating", "scale points", "the participant's rating on the protocol's scale",
                type="integer", range="scale"),
           _RT),
    wide=Wide("rating", "sample", "scale points",
              "mean rating of sample {cell} over its repetitions"),
    ask=lambda r, q, rng: r.rate(q.trial, q.protocol.rating, q.results[0], rng),
    needs="rating", options=("within", "by", "normalize"),
    analysed="by its factors",
    row=_rating_row,
    scripted=lambda q, rng: (int(rng.integers(q.protocol.rating.min, q.protocol.rating.max + 1)),
                             float(rng.uniform(0.8, 2.5))),
    simulated=lambda m, q, rng: m.rate(q.trial, q.protocol.rating, q.results[0], rng),
    texts={
        "rating_keys": "Press a number key, then ENTER.",
        "rating_chosen": "Your rating: {value} — ENTER confirms, another number changes it.",
        "rating_typed": "Type a number from {min} to {max}, then press ENTER.",
        "rating_slider": "Move the marker with the arrow keys (or click), then press ENTER.",
        "rating_confirmed": "Your rating: {value}",
        "rating_invalid": "{value} is not on the scale {min}–{max}.",
    },
    # each entry mode's own texts (RatingScale.entry_mode)
    shown_when={"rating_keys": "keys", "rating_chosen": "keys", "rating_typed": "typed",
                "rating_slider": "slider", "rating_invalid": "typed"},
    marker=("rating",)))


def _names_row(value: Any, q: Question) -> dict:
    names = [str(v) for v in value]
    if len(names) != len(q.trial.samples):
        raise ValueError(f"{len(names)} names for {len(q.trial.samples)} surfaces")
    return {"answer": ",".join(names), "correct": int(names == list(q.trial.samples))}


ANSWER = register_response(Response(
    name="answer", dv="answer",
    summary="a name from the protocol's [answer] choices for each surface",
    cells=(Cell("answer", "", "the names given to the surfaces, in order", type="names",
                count="samples", among="answer_choices"),
           _RT,
           Cell("correct", "0/1", "1 when every surface was named right", type="integer",
                among=(0, 1), labels={"0": "wrong", "1": "all named right"})),
    wide=Wide("correct", "repetition", "0/1", "proportion correct in repetition {cell}",
              name="rep{cell}"),
    ask=lambda r, q, rng: r.identify(q.trial, q.protocol.answer.choices, q.results, rng),
    needs="answer", options=("scoring",),
    analysed="by its score, not by factors; use 'scoring'",
    row=_names_row,
    scripted=lambda q, rng: ([str(c) for c in rng.permutation(list(q.protocol.answer.choices))],
                             float(rng.uniform(3.0, 8.0))),
    simulated=lambda m, q, rng: m.identify(q.trial, q.protocol.answer.choices, q.results, rng),
    texts={"name_hint": "press N to name them", "name": "Surface {i} is …",
           "names": "{names}"},
    marker=("answer",)))


def _choice_row(value: Any, q: Question) -> dict:
    n = len(q.trial.samples)
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not 0 <= value < n:
        raise ValueError(f"chose {value!r}, not one of the {n} samples felt")
    return {"answer": q.trial.samples[int(value)]}


def _nearer_real(m, q: Question, rng) -> tuple[int, float]:
    """The sample whose felt features lay nearer what the participant remembers of real
    contact, each perceived with fresh noise; a coin where nothing could be compared."""
    d = m.distances(q.trial, q.results, rng)
    k = int(rng.integers(0, len(d))) if any(math.isnan(x) for x in d) else \
        min(range(len(d)), key=d.__getitem__)
    return k, m.response_time(1.8, rng)


CHOICE = register_response(Response(
    name="choice", dv="choice",
    summary="which of the trial's samples felt more like real contact",
    cells=(Cell("answer", "", "the sample chosen as more like real contact", noun="choice",
                among="samples"),
           _RT),
    wide=Wide("answer", "chosen", "proportion", "share of its comparisons sample {cell} won"),
    ask=lambda r, q, rng: r.choose(q.trial, q.results, rng),
    analysed="by its pairs (which sample was chosen)",
    row=_choice_row,
    scripted=lambda q, rng: (int(rng.integers(0, len(q.trial.samples))),
                             float(rng.uniform(0.8, 2.5))),
    simulated=_nearer_real,
    texts={"choice": "Which felt more like touching a real object?",
           "choice_keys": "1 = the first        2 = the second"},
    marker=("answer",)))


def _larger_row(value: Any, q: Question) -> dict:
    s = q.trial.stimulus
    n = len(q.trial.samples)
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not 0 <= value < n:
        raise ValueError(f"chose {value!r}, not one of the {n} samples felt")
    correct = int(value) == s.larger
    return {"answer": q.trial.samples[int(value)], "correct": int(correct),
            **s.record(q.after(correct))}


def _values(q: Question) -> tuple[float, ...]:
    """The parameter the phase measures, of each sample the trial felt."""
    name = q.phase.adaptive.parameter
    return tuple(getattr(q.trial.sample_of(q.protocol, sid).scene.transient, name)
                 for sid in q.trial.samples)


FORCED_CHOICE = register_response(Response(
    name="forced_choice", dv="forced_choice",
    summary="which of two renderings had more of the phase's parameter (the comparison's "
            "set by an adaptive procedure)",
    cells=(Cell("answer", "", "the sample chosen as having more of the parameter asked about",
                noun="choice", among="samples"),
           _RT,
           Cell("correct", "0/1", "1 when the sample chosen had the larger parameter",
                type="integer", among=(0, 1), labels={"0": "wrong", "1": "right"}),
           Cell("track", "", "the adaptive track: <standard>-<up|down>", noun="track"),
           Cell("intensity", "the phase's units", "the intensity the procedure presented: "
                "how far the comparison lay from the standard, in the phase's units "
                "(linear, log10 ratio, or dB)", type="number", range=(0.0, None)),
           Cell("state", "", "the procedure after the answer (JSON): next intensity, step "
                "and reversals (staircase), or its estimate and credible interval (QUEST+); "
                "catch trials say so")),
    wide=Wide("correct", "track", "the phase's units",
              "threshold of track {cell} at the phase's criterion", name="{cell}"),
    ask=lambda r, q, rng: r.discriminate(q.trial, q.phase.adaptive.question, rng),
    needs=None, options=("criterion", "function", "lapse_max"),
    analysed="by a psychometric function fitted per track",
    row=_larger_row,
    scripted=lambda q, rng: (int(rng.integers(0, len(q.trial.samples))),
                             float(rng.uniform(0.6, 2.0))),
    simulated=lambda m, q, rng: m.judge_larger(q.phase.adaptive.parameter, _values(q), rng),
    texts={"discriminate_keys": "1 = the first        2 = the second",
           "answer_hint": "press N to answer",
           "discriminate_surfaces": "Two surfaces: press 1 or 2 to tap either one, as often "
                                    "as you like. When you have tapped both, press N and say "
                                    "which had more of what the question asks: 1 or 2. You "
                                    "must choose one, even when they feel alike.\n\n"
                                    "Press SPACE to begin."},
    # the two surfaces' texts only where a phase presents its trials so
    shown_when={"answer_hint": "surfaces", "discriminate_surfaces": "surfaces"},
    marker=("answer", "correct", "intensity")))
