"""Who answers in a session: a person at the screen, a scripted responder, a simulated person.

:class:`Responder` is what the runner asks of all of them, with a default for every
question that a kind of participant has no use for, so the runner calls every hook
unconditionally. What a participant answers after a trial is asked through one method,
:meth:`Responder.answer`, with the response's declaration (:mod:`protocols.responses`),
which says how each kind of participant answers it. Every choice a non-human participant
makes comes from the generator it is handed, which the runner derives from (session seed,
trial index, attempt): a resumed session repeats the uninterrupted one exactly.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["Responder", "ScriptedResponder", "RESPONDERS"]

#: who answers: a person (``person``, at the PsychoPy screen), random answers to test the
#: machinery (``scripted``), or the simulated participant model (``simulated``)
RESPONDERS = ("person", "scripted", "simulated")


class Responder:
    """What the runner asks of whoever answers (defaults: nothing to show, one window)."""

    name = "participant"
    #: True when answers depend on what was felt before: a resumed session then replays the
    #: recorded attempts first (:meth:`app.runner.SessionRunner.replay`)
    stateful = False

    def instructions(self, phase: str) -> None:
        """A phase begins (a screen shows its instructions)."""

    def ready(self, trial) -> None:
        """The operator placed the item; the trial starts."""

    def waiting(self, trial) -> None:
        """Between trials: the operator is changing the sample."""

    def poll(self) -> str | None:
        """While waiting between trials: a request (``"reference"``: tap the real block
        again), or None. A screen keeps its window alive here."""
        return None

    def choose_reference(self, trial, blocks: list[tuple[str, str]]) -> str | None:
        """The participant asked for a real block again (R) and the phase has several:
        which one (a sample id of ``blocks``, pairs of (sample id, what it is called)), or
        None for none. Default: the first."""
        return blocks[0][0] if blocks else None

    def reference(self, trial, sample) -> None:
        """A real reference block is about to be tapped (``sample``)."""

    def saturated(self, trial, comes_back: bool = True) -> None:
        """The trial saturated: it comes back later, or (``comes_back`` False) it saturated
        as often as the protocol allows and is left out (a screen says which, also without
        sound)."""

    def before_window(self, trial, sample_id: str, device, rng: np.random.Generator) -> None:
        """Just before a tapping window on ``sample_id``."""

    def progress(self, t: float, partial, duration: float) -> None:
        """During a window: ``t`` [s] elapsed of ``duration``, what the device reported."""

    def after_window(self, trial, sample_id: str, result) -> None:
        """After a window: what the device reported (a simulated person feels it)."""

    def keep_tapping(self) -> bool:
        """Familiarization: another window? (default: one window)."""
        return False

    def moving_on(self) -> bool:
        """During an identification window (asked a few times a second): True once the
        participant chose to go on — to another surface, or to answer — which ends the
        window now; :meth:`choose_surface` then returns that choice. Default: never, each
        window runs its duration."""
        return False

    def choose_surface(self, trial, visited: set[int]) -> int | None:
        """Identification: which surface to tap next (index), or None to answer. Default:
        each surface once, in order."""
        rest = [i for i in range(len(trial.samples)) if i not in visited]
        return rest[0] if rest else None

    def answer(self, response, question, rng: np.random.Generator) -> tuple[Any, float]:
        """The answer to ``response`` (a :class:`protocols.responses.Response`) after the
        windows ``question`` holds: (value, response time [s]). Default: as a person's
        screen is asked (``response.ask``, which calls the screen's method for it)."""
        return response.ask(self, question, rng)

    def pause(self, fault: bool = False) -> None:
        """The operator paused the session (``fault``: an e-stop or the watchdog)."""

    def finished(self, summary: str = "") -> None:
        """The session is over."""

    def debrief(self) -> str:
        """Free-text criteria at the end."""
        return ""

    def close(self) -> None:
        """Release what the participant holds (a window)."""


class ScriptedResponder(Responder):
    """Answers at random from the generator it is given: for dry runs of the machinery,
    not a model of anyone (see the simulated participant for that)."""

    name = "scripted"

    def answer(self, response, question, rng) -> tuple[Any, float]:
        """At random, as the response declares (``response.scripted``)."""
        return response.scripted(question, rng)

    def debrief(self) -> str:
        return "scripted responder: no criteria"
