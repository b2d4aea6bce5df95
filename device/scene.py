"""What a device renders for one sample: the :class:`Scene` and its parts.

A scene is plain validated data with SI units. It lists exactly what the sample
needs, and the device models nothing more: a real sample has a physical
:class:`Material` and no rendering; a virtual sample has a penetration spring and
optionally a :class:`Transient` played open-loop at contact.

Sign conventions (used throughout :mod:`device`): heights point up, the surface
is at ``surface_height``; penetration is ``surface_height - z``; an *incoming
velocity* is reported as a positive speed into the surface; forces are positive
out of the surface (upwards).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import MISSING, dataclass, field, fields
from typing import Any, ClassVar

from .codes import Blend
from .errors import SceneError

__all__ = [
    "TransientTable",
    "LibraryTransient",
    "TableTransient",
    "GraspModel",
    "GraspTransient",
    "PUBLISHED_GRASP",
    "Scene",
    "Material",
    "Support",
    "MAX_BLOCK_KG",
    "MAX_STIFFNESS",
    "MAX_DAMPING",
    "MAX_RINGING_HZ",
    "MAX_SLOPE",
    "MAX_DECAY",
    "MAX_GAIN",
    "Ringing",
    "Transient",
    "Pulse",
    "ForceSinusoid",
    "AccelSinusoid",
    "register_transient",
    "transient_kinds",
    "unknown_key",
]


def _finite(where: str, name: str, value: Any, *, minimum: float | None = None,
            strict: bool = False, maximum: float | None = None, why: str = "") -> float:
    """Return ``value`` as a float after checking it is a finite number in range (``why``:
    the reason for the range, said when it is broken)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"must be a number, got {value!r}", name, where=where)
    try:
        v = float(value)
    except OverflowError:  # an integer beyond any float (10**400)
        raise SceneError("must be finite, got an integer of about 10^"
                         f"{int(abs(value).bit_length() * math.log10(2))}", name,
                         where=where) from None
    if not math.isfinite(v):
        raise SceneError(f"must be finite, got {value!r}", name, where=where)
    if minimum is not None and (v <= minimum if strict else v < minimum):
        op = ">" if strict else ">="
        raise SceneError(f"must be {op} {minimum:g}, got {v:g}", name, where=where)
    if maximum is not None and v > maximum:
        raise SceneError(f"must be <= {maximum:g}, got {v:g}" + (f" ({why})" if why else ""),
                         name, where=where)
    return v


#: stiffest contact or spring a scene may state [N/m]: a 5-mm steel tip pressed on steel at
#: 10 N is about 1.2·10⁷ N/m (Hertz: 2·E*·a, E* = 110 GPa, a = 55 µm), the hardest contact a
#: stylus meets; ten times that leaves
#: room, and keeps every matrix exponential of the simulated contact finite (10³⁰⁰ N/m raised
#: numpy's LinAlgError, 10²⁰ N/m never finished). How fast a given contact may ring on the
#: masses it joins is bounded when a device compiles it (:data:`device.sim.plant.MAX_CONTACT_HZ`)
MAX_STIFFNESS = 1.0e8
#: most damping a contact or support may state [N·s/m]: twice the critical damping of the
#: stiffest contact on the heaviest block (2·√(k·m) = 2·√(10⁸ · 5) = 4.5·10⁴)
MAX_DAMPING = 1.0e5
#: fastest a material may be stated to ring [Hz]: ten times the top of the vibrotactile range
#: (~1 kHz, SPEC §4); the papers' fastest, aluminum, rings at 1,153 Hz
MAX_RINGING_HZ = 10_000.0
#: largest acceleration slope A of a vibration model [1/s]: a hundred times aluminum's
#: (−1·10⁵ 1/s, Table 1); at a 0.11-m/s tap it is already ~10⁵ g
MAX_SLOPE = 1.0e7
#: fastest decay rate B of a vibration model [1/s]: 1/e within 10 µs, a tick of the 100-kHz
#: reference servo (aluminum's is 1,500 1/s)
MAX_DECAY = 1.0e5
#: largest force gain of a pulse or sinusoid [N·s/m]: at a 0.11-m/s tap, 10⁴ N·s/m asks
#: 1.1 kN, hundreds of times any desktop device's peak force (the study's: 15.9 N·s/m)
MAX_GAIN = 1.0e4

# range rules for _set_checked
_NONNEG: dict[str, Any] = {"minimum": 0.0}
_POS: dict[str, Any] = {"minimum": 0.0, "strict": True}
_STIFFNESS: dict[str, Any] = {"minimum": 0.0, "strict": True, "maximum": MAX_STIFFNESS,
                              "why": "steel pressed on steel by a stylus is ~1.2e7 N/m"}
