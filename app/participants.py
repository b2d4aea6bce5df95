"""Who answers in a headless session: pluggable participants.

A participant rates windows, names surfaces, and may adjust how the simulated device's
hand taps (``before_window``). Every choice comes from the generator it is handed, which
the runner derives from (session seed, trial index, attempt): a resumed session repeats
the uninterrupted one exactly.
"""

from __future__ import annotations

from typing import Protocol as _Protocol

import numpy as np

__all__ = ["Participant", "ScriptedResponder", "make_participant"]


class Participant(_Protocol):
    """What the runner asks of a (simulated or scripted) participant."""

    def before_window(self, trial, sample_id: str, device, rng: np.random.Generator) -> None:
        ...

    def rate(self, trial, scale, result, rng: np.random.Generator) -> tuple[int, float]:
        """(rating on the scale, response time [s])."""
        ...

    def identify(self, trial, choices, results, rng: np.random.Generator
                 ) -> tuple[list[str], float]:
        """(a name for each surface in order, response time [s])."""
        ...

    def debrief(self) -> str:
        ...


class ScriptedResponder:
    """Answers at random from the generator it is given: for dry runs of the machinery,
    not a model of anyone (see the simulated participant for that)."""

    name = "scripted"

    def before_window(self, trial, sample_id, device, rng) -> None:
        return None

    def rate(self, trial, scale, result, rng) -> tuple[int, float]:
        return int(rng.integers(scale.min, scale.max + 1)), float(rng.uniform(0.8, 2.5))

    def identify(self, trial, choices, results, rng) -> tuple[list[str], float]:
        return [str(c) for c in rng.permutation(list(choices))], float(rng.uniform(3.0, 8.0))

    def debrief(self) -> str:
        return "scripted responder: no criteria"

    def keep_tapping(self) -> bool:
        return False  # one familiarization window


def make_participant(name: str, protocol=None, seed: int = 0, group: str = "") -> Participant:
    """``scripted`` (random answers) or ``simulated`` (see :mod:`app.simulated`; ``group``
    ``expert`` or ``novice`` sets how finely it perceives)."""
    if name == "scripted":
        return ScriptedResponder()
    if name == "simulated":
        from app.simulated import SimulatedParticipant

        return SimulatedParticipant(protocol, seed, group)
    raise ValueError(f"unknown responder {name!r}; available: scripted, simulated")
