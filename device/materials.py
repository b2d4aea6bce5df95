"""A real sample's physics: :class:`Material` (its contact, how it rings, what it rests on),
with :class:`Ringing` and :class:`Support`. A real sample is touched, never rendered."""

from __future__ import annotations

from dataclasses import dataclass

from ._checks import (
    _DAMPING,
    _DECAY,
    _POS,
    _STIFFNESS,
    MAX_RINGING_HZ,
    _check_slope,
    _finite,
    _set_checked,
)
from .errors import SceneError

__all__ = ["Ringing", "Support", "Material", "MAX_BLOCK_KG", "BLOCK_HINT"]


@dataclass(frozen=True)
class Ringing:
    """Decaying-sinusoid vibration model of a material, Q(t) = A·v·exp(−B·t)·sin(2π·f·t).

    Parameters
    ----------
    slope : float [1/s]
        A, amplitude of acceleration per unit normal velocity. The papers give it
        negative: with the normal velocity negative into the surface, ``A·v`` > 0 and
        the first push is out of the surface.
    decay : float [1/s]
        B, exponential decay rate, > 0 (a vibration that never dies out, or grows, is
        not a material's).
    frequency : float [Hz]
        f, > 0.
    """

    slope: float
    decay: float
    frequency: float

    def __post_init__(self) -> None:
        _check_slope(self, "ringing")
        _set_checked(self, "ringing", decay=_DECAY, frequency={
            **_POS, "maximum": MAX_RINGING_HZ, "why": "ten times the vibrotactile range"})

    def acceleration(self, t, speed: float):
        """Model acceleration [m/s²] at times ``t`` [s] after a contact at ``speed`` [m/s]."""
        import numpy as np

        t = np.asarray(t, dtype=float)
        q = self.slope * (-speed) * np.exp(-self.decay * t) * np.sin(2 * np.pi * self.frequency * t)
        return np.where(t >= 0, q, 0.0)


@dataclass(frozen=True)
class Support:
    """What a block rests on, as a spring and damper to the ground (foam, a table top).

    Parameters
    ----------
    stiffness : float [N/m]
        > 0.
    damping : float [N·s/m]
        >= 0.
    """

    stiffness: float
    damping: float = 0.0

    def __post_init__(self) -> None:
        _set_checked(self, "support", stiffness=_STIFFNESS, damping=_DAMPING)


#: heaviest block a sample may be [kg] (a 3.5-cm cube of steel is 0.34 kg)
MAX_BLOCK_KG = 5.0
#: what to give a ringing sample so it can be simulated
BLOCK_HINT = ("give the block's 'mass' [kg]: its vibration is the block moving on what it "
              "rests on (a 3.5-cm cube of wood is about 0.026 kg, of aluminum 0.116 kg)")


@dataclass(frozen=True)
class Material:
    """A physical sample touched through the device (real, never rendered): passive
    physics only, so it can store and return energy but never create it.

    Three forms:

    - a sample fixed to the ground (foam, a rubber pad): the tip touches it through a
      contact spring ``stiffness`` and damper ``damping``;
    - a block, a second body of ``mass``, resting on a given ``support`` (balsa on foam):
      the contact as above between the tip and the block;
    - a block of ``mass`` that rings as measured (``ringing``, Table 1): ``stiffness`` is
      then what pressing it feels (the contact and the support in series, Table 1's K),
      and the simulator derives the contact's stiffness and damping and the support so the
      tip and the block, bouncing against each other on the contact, ring at the measured
      frequency and decay (:func:`device.sim.plant.block_model`). The slope A is not
      imposed: how strongly the tip shakes is what the masses allow.

    A tap moves a block; its vibration reaches the tip only through the contact.

    Parameters
    ----------
    stiffness : float [N/m]
        Contact stiffness (a ringing block: its quasi-static stiffness), > 0.
    damping : float [N·s/m]
        Contact damping, >= 0 (a ringing block: derived, not given).
    ringing : Ringing or None
        The vibration measured on the real sample (the simulator needs ``mass`` with it).
    mass : float or None [kg]
        The block's mass (0 < mass <= :data:`MAX_BLOCK_KG`); None: the sample does not move.
    support : Support or None
        What the block rests on (needs ``mass``; not with ``ringing``, which derives it).
    """

    stiffness: float
    damping: float = 0.0
    ringing: Ringing | None = None
    mass: float | None = None
    support: Support | None = None

    def __post_init__(self) -> None:
        _set_checked(self, "material", stiffness=_STIFFNESS, damping=_DAMPING)
        if self.mass is not None:
            object.__setattr__(self, "mass", _finite("material", "mass", self.mass, minimum=0.0,
                                                     strict=True, maximum=MAX_BLOCK_KG))
            if self.ringing is None and self.support is None:
                raise SceneError("a block needs what it rests on: give 'support' (stiffness, "
                                 "damping) or the 'ringing' it was measured with", "mass",
                                 where="material")
            if self.ringing is not None and self.support is not None:
                raise SceneError("give either 'ringing' (the support is derived from it) or "
                                 "'support', not both", "support", where="material")
        elif self.support is not None:
            raise SceneError("'support' is what a block rests on: give the block's "
                             "'mass' [kg] too", "mass", where="material")
        # a ringing without a mass describes the sample (a real device never simulates it;
        # older protocol copies say no more); the simulator asks for the mass (BLOCK_HINT)

    @property
    def is_block(self) -> bool:
        """True when the sample is a second body that moves."""
        return self.mass is not None