_DAMPING: dict[str, Any] = {"minimum": 0.0, "maximum": MAX_DAMPING,
                            "why": "twice critical damping of the stiffest contact on a 5-kg block"}
_GAIN: dict[str, Any] = {"minimum": 0.0, "maximum": MAX_GAIN,
                         "why": "1.1 kN at a 0.11-m/s tap, beyond any desktop device"}
_DECAY: dict[str, Any] = {"minimum": 0.0, "strict": True, "maximum": MAX_DECAY,
                          "why": "1/e within a 100-kHz tick"}
_FRACTION: dict[str, Any] = {"minimum": 0.0, "strict": True, "maximum": 1.0}
_FRACTION_2: dict[str, Any] = {"minimum": 0.0, "strict": True, "maximum": 2.0}


def _set_checked(obj: Any, where: str, **rules: dict[str, Any]) -> None:
    """Validate fields of a frozen dataclass in place: ``field=rule`` for :func:`_finite`."""
    for name, rule in rules.items():
        object.__setattr__(obj, name, _finite(where, name, getattr(obj, name), **rule))


def _check_slope(obj: Any, where: str) -> None:
    """A vibration model's slope A [1/s]: finite, |A| <= :data:`MAX_SLOPE` (either sign)."""
    a = _finite(where, "slope", obj.slope)
    if abs(a) > MAX_SLOPE:
        raise SceneError(f"must be within ±{MAX_SLOPE:g}, got {a:g} (a hundred times "
                         "aluminum's slope)", "slope", where=where)
    object.__setattr__(obj, "slope", a)


def unknown_key(key: str, allowed) -> str:
    """The one phrasing of an unknown key, for scenes and protocol files alike."""
    import difflib

    hint = difflib.get_close_matches(str(key), sorted(allowed), n=1, cutoff=0.5)
    extra = f" (did you mean '{hint[0]}'?)" if hint else ""
    return f"unknown key{extra}; allowed: {', '.join(sorted(allowed))}"


def _check_keys(where: str, data: Mapping[str, Any], allowed: set[str], required: set[str]) -> None:
    for key in data:
        if key not in allowed:
            raise SceneError(unknown_key(key, allowed), key, where=where)
    missing = sorted(required - set(data))
    if missing:
        raise SceneError(f"missing (required: {', '.join(sorted(required))})", missing[0],
                         where=where)


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


BLENDS = tuple(b.label for b in Blend)
#: longest contact transient a device is asked to play [s] (the papers' last ≤ 0.1 s)
MAX_TRANSIENT_S = 1.0
#: a transient a device renders at less than this share of its peak is refused
#: (:meth:`Transient.rendered_share`; a frequency near Nyquist: at 0.499 × the servo rate
#: a sinusoid's table reached 4–14 % of its peak, and the hold passes 64 % of that)
MIN_RENDERED = 0.5
#: ... and one rendered at less than this is warned of (``protocol validate --device``,
#: the preflight): a fifth of the rate renders ~89 %, a quarter ~90 %, a third ~72 %
WARN_RENDERED = 0.85
#: how much finer than the servo the transient's true peak is sampled for that comparison
OVERSAMPLE = 64
#: farthest a surface may be from the device's origin [m]: a desktop stylus reaches a few
#: centimetres, and a surface beyond reach would make every window time out
MAX_REACH_M = 0.5


