"""The checks every part of a scene shares: finite numbers in range, known keys, and the
bounds the papers' values sit far inside (private to :mod:`device`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from .errors import SceneError

__all__ = ["MAX_STIFFNESS", "MAX_DAMPING", "MAX_RINGING_HZ", "MAX_SLOPE", "MAX_DECAY",
           "MAX_GAIN", "unknown_key"]


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
