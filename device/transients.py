"""What a virtual sample plays at contact: :class:`Transient` and its kinds (pulse, decaying
sinusoids, a transient library, the grasp-force model, a table), the table a device plays
(:class:`TransientTable`), and the registry of kinds a scene's ``transient.kind`` names.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import MISSING, dataclass, fields
from typing import Any, ClassVar

from ._checks import (
    _DECAY,
    _FRACTION,
    _FRACTION_2,
    _GAIN,
    _NONNEG,
    _POS,
    _check_keys,
    _check_slope,
    _finite,
    _set_checked,
)
from .codes import Blend
from .errors import SceneError
from .materials import Ringing

__all__ = ["TransientTable", "Transient", "Pulse", "ForceSinusoid", "AccelSinusoid",
           "LibraryTransient", "GraspModel", "PUBLISHED_GRASP", "GraspTransient",
           "TableTransient", "register_transient", "transient_kinds", "BLENDS",
           "MAX_TRANSIENT_S", "MIN_RENDERED", "WARN_RENDERED", "OVERSAMPLE",
           "parse_transient"]


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
    """Make a transient kind available to :meth:`device.scene.Scene.from_dict`.

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
    source_scene: Any = None  # a Scene (device.scene imports this module, not the reverse)

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


def parse_transient(where: str, data: Any) -> Transient | None:
    """A scene's ``transient`` table as the :class:`Transient` of its ``kind`` (None for
    ``kind = "none"``), through the parser registered for that kind."""
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