@dataclass(frozen=True, eq=False)
class TransientTable:
    """Force transients to play at a contact, one row per reference speed.

    Parameters
    ----------
    velocities : ndarray, shape (n,) [m/s]
        Incoming speed of each row, ascending.
    forces : ndarray, shape (n, L) [N]
        Force per servo tick after contact for each row.
    blend : str
        How a contact at speed v uses the rows: ``scale`` (row 0 × v/v0), ``nearest``
        (nearest row × v/v_i) or ``linear`` (the two bracketing rows weighted linearly;
        outside the range the end row × v/v_end).
    attenuation : float
        Factor on everything played (0.8 for the acceleration-matched library).
    """

    velocities: Any
    forces: Any
    blend: Blend | str = Blend.SCALE
    attenuation: float = 1.0

    def __post_init__(self) -> None:
        import numpy as np

        w = "transient table"
        v = np.ascontiguousarray(self.velocities, dtype=float).reshape(-1)
        f = np.ascontiguousarray(self.forces, dtype=float)
        if f.ndim == 1:
            f = f[None, :]
        if f.ndim != 2 or f.shape[0] != v.size or v.size == 0 or f.shape[1] == 0:
            raise SceneError(f"{v.size} velocities for {f.shape[0]} rows of "
                             f"{f.shape[1] if f.ndim == 2 else 0} ticks", "forces", where=w)
        if not (np.all(np.isfinite(v)) and np.all(v > 0) and np.all(np.diff(v) > 0)):
            raise SceneError("must be finite, > 0 and ascending", "velocities", where=w)
        if not np.all(np.isfinite(f)):
            bad = int(np.flatnonzero(~np.isfinite(f.reshape(-1)))[0])
            raise SceneError(f"must be finite; row {bad // f.shape[1]}, tick "
                             f"{bad % f.shape[1]} is {f.reshape(-1)[bad]}", "forces", where=w)
        try:
            blend = Blend.parse(self.blend)
        except ValueError as exc:
            raise SceneError(str(exc), "blend", where=w) from None
        object.__setattr__(self, "velocities", v)
        object.__setattr__(self, "forces", f)
        object.__setattr__(self, "blend", blend)
        object.__setattr__(self, "attenuation", _finite(w, "attenuation", self.attenuation,
                                                        minimum=0.0))

    def force_at(self, speed: float):
        """The force transient [N] a contact at ``speed`` [m/s] plays (reference for tests)."""
        v, f = self.velocities, self.forces
        if self.blend == Blend.SCALE or len(v) == 1:
            out = f[0] * speed / v[0]
        elif self.blend == Blend.NEAREST:
            i = int(abs(v - speed).argmin())
            out = f[i] * speed / v[i]
        elif speed <= v[0]:
            out = f[0] * speed / v[0]
        elif speed >= v[-1]:
            out = f[-1] * speed / v[-1]
        else:
            j = int((v < speed).sum()) - 1
            w = (speed - v[j]) / (v[j + 1] - v[j])
            out = (1 - w) * f[j] + w * f[j + 1]
        return self.attenuation * out


class Transient:
    """Base of open-loop contact transients; subclasses register a ``kind`` name.

    A transient becomes a :class:`TransientTable` at a servo rate. Parametric kinds
    define :meth:`unit_table`, the force [N] per tick for a contact at 1 m/s, scaled
    by the device's own estimate of the incoming speed.
    """

    kind: ClassVar[str] = ""
    #: (field, [Hz]) of the transient's frequency, if it has one (checked against Nyquist)
    _frequency_field: ClassVar[str | None] = None
    #: the field that sets how long the table lasts
    _length_field: ClassVar[str | None] = None

    def unit_table(self, rate_hz: float, effective_mass: float):
        """Force per unit incoming speed [N/(m/s)] at each servo tick after contact."""
        raise NotImplementedError(f"transient kind {self.kind!r} has no unit table")

    def table(self, rate_hz: float, effective_mass: float) -> TransientTable:
        """What the device plays (see :class:`TransientTable`), after :meth:`check_for`."""
        self.check_for(rate_hz)
        return TransientTable([1.0], self.unit_table(rate_hz, effective_mass), "scale")

    def length_s(self) -> float | None:
        """How long the table lasts [s] (None: not a parametric transient)."""
        return None

    def frequency_hz(self) -> float | None:
        """The vibration frequency [Hz] the table must carry (None: none)."""
        return None

    def rendered_share(self, rate_hz: float) -> float | None:
        """Share [1] of the transient's peak that a device at ``rate_hz`` [Hz] renders.

        Two losses, both worse towards the Nyquist frequency: the table's samples miss the
        transient's crests (its largest sample against the transient sampled
        :data:`OVERSAMPLE` times finer), and the device holds each sample for a tick, which
        passes a frequency f with the gain sin(πf/R)/(πf/R) (64 % at Nyquist). At 0.499 ×
        the rate a decaying sinusoid renders 7 % (5-ms decay) to 41 % (50 ms) of its peak;
        at a quarter of the rate 90 %. None: the transient has no frequency, or nothing to play.
        """
        import numpy as np

        f = self.frequency_hz()
        if f is None:
            return None
        fine = float(np.max(np.abs(self.unit_table(rate_hz * OVERSAMPLE, 1.0))))
        if not fine > 0:
            return None
        crests = float(np.max(np.abs(self.unit_table(rate_hz, 1.0)))) / fine
        return crests * float(np.sinc(f / rate_hz))  # numpy's sinc is sin(πx)/(πx)

    def rendering_note(self, rate_hz: float) -> str | None:
        """A warning, in words, when a device at ``rate_hz`` [Hz] plays less than
        :data:`WARN_RENDERED` of the transient's peak (None: it renders it faithfully)."""
        share = self.rendered_share(rate_hz)
        if share is None or share >= WARN_RENDERED:
            return None
        f = self.frequency_hz()
        return (f"a device at {rate_hz:g} Hz renders {share:.0%} of its peak ({f:g} Hz is "
                f"{f / rate_hz:.3g} × the servo rate: its samples miss the crests and each "
                f"is held a tick); keep it below about {rate_hz / 5:g} Hz, or use a faster "
                "servo")

    def check_for(self, rate_hz: float) -> None:
        """Refuse a transient a device at ``rate_hz`` [Hz] cannot play as written.

        A frequency at or above half the servo rate would alias (at exactly the rate it
        samples to zeros), and one the device renders at less than :data:`MIN_RENDERED` of
        its peak is not the transient asked for (:meth:`rendered_share`); a table shorter
        than one tick is nothing, and a time constant shorter than one tick is a single
        sample; a table longer than :data:`MAX_TRANSIENT_S` is not a contact transient (and
        would fill the device's memory).

        Raises
        ------
        SceneError
            Naming the field, its value and the range allowed at this rate.
        """
        where = f"transient '{self.kind}'"
        nyq = rate_hz / 2
        f = self.frequency_hz()
        if f is not None and not f < nyq:
            raise SceneError(f"{f:g} Hz is at or above the Nyquist frequency of a "
                             f"{rate_hz:g}-Hz servo; must be < {nyq:g} Hz",
                             self._frequency_field, where=where)
        d = self.length_s()
        if d is None:
            return
        tick = 1.0 / rate_hz
        if not d <= MAX_TRANSIENT_S:
            raise SceneError(f"the table would last {d:.3g} s; a contact transient lasts at "
                             f"most {MAX_TRANSIENT_S:g} s", self._length_field, where=where)
        if not d >= tick:
            raise SceneError(f"the table would last {d:.3g} s, less than one servo tick "
                             f"({tick:g} s at {rate_hz:g} Hz)", self._length_field, where=where)
        share = self.rendered_share(rate_hz)
        if share is not None and share < MIN_RENDERED:
            raise SceneError(f"a device at {rate_hz:g} Hz renders only {share:.0%} of its "
                             f"peak ({f:g} Hz is {f / rate_hz:.3f} × the servo rate: its "
                             "samples miss the crests and each is held a tick); keep it "
                             f"below about {rate_hz / 5:g} Hz, or use a faster servo",
                             self._frequency_field, where=where)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"kind": self.kind}
        for f in fields(self):  # type: ignore[arg-type]
            out[f.name] = getattr(self, f.name)
        return out


