"""Adaptive procedures for forced-choice thresholds: a transformed up-down staircase and
QUEST+, pure functions of the answers so far.

A phase of an adaptive kind (:mod:`protocols.kinds`: ``staircase``, ``questplus``) measures,
on one or more *tracks*, how far a *comparison* rendering must differ from a *standard*
(one of the protocol's samples) in one parameter of its transient (``frequency``,
``decay``, ``slope``, …) for the participant to tell which is larger. The procedure works
on an *intensity* x in its units:

``linear``
    x = |comparison − standard| in the parameter's own unit;
``log``
    x = log10(comparison / standard) (of magnitudes), so 0.1 is a Weber fraction of 26 %;
``dB``
    x = 20·log10(comparison / standard), the amplitude convention.

A track's ``direction`` puts the comparison above (``up``) or below (``down``) the
standard. Each procedure's state is a function of the answers (correct or not) of its
track's trials in order, nothing else: the session engine replays them from trials.tsv, so
a resumed session continues exactly where the log stops.

The staircase follows Levitt (1971): after ``down`` correct answers in a row the intensity
falls by a step, after a wrong one it rises by one (n-down/1-up); a *reversal* is a move in
the other direction from the last; the step size is ``steps[i]`` once ``change_after[i-1]``
reversals have happened; it stops after ``stop_reversals`` reversals (or the phase's cap on
trials), and its estimate is the mean intensity at the reversals after the first
``discard``. It converges on the proportion correct p at which a step down is as likely as
a step up, p^down = 1/2 (70.7 % for 2-down/1-up, 79.4 % for 3-down/1-up). Up and down steps
are equal (not Kaernbach's weighted up-down).

QUEST+ (Watson, 2017) keeps a posterior over a Weibull psychometric function's threshold,
slope and lapse on grids and presents the intensity that minimises the expected entropy of
the posterior after the answer, through the ``questplus`` package (Höchenberger's
implementation, which PsychoPy's own ``QuestPlusHandler`` wraps). We call the package
directly rather than PsychoPy's handler: the procedure is part of the session engine, which
lives in :mod:`protocols` and must not import PsychoPy (only ``app`` does), and which
rebuilds the procedure from the log on every resume; the handler's trial loop and data
saving are the runner's and the recorder's jobs here. Its stimulus choice is
``min_entropy``, which draws no random numbers (its ``min_n_entropy`` would draw from a
generator of its own, not from the session seed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

__all__ = ["UNITS", "DIRECTIONS", "FUNCTIONS", "Staircase", "StaircaseState", "QuestPlus",
           "QuestState", "Track", "AdaptiveDesign", "Stimulus", "Tracks", "value_at",
           "intensity_of", "weber_fraction", "convergence", "weibull", "threshold_at",
           "comparison_sample"]

UNITS = ("linear", "log", "dB")
DIRECTIONS = ("up", "down")
#: psychometric functions QUEST+ may assume (questplus's names in brackets)
FUNCTIONS = ("weibull",)


def value_at(standard: float, x: float, units: str, direction: str = "up") -> float:
    """The comparison's parameter value at intensity ``x`` [units] from ``standard``.

    Magnitudes move (a negative slope becomes more negative going ``up``); the sign stays.

    Examples
    --------
    >>> round(value_at(100.0, 0.1, "log"), 3), round(value_at(-240.0, 6.0, "dB"), 2)
    (125.893, -478.86)
    >>> value_at(30.0, 3.0, "linear", "down")
    27.0
    """
    sign = 1.0 if direction == "up" else -1.0
    mag, s = abs(standard), math.copysign(1.0, standard)
    if units == "linear":
        return s * (mag + sign * x)
    if units == "log":
        return s * mag * 10.0 ** (sign * x)
    if units == "dB":
        return s * mag * 10.0 ** (sign * x / 20.0)
    raise ValueError(f"units must be one of {UNITS}, got {units!r}")


def intensity_of(standard: float, value: float, units: str) -> float:
    """The intensity [units] of a comparison ``value`` from ``standard`` (its magnitude of
    difference: never negative)."""
    a, b = abs(standard), abs(value)
    if units == "linear":
        return abs(b - a)
    r = abs(math.log10(b / a))
    return r if units == "log" else 20.0 * r


def weber_fraction(x: float, units: str, standard: float | None = None) -> float:
    """The Weber fraction (comparison − standard) / standard [1] of an intensity ``x``
    upwards (``linear`` needs the standard's magnitude)."""
    if units == "log":
        return 10.0 ** x - 1.0
    if units == "dB":
        return 10.0 ** (x / 20.0) - 1.0
    if standard is None or standard == 0:
        raise ValueError("a linear intensity is a Weber fraction only of a known standard")
    return x / abs(standard)


def convergence(down: int) -> float:
    """The proportion correct a ``down``-down/1-up staircase converges on (Levitt 1971):
    p with p^down = 1/2.

    Examples
    --------
    >>> round(convergence(2), 4), round(convergence(3), 4)
    (0.7071, 0.7937)
    """
    return 0.5 ** (1.0 / down)


def weibull(x, threshold: float, slope: float, guess: float, lapse: float):
    """P(correct) of a Weibull psychometric function: guess + (1 − guess − lapse)·(1 −
    exp(−(x/threshold)^slope)), x ≥ 0 [intensity units]."""
    x = np.maximum(np.asarray(x, dtype=float), 0.0)
    return guess + (1.0 - guess - lapse) * (1.0 - np.exp(-(x / threshold) ** slope))


def threshold_at(p: float, threshold: float, slope: float, guess: float, lapse: float
                 ) -> float:
    """The intensity at which :func:`weibull` gives proportion correct ``p`` (NaN where it
    never does: ``p`` at or below the guess rate, or at or above 1 − lapse)."""
    f = (p - guess) / (1.0 - guess - lapse)
    if not 0.0 < f < 1.0:
        return math.nan
    return threshold * (-math.log1p(-f)) ** (1.0 / slope)


# ---------------------------------------------------------------------- the staircase
@dataclass(frozen=True)
class Staircase:
    """A transformed up-down staircase (module docstring).

    Attributes
    ----------
    start : float
        The first intensity [units].
    steps : tuple of float
        Step sizes [units], the first used from the start.
    change_after : tuple of int
        Reversal counts after which the next step size applies (one fewer than ``steps``).
    down : int
        Correct answers in a row that lower the intensity (one wrong answer raises it).
    stop_reversals : int
        Reversals after which the track ends.
    discard : int
        The first reversals left out of the reversal average.
    minimum, maximum : float
        Bounds of the intensity [units].
    """

    start: float
    steps: tuple[float, ...]
    change_after: tuple[int, ...] = ()
    down: int = 3
    stop_reversals: int = 12
    discard: int = 4
    minimum: float = 0.0
    maximum: float = math.inf

    def __post_init__(self) -> None:
        if not self.steps or any(not (s > 0 and math.isfinite(s)) for s in self.steps):
            raise ValueError(f"steps must be positive numbers, got {list(self.steps)}")
        if len(self.change_after) != len(self.steps) - 1:
            raise ValueError(f"change_after gives the reversal count at which each step "
                             f"after the first begins: {len(self.steps) - 1} of them for "
                             f"{len(self.steps)} steps, got {list(self.change_after)}")
        if list(self.change_after) != sorted(set(self.change_after)) or \
                any(c < 1 for c in self.change_after):
            raise ValueError(f"change_after must rise from 1, got {list(self.change_after)}")
        if self.down < 1:
            raise ValueError(f"down must be at least 1, got {self.down}")
        if not self.minimum <= self.start <= self.maximum:
            raise ValueError(f"start {self.start:g} is outside [{self.minimum:g}, "
                             f"{self.maximum:g}]")
        if self.stop_reversals <= self.discard:
            raise ValueError(f"stop_reversals ({self.stop_reversals}) must exceed discard "
                             f"({self.discard}): the average needs reversals to average")

    @property
    def target(self) -> float:
        """The proportion correct it converges on (:func:`convergence`)."""
        return convergence(self.down)

    def begin(self) -> StaircaseState:
        return StaircaseState(x=self.start)

    def step_after(self, reversals: int) -> float:
        i = sum(reversals >= c for c in self.change_after)
        return self.steps[i]

    def update(self, s: StaircaseState, correct: bool) -> StaircaseState:
        """The state after an answer at ``s.x``."""
        right = s.right + 1 if correct else 0
        move = -1 if right >= self.down else (0 if correct else +1)
        if move == 0:
            return replace(s, right=right, trials=s.trials + 1, reversal=False)
        reversal = s.direction != 0 and move != s.direction
        reversals = s.reversals + ((s.x,) if reversal else ())
        step = self.step_after(len(reversals))
        x = min(self.maximum, max(self.minimum, s.x + move * step))
        return StaircaseState(x=x, right=0, direction=move, reversals=reversals,
                              trials=s.trials + 1, reversal=reversal)

    def done(self, s: StaircaseState) -> bool:
        return len(s.reversals) >= self.stop_reversals

    def estimate(self, s: StaircaseState) -> dict:
        """The reversal average: mean and SD of the intensities at the reversals after the
        first ``discard`` (None where there are none)."""
        kept = s.reversals[self.discard:]
        if not kept:
            return {"mean": None, "sd": None, "n": 0}
        return {"mean": float(np.mean(kept)),
                "sd": float(np.std(kept, ddof=1)) if len(kept) > 1 else None,
                "n": len(kept)}

    def to_dict(self) -> dict:
        return {"procedure": "staircase", "start": self.start, "steps": list(self.steps),
                "change_after": list(self.change_after), "down": self.down, "up": 1,
                "stop_reversals": self.stop_reversals, "discard": self.discard,
                "minimum": self.minimum,
                "maximum": None if math.isinf(self.maximum) else self.maximum,
                "converges_on": round(self.target, 4)}


@dataclass(frozen=True)
class StaircaseState:
    """Where a staircase stands: the next intensity ``x``, the correct answers in a row,
    the last move's direction (−1, 0, +1), the intensities at the reversals so far, the
    answers taken, and whether the last answer made a reversal."""

    x: float
    right: int = 0
    direction: int = 0
    reversals: tuple[float, ...] = ()
    trials: int = 0
    reversal: bool = False

    def summary(self, procedure: Staircase) -> dict:
        """What a trial row records of it (after the trial's answer)."""
        return {"next": round(self.x, 6), "step": procedure.step_after(len(self.reversals)),
                "reversals": len(self.reversals), "reversal": self.reversal,
                "answered": self.trials}


# ---------------------------------------------------------------------- QUEST+
@dataclass(frozen=True)
class QuestPlus:
    """QUEST+ over a Weibull function on the intensity (module docstring).

    Attributes
    ----------
    intensities : tuple of float
        The intensities it may present [units], ascending, all > 0.
    thresholds : tuple of float
        The grid of the Weibull's threshold (scale) [units].
    slopes : tuple of float
        The grid of its slope (shape).
    lapses : tuple of float
        The grid of the lapse rate.
    trials : int
        Answers after which the track ends.
    guess : float
        The guess rate (1/n of an n-alternative forced choice).
    criterion : float
        The proportion correct at which its own estimate (recorded with each trial) is read.
    """

    intensities: tuple[float, ...]
    thresholds: tuple[float, ...]
    slopes: tuple[float, ...] = (1.5, 2.0, 2.5, 3.0, 3.5, 4.5, 6.0)
    lapses: tuple[float, ...] = (0.0, 0.01, 0.02, 0.04)
    trials: int = 50
    guess: float = 0.5
    criterion: float = 0.75

    def __post_init__(self) -> None:
        for name in ("intensities", "thresholds", "slopes"):
            v = getattr(self, name)
            if len(v) < 2 or any(not (a > 0 and math.isfinite(a)) for a in v) or \
                    list(v) != sorted(set(v)):
                raise ValueError(f"{name} must be two or more rising positive numbers")
        if not self.lapses or any(not 0 <= a < 0.5 for a in self.lapses):
            raise ValueError(f"lapses must lie in [0, 0.5), got {list(self.lapses)}")
        if self.trials < 1:
            raise ValueError(f"trials must be at least 1, got {self.trials}")
        if not self.guess < self.criterion < 1 - max(self.lapses):
            raise ValueError(f"criterion {self.criterion:g} must lie above the guess rate "
                             f"{self.guess:g} and below 1 − the largest lapse")

    def begin(self) -> QuestState:
        import questplus

        qp = questplus.QuestPlus(
            stim_domain={"intensity": np.asarray(self.intensities, dtype=float)},
            param_domain={"threshold": np.asarray(self.thresholds, dtype=float),
                          "slope": np.asarray(self.slopes, dtype=float),
                          "lower_asymptote": self.guess,
                          "lapse_rate": np.asarray(self.lapses, dtype=float)},
            outcome_domain={"response": ["Correct", "Incorrect"]},
            func="weibull", stim_scale="linear", stim_selection_method="min_entropy",
            param_estimation_method="mean")
        return QuestState(qp=qp, posterior=qp.posterior, x=float(qp.next_stim["intensity"]))

    def update(self, s: QuestState, correct: bool) -> QuestState:
        """The state after an answer at ``s.x``: the posterior times the answer's
        likelihood, normalised, and the next intensity (the package's own update and
        choice, on this state's posterior; a state is never changed once made)."""
        qp = s.qp
        like = qp.likelihoods.sel(intensity=s.x,
                                  response="Correct" if correct else "Incorrect")
        post = s.posterior * like
        post = post / post.sum()
        qp.posterior = post  # the package object is shared: its posterior is set per use
        return QuestState(qp=qp, posterior=post, x=float(qp.next_stim["intensity"]),
                          trials=s.trials + 1)

    def done(self, s: QuestState) -> bool:
        return s.trials >= self.trials

    def estimate(self, s: QuestState) -> dict:
        """Its own estimate: the posterior mean of the Weibull's parameters and of the
        threshold at ``criterion``, with the 2.5–97.5 % quantiles of the latter (a credible
        interval over the grid)."""
        post = np.asarray(s.posterior, dtype=float)  # (threshold, slope, guess, lapse)
        t = np.asarray(self.thresholds)[:, None, None, None]
        b = np.asarray(self.slopes)[None, :, None, None]
        lam = np.asarray(self.lapses)[None, None, None, :]
        f = (self.criterion - self.guess) / (1.0 - self.guess - lam)
        xc = t * (-np.log1p(-f)) ** (1.0 / b) * np.ones_like(post)
        order = np.argsort(xc, axis=None)
        w = post.ravel()[order] / post.sum()
        cum = np.cumsum(w)
        vals = xc.ravel()[order]
        lo, hi = vals[np.searchsorted(cum, 0.025)], vals[min(np.searchsorted(cum, 0.975),
                                                              len(vals) - 1)]
        s.qp.posterior = s.posterior
        est = s.qp.param_estimate
        return {"mean": float(np.sum(w * vals)), "ci": [float(lo), float(hi)],
                "threshold": float(est["threshold"]), "slope": float(est["slope"]),
                "lapse": float(est["lapse_rate"])}

    def to_dict(self) -> dict:
        return {"procedure": "questplus", "function": "weibull",
                "intensities": list(self.intensities), "thresholds": list(self.thresholds),
                "slopes": list(self.slopes), "lapses": list(self.lapses),
                "trials": self.trials, "guess": self.guess, "criterion": self.criterion}


@dataclass(frozen=True)
class QuestState:
    """Where QUEST+ stands: its posterior over the grids, the next intensity, the answers
    taken; ``qp`` is the package's object (its likelihoods and choice), shared by a
    track's states."""

    qp: Any = field(compare=False, repr=False)
    posterior: Any = field(compare=False, repr=False)
    x: float = 0.0
    trials: int = 0

    def summary(self, procedure: QuestPlus) -> dict:
        est = procedure.estimate(self)
        return {"next": round(self.x, 6), "answered": self.trials,
                "estimate": round(est["mean"], 6),
                "ci": [round(est["ci"][0], 6), round(est["ci"][1], 6)]}


# ---------------------------------------------------------------------- a phase's design
@dataclass(frozen=True)
class Track:
    """One procedure run within a phase: on ``standard`` (a sample id, whose parameter is
    ``value``), the comparison ``direction`` of it; named ``<standard>-<direction>``."""

    standard: str
    direction: str = "up"
    value: float | None = None

    @property
    def name(self) -> str:
        return f"{self.standard}-{self.direction}"


@dataclass(frozen=True)
class AdaptiveDesign:
    """What an adaptive phase measures and how.

    Attributes
    ----------
    parameter : str
        The transient field the comparison changes (``frequency``, ``decay``, ``slope``, …).
    units : str
        ``linear``, ``log`` or ``dB`` (:data:`UNITS`).
    procedure : Staircase or QuestPlus
    tracks : tuple of Track
        Interleaved: each trial is drawn among the tracks not yet done.
    max_trials : int
        A track's cap on trials (those that end: valid, left out, skipped), so a track
        that never converges still ends.
    catch : float
        The share of trials that are catch trials: the comparison at ``catch_intensity``
        (well above threshold), answered and recorded but not given to the procedure (the
        lapse shows in them).
    catch_intensity : float
        [units].
    question : str
        What the participant is asked (which of the two is larger).
    presentation : str
        ``intervals``: the two renderings one after the other, one window each
        (two-interval forced choice); ``surfaces``: both as surfaces of one scene, the
        participant going between them as often as they like before answering (a
        two-alternative forced choice in space, as identification's surfaces).
    """

    parameter: str
    units: str
    procedure: Staircase | QuestPlus
    tracks: tuple[Track, ...]
    max_trials: int = 60
    catch: float = 0.0
    catch_intensity: float = 0.0
    question: str = ""
    presentation: str = "intervals"

    def max_total(self) -> int:
        """At most this many trials end in the phase (procedure and catch trials)."""
        return len(self.tracks) * self.max_trials + self.max_catch()

    def max_catch(self) -> int:
        return int(math.ceil(self.catch * len(self.tracks) * self.max_trials))

    def to_dict(self) -> dict:
        return {"parameter": self.parameter, "units": self.units,
                "tracks": [{"name": t.name, "standard": t.standard, "direction": t.direction,
                            "value": t.value} for t in self.tracks],
                "max_trials": self.max_trials, "catch": self.catch,
                "catch_intensity": self.catch_intensity, "question": self.question,
                "presentation": self.presentation, **self.procedure.to_dict()}


# ---------------------------------------------------------------------- the engine's part
@dataclass(frozen=True)
class Stimulus:
    """An adaptive trial: what its two windows render and which answer is right.

    Attributes
    ----------
    track : str
        The track's name.
    intensity : float
        The intensity presented [the phase's units].
    catch : bool
        A catch trial (at the catch intensity; not given to the procedure).
    standard : str
        The standard's sample id.
    comparison : Sample
        The comparison rendering made for this trial (its id ``<standard>@<value>``).
    larger : int
        The index in the trial's samples of the one with the larger parameter (the right
        answer to "which was larger").
    answers : tuple of bool
        The track's answers before this trial (its procedure's state follows from them).
    """

    track: str
    intensity: float
    catch: bool
    standard: str
    comparison: Any
    larger: int
    answers: tuple[bool, ...] = ()

    def record(self, state: dict) -> dict:
        """The trial row's procedure cells (``track``, ``intensity``, ``state``: the
        procedure after the answer, as JSON)."""
        import json

        return {"track": self.track, "intensity": round(self.intensity, 6),
                "state": json.dumps(state, separators=(",", ":"), sort_keys=True)}


@dataclass
class Tracks:
    """An adaptive phase's tracks as a replay stands: each track's answers (what its
    procedure took) and its trials that ended, the catch trials used, and how many trials
    have been made (the count seeds each trial's draws)."""

    answers: dict[str, tuple[bool, ...]]
    ended: dict[str, int]
    catch_done: int = 0
    made: int = 0

    @classmethod
    def of(cls, design: AdaptiveDesign) -> Tracks:
        return cls({t.name: () for t in design.tracks}, {t.name: 0 for t in design.tracks})

    def copy(self) -> Tracks:
        return Tracks(dict(self.answers), dict(self.ended), self.catch_done, self.made)


def comparison_sample(standard, parameter: str, value: float):
    """The standard sample with its transient's ``parameter`` set to ``value`` (checked
    as the transient checks its fields), named ``<standard>@<value>``."""
    import dataclasses

    tr = standard.scene.transient
    scene = dataclasses.replace(standard.scene, transient=dataclasses.replace(
        tr, **{parameter: value}))
    sid = f"{standard.id}@{value:.6g}"
    return dataclasses.replace(standard, id=sid, scene=dataclasses.replace(scene, name=sid),
                               params={**dict(standard.params), parameter: value},
                               rated=True)