_TRANSIENTS: dict[str, Callable[[str, Mapping[str, Any]], Transient]] = {}


def register_transient(kind: str, parser: Callable[[str, Mapping[str, Any]], Transient]) -> None:
    """Make a transient kind available to :meth:`Scene.from_dict`.

    ``parser(where, data)`` receives the table without its ``kind`` key and returns
    a :class:`Transient`, raising :class:`SceneError` naming ``where`` on bad data.
    Later capabilities (acceleration-matched libraries, the grasp model) plug in here.
    """
    _TRANSIENTS[kind] = parser


def transient_kinds() -> list[str]:
    """Names of the transient kinds this installation can build, sorted."""
    return sorted(_TRANSIENTS)


@dataclass(frozen=True)
class Pulse(Transient):
    """Fixed-duration rectangular force pulse of magnitude ``gain``·v.

    Parameters
    ----------
    gain : float [N·s/m]
        A, force per unit incoming speed.
    duration : float [s]
        d, pulse length.
    """

    kind: ClassVar[str] = "pulse"
    _length_field: ClassVar[str] = "duration"
    gain: float
    duration: float

    def __post_init__(self) -> None:
        _set_checked(self, "transient 'pulse'", gain=_GAIN, duration=_POS)

    def length_s(self) -> float:
        return self.duration

    def unit_table(self, rate_hz: float, effective_mass: float):
        import numpy as np

        n = max(1, int(round(self.duration * rate_hz)))
        return np.full(n, self.gain)


@dataclass(frozen=True)
class ForceSinusoid(Transient):
    """Decaying sinusoid specified in force: F(t) = A·v·exp(−t/d)·sin(2π·f·t).

    ``d`` is read as the decay time constant; the table stops when the envelope
    has fallen to ``cutoff`` of its start.

    Parameters
    ----------
    gain : float [N·s/m]
        A.
    decay_time : float [s]
        d, time constant of the envelope.
    frequency : float [Hz]
        f.
    cutoff : float [1]
        Relative envelope at which playback stops (default 0.01, i.e. after d·ln 100).
    """

    kind: ClassVar[str] = "sinusoid"
    _frequency_field: ClassVar[str] = "frequency"
    _length_field: ClassVar[str] = "decay_time"
    gain: float
    decay_time: float
    frequency: float
    cutoff: float = 0.01

    def __post_init__(self) -> None:
        _set_checked(self, "transient 'sinusoid'", gain=_GAIN, decay_time=_POS,
                     frequency=_POS, cutoff=_FRACTION)

    def length_s(self) -> float:
        return self.decay_time * math.log(1.0 / self.cutoff)

    def frequency_hz(self) -> float:
        return self.frequency

    def check_for(self, rate_hz: float) -> None:
        super().check_for(rate_hz)
        if not self.decay_time >= 1.0 / rate_hz:
            raise SceneError(f"{self.decay_time:g} s is shorter than one servo tick "
                             f"({1 / rate_hz:g} s at {rate_hz:g} Hz): the table would be one "
                             "sample", "decay_time", where="transient 'sinusoid'")

    def unit_table(self, rate_hz: float, effective_mass: float):
        import numpy as np

        n = max(1, int(math.ceil(self.decay_time * math.log(1.0 / self.cutoff) * rate_hz)))
        t = np.arange(n) / rate_hz
        return self.gain * np.exp(-t / self.decay_time) * np.sin(2 * np.pi * self.frequency * t)


@dataclass(frozen=True)
class AccelSinusoid(Transient):
    """Decaying sinusoid specified in acceleration, played as effective mass × Q(t).

    Q(t) = A·v_n·exp(−B·t)·sin(2π·f·t) with v_n the (negative) normal velocity,
    as in the reality-based vibration models (SPEC §2).

    Parameters
    ----------
    slope : float [1/s]
        A (negative in the papers' tables).
    decay : float [1/s]
        B.
    frequency : float [Hz]
        f.
    cutoff : float [1]
        Relative envelope at which playback stops (default 0.01).
    """

    kind: ClassVar[str] = "q_sinusoid"
    _frequency_field: ClassVar[str] = "frequency"
    _length_field: ClassVar[str] = "decay"
    slope: float
    decay: float
    frequency: float
    cutoff: float = 0.01

    def __post_init__(self) -> None:
        _check_slope(self, "transient 'q_sinusoid'")
        _set_checked(self, "transient 'q_sinusoid'", decay=_DECAY, frequency=_POS,
                     cutoff=_FRACTION)

    def length_s(self) -> float:
        return math.log(1.0 / self.cutoff) / self.decay

    def frequency_hz(self) -> float:
        return self.frequency

    def check_for(self, rate_hz: float) -> None:
        super().check_for(rate_hz)
        if not self.decay <= rate_hz:
            raise SceneError(f"{self.decay:g} 1/s decays within one servo tick at {rate_hz:g} "
                             f"Hz (the table would be one sample); must be <= {rate_hz:g} 1/s",
                             "decay", where="transient 'q_sinusoid'")

    def unit_table(self, rate_hz: float, effective_mass: float):
        import numpy as np

        n = max(1, int(math.ceil(math.log(1.0 / self.cutoff) / self.decay * rate_hz)))
        t = np.arange(n) / rate_hz
        ring = Ringing(self.slope, self.decay, self.frequency)
        return effective_mass * ring.acceleration(t, 1.0)


@dataclass(frozen=True)
class LibraryTransient(Transient):
    """Acceleration-matched transients from a library built on the device itself.

    Parameters
    ----------
    source : str
        Id of the real sample whose taps the library reproduces (e.g. ``wood_on_foam``).
    attenuation : float [1]
        Factor on the whole library at playback (0.8 in the study: the unscaled
        library felt "active").
    blend : str
        ``linear`` (two nearest entries by velocity), ``nearest`` or ``scale``.
    path : str or None
        Library file. Without it, the library built on the device in use is looked up in
        the library store (:func:`device.matching.library.find_library`); a library is
        refused on any device but the one it was made on.
    source_scene : Scene or None
        The source sample's scene, filled in by the protocol loader.
    """

    kind: ClassVar[str] = "library"
    source: str
    attenuation: float = 0.8
    blend: str = "linear"
    path: str | None = None
    source_scene: Scene | None = None

    def __post_init__(self) -> None:
        w = "transient 'library'"
        if not isinstance(self.source, str) or not self.source:
            raise SceneError("must name the real sample the library matches, got "
                             f"{self.source!r}", "source", where=w)
        _set_checked(self, w, attenuation=_FRACTION_2)
        if self.blend not in BLENDS:
            raise SceneError(f"must be one of {', '.join(BLENDS)}, got {self.blend!r}",
                             "blend", where=w)
        if self.path is not None and (not isinstance(self.path, str) or not self.path):
            raise SceneError(f"must be a file name, got {self.path!r}", "path", where=w)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"kind": self.kind, "source": self.source,
                               "attenuation": self.attenuation, "blend": self.blend}
        if self.path is not None:
            out["path"] = self.path
        return out


@dataclass(frozen=True)
class GraspModel:
    """m, c, k linear in grasp force: value = intercept + slope·F_g."""

    m: tuple[float, float] = (0.023, -0.00032)
    c: tuple[float, float] = (14.0, -0.19)
    k: tuple[float, float] = (75_000.0, -1_000.0)

    def at(self, grasp_force: float) -> tuple[float, float, float]:
        """(m [kg], c [N·s/m], k [N/m]) at ``grasp_force`` [N]."""
        m, c, k = (p[0] + p[1] * grasp_force for p in (self.m, self.c, self.k))
        if min(m, c, k) <= 0:
            raise ValueError(f"grasp force {grasp_force} N is outside the model's range "
                             f"(m={m:.4g} kg, c={c:.4g} N·s/m, k={k:.4g} N/m must be > 0)")
        return m, c, k


PUBLISHED_GRASP = GraspModel()


@dataclass(frozen=True)
class GraspTransient(Transient):
    """Contact transient of a gripper scene, scaled by grasp force (SPEC §3).

    The grasp paper's model, m·ẍ + c·ẋ + k·x = F, with m, c, k at the scene's grasp force
    F_g and F_g as its input (its a(s)/F(s) = K·s²/(T²s² + 2ζTs + 1)). With x out of the
    surface, the handle arrives at speed v (ẋ(0) = −v, x(0) = 0) and from the contact on
    the surface returns the grasp force it is pressed with, a step F_g; with σ = ζω_n and
    ω_d = ω_n√(1 − ζ²)

        ẍ(t) = e^(−σt)·[v·(2σω_d·cos ω_d t − (σ² − ω_d²)·sin ω_d t)/ω_d
                       + (F_g/m)·(cos ω_d t − (σ/ω_d)·sin ω_d t)].

    The first term is the speed's share (it stops the handle), the second the grasp's
    (the step response of the paper's eq. 7), which makes the peak grow about linearly
    with grasp force, as the paper measured: at 0.11 m/s, 166 m/s² at 0 N, 315 at 5 N,
    1,272 at 20 N. The device plays ``attenuation`` × effective mass × ẍ, from a two-row
    table at :attr:`SPEEDS` with the linear blend, which is exact between them because ẍ
    is affine in v (below the slowest row the device scales it by speed, as every table).
    On a 55-g stylus that is 9–70 N at 0.11 m/s unattenuated: the paper's gripper, not a
    desktop device; a scene for a 3-N device attenuates it (0.04 keeps 5 N of grasp at
    0.11 m/s within 3 N), and the protocol check and the wire refuse what does not fit.

    Parameters
    ----------
    grasp_force : float [N]
    cutoff : float [1]
        Playback stops when the envelope falls to this fraction.
    attenuation : float [1]
        Factor on the force played, in (0, 1].
    """

    kind: ClassVar[str] = "grasp"
    _frequency_field: ClassVar[str] = "grasp_force"
    _length_field: ClassVar[str] = "cutoff"
    #: incoming speeds of the table's rows [m/s]: the simulated tapper's whole range
    SPEEDS: ClassVar[tuple[float, float]] = (0.02, 0.40)
    grasp_force: float
    cutoff: float = 0.01
    attenuation: float = 1.0

    def __post_init__(self) -> None:
        w = "transient 'grasp'"
        _set_checked(self, w, grasp_force=_NONNEG, cutoff=_FRACTION, attenuation=_FRACTION)
        try:
            PUBLISHED_GRASP.at(self.grasp_force)
        except ValueError as exc:
            raise SceneError(str(exc), "grasp_force", where=w) from None

    def _modal(self) -> tuple[float, float]:
        """(σ [1/s], ω_d [rad/s]) of the grasped handle at this grasp force."""
        m, c, k = PUBLISHED_GRASP.at(self.grasp_force)
        wn = math.sqrt(k / m)
        zeta = c / (2 * math.sqrt(k * m))
        return zeta * wn, wn * math.sqrt(max(1e-12, (1 - zeta) * (1 + zeta)))

    def length_s(self) -> float:
        sigma, _ = self._modal()
        return math.log(1 / self.cutoff) / sigma

    def frequency_hz(self) -> float:
        return self._modal()[1] / (2 * math.pi)

    def shares(self, rate_hz: float):
        """(per unit speed [m/s² per m/s], of the grasp [m/s²]): the handle's acceleration
        at each servo tick after contact, out of the surface positive."""
        import numpy as np

        m = PUBLISHED_GRASP.at(self.grasp_force)[0]
        sigma, wd = self._modal()
        t = np.arange(max(1, int(math.ceil(self.length_s() * rate_hz)))) / rate_hz
        e, sn, cs = np.exp(-sigma * t), np.sin(wd * t), np.cos(wd * t)
        speed = -e * ((sigma**2 - wd**2) * sn - 2 * sigma * wd * cs) / wd
        grasp = self.grasp_force / m * e * (cs - sigma / wd * sn)
        return speed, grasp

    def unit_table(self, rate_hz: float, effective_mass: float):
        """The speed's share alone, per unit speed [N/(m/s)] (its frequency and crests are
        the whole transient's; what is played is :meth:`table`)."""
        return self.attenuation * effective_mass * self.shares(rate_hz)[0]

    def table(self, rate_hz: float, effective_mass: float) -> TransientTable:
        self.check_for(rate_hz)
        speed, grasp = self.shares(rate_hz)
        k = self.attenuation * effective_mass  # in the rows: the wire checks what is played
        return TransientTable(list(self.SPEEDS), [k * (v * speed + grasp) for v in self.SPEEDS],
                              "linear")


@dataclass(frozen=True, eq=False)
class TableTransient(Transient):
    """A transient given directly as a :class:`TransientTable` (e.g. received by an emulator
    over the wire). Not built from protocol data."""

    kind: ClassVar[str] = "table"
    transient_table: TransientTable

    def table(self, rate_hz: float, effective_mass: float) -> TransientTable:
        return self.transient_table

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "rows": int(len(self.transient_table.velocities))}


def _dataclass_parser(cls, exclude: tuple[str, ...] = ()
                      ) -> Callable[[str, Mapping[str, Any]], Transient]:
    """Parser for a transient dataclass: its fields (less ``exclude``) are the allowed keys."""
    names = {f.name for f in fields(cls)} - set(exclude)
    required = {f.name for f in fields(cls)
                if f.default is MISSING and f.default_factory is MISSING} - set(exclude)

    def parse(where: str, data: Mapping[str, Any]) -> Transient:
        _check_keys(where, data, names, required)
        try:
            return cls(**data)
        except SceneError as exc:
            raise exc.within(where=where) from None

    return parse


for _cls in (Pulse, ForceSinusoid, AccelSinusoid, GraspTransient):
    register_transient(_cls.kind, _dataclass_parser(_cls))
# a library's source scene comes from the protocol, never from the transient's own data
register_transient(LibraryTransient.kind, _dataclass_parser(LibraryTransient, ("source_scene",)))


@dataclass(frozen=True)
class Scene:
    """One sample as the device sees it.

    Exactly one of ``material`` (a real sample, physically touched) and ``spring``
    (a virtual sample) is set. Build scenes from data with :meth:`from_dict`.

    Parameters
    ----------
    name : str
        Identifier, used in records and messages.
    surface_height : float [m]
        Height of the (real or virtual) surface in device coordinates, within
        ±:data:`MAX_REACH_M`.
    spring : float or None [N/m]
        Penetration-spring stiffness of a virtual sample (0 allowed: transient only);
        None for a real sample.
    transient : Transient or None
        Open-loop force transient played at each contact (virtual samples only).
    material : Material or None
        Physical contact of a real sample.
    """

    name: str
    surface_height: float = 0.0
    spring: float | None = None
    transient: Transient | None = None
    material: Material | None = None
    meta: Mapping[str, Any] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise SceneError(f"must be a non-empty string, got {self.name!r}", "name",
                             where="scene")
        where = f"scene '{self.name}'"
        object.__setattr__(self, "surface_height",
                           _finite(where, "surface_height", self.surface_height,
                                   minimum=-MAX_REACH_M, maximum=MAX_REACH_M))
        if self.material is None and self.spring is None:
            raise SceneError("a scene needs either 'material' (real sample) or 'spring' "
                             "(virtual sample)", "spring", where=where)
        if self.material is not None and (self.spring is not None or self.transient is not None):
            raise SceneError("a real sample ('material') cannot also have 'spring' or "
                             "'transient'; real samples are touched, not rendered",
                             "spring" if self.spring is not None else "transient", where=where)
        if self.spring is not None:
            object.__setattr__(self, "spring", _finite(where, "spring", self.spring,
                                                       **{**_STIFFNESS, "strict": False}))

    @property
    def is_real(self) -> bool:
        """True for a physical sample (no rendering)."""
        return self.material is not None

    @property
    def kind(self) -> str:
        """``real``, ``spring`` or the transient kind."""
        if self.material is not None:
            return "real"
        return self.transient.kind if self.transient is not None else "spring"

    # ------------------------------------------------------------------ data
    _KEYS: ClassVar[set[str]] = {"name", "surface_height", "spring", "transient", "material"}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str | None = None) -> Scene:
        """Build and validate a scene from plain data (e.g. a TOML table).

        Parameters
        ----------
        data : mapping
            Keys ``name``, ``surface_height`` [m], and either ``spring`` [N/m] with an
            optional ``transient`` table (``kind`` plus its fields), or a ``material``
            table (``stiffness`` [N/m], ``damping`` [N·s/m], optional ``ringing`` table
            with ``slope`` [1/s], ``decay`` [1/s], ``frequency`` [Hz]).
        where : str, optional
            Prefix for error messages (e.g. a file and table name).

        Raises
        ------
        SceneError
            Naming the field, the offending value and what is allowed.
        """
        if not isinstance(data, Mapping):
            raise SceneError(f"expected a table, got {type(data).__name__}",
                             where=where or "scene")
        name = data.get("name", "?")
        where = where or f"scene '{name}'"
        _check_keys(where, data, cls._KEYS, {"name"})
        kwargs: dict[str, Any] = {"name": data["name"]}
        if "surface_height" in data:
            kwargs["surface_height"] = data["surface_height"]
        if "spring" in data:
            kwargs["spring"] = data["spring"]
        if "transient" in data:
            kwargs["transient"] = _in_part(("transient",), _parse_transient,
                                           f"{where}.transient", data["transient"])
        if "material" in data:
            kwargs["material"] = _in_part(("material",), _parse_material,
                                          f"{where}.material", data["material"])
        try:
            return cls(**kwargs)
        except SceneError as exc:
            raise exc.within(where=where) from None

    def to_dict(self) -> dict[str, Any]:
        """Plain-data form accepted by :meth:`from_dict`."""
        out: dict[str, Any] = {"name": self.name, "surface_height": self.surface_height}
        if self.spring is not None:
            out["spring"] = self.spring
        if self.transient is not None:
            out["transient"] = self.transient.to_dict()
        if self.material is not None:
            m: dict[str, Any] = {"stiffness": self.material.stiffness,
                                 "damping": self.material.damping}
            if self.material.ringing is not None:
                r = self.material.ringing
                m["ringing"] = {"slope": r.slope, "decay": r.decay, "frequency": r.frequency}
            if self.material.mass is not None:
                m["mass"] = self.material.mass
            if self.material.support is not None:
                sp = self.material.support
                m["support"] = {"stiffness": sp.stiffness, "damping": sp.damping}
            out["material"] = m
        return out


def _in_part(part: tuple[str, ...], parse: Callable[[str, Any], Any], where: str, data: Any):
    """Run a sub-parser, recording in any SceneError which part of the scene failed."""
    try:
        return parse(where, data)
    except SceneError as exc:
        raise exc.within(part) from None


def _parse_transient(where: str, data: Any) -> Transient | None:
    if not isinstance(data, Mapping):
        raise SceneError(f"expected a table with 'kind', got {data!r}", where=where)
    kind = data.get("kind")
    kinds = "none, " + ", ".join(transient_kinds())
    if kind in (None, "none"):
        if kind is None:
            raise SceneError(f"missing (allowed kinds: {kinds})", "kind", where=where)
        _check_keys(where, data, {"kind"}, set())
        return None
    if kind not in _TRANSIENTS:
        raise SceneError(f"transient kind {kind!r} is not available; allowed: {kinds}",
                         "kind", where=where)
    rest = {k: v for k, v in data.items() if k != "kind"}
    return _TRANSIENTS[kind](where, rest)


def _parse_material(where: str, data: Any) -> Material:
    if not isinstance(data, Mapping):
        raise SceneError(f"expected a table, got {data!r}", where=where)
    _check_keys(where, data, {"stiffness", "damping", "ringing", "mass", "support"},
                {"stiffness"})
    if "damping" in data and "mass" in data and "ringing" in data:
        raise SceneError("a ringing block's contact damping is derived from its ringing's "
                         "decay; remove 'damping'", "damping", where=where)
    ringing = _sub_table(where, data, "ringing", Ringing, {"slope", "decay", "frequency"},
                         {"slope", "decay", "frequency"})
    support = _sub_table(where, data, "support", Support, {"stiffness", "damping"},
                         {"stiffness"})
    try:
        return Material(stiffness=data["stiffness"], damping=data.get("damping", 0.0),
                        ringing=ringing, mass=data.get("mass"), support=support)
    except SceneError as exc:
        raise exc.within(where=where) from None


def _sub_table(where: str, data: Mapping[str, Any], key: str, cls, allowed: set[str],
               required: set[str]):
    """The optional sub-table ``key`` of a material, built as ``cls`` (None when absent)."""
    if key not in data:
        return None
    r = data[key]
    w = f"{where}.{key}"
    if not isinstance(r, Mapping):
        raise SceneError(f"expected a table, got {r!r}", part=(key,), where=w)

    def build(w: str, d: Mapping[str, Any]):
        _check_keys(w, d, allowed, required)
        try:
            return cls(**d)
        except SceneError as exc:
            raise exc.within(where=w) from None

    return _in_part((key,), build, w, r)
