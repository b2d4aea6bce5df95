"""An adaptive phase's keys in a protocol file (:mod:`protocols.loader` calls it): the
parameter, units, tracks and the procedure's table, each problem named by file, line and
field."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from device.scene import SceneError

from .adaptive import (
    DIRECTIONS,
    UNITS,
    AdaptiveDesign,
    QuestPlus,
    Staircase,
    Track,
    comparison_sample,
    value_at,
)

__all__ = ["ADAPTIVE_KEYS", "FITS", "adaptive_design", "fit_options", "extreme_samples"]

#: the phase keys of an adaptive kind (no other kind takes them)
ADAPTIVE_KEYS = ("parameter", "units", "directions", "max_trials", "catch", "catch_intensity",
                 "question", "presentation", "staircase", "questplus")
#: psychometric functions the analysis fits
FITS = ("weibull", "normal", "logistic")
#: what the participant is asked when the phase does not say, by parameter
QUESTIONS = {"frequency": "Which vibrated faster (the higher pitch)?",
             "decay": "Which died away faster?",
             "slope": "Which tap was stronger?",
             "gain": "Which tap was stronger?",
             "decay_time": "Which rang longer?"}


def _numbers(cx, path: tuple, value: Any, *, minimum: float | None = None,
             strict: bool = False, maximum: float | None = None) -> tuple[float, ...]:
    if not isinstance(value, list) or not value:
        raise cx.error(path, f"must be a list of numbers, got {value!r}")
    return tuple(float(cx.number((*path, i), v, minimum=minimum, strict=strict,
                                 maximum=maximum)) for i, v in enumerate(value))


def _grid(cx, path: tuple, raw: Any) -> tuple[float, ...]:
    """A grid: a list, or ``{ min, max, n, spacing = "log" | "linear" }``."""
    if isinstance(raw, list):
        vals = _numbers(cx, path, raw, minimum=0, strict=True)
        if list(vals) != sorted(set(vals)) or len(vals) < 2:
            raise cx.error(path, "must be two or more rising numbers")
        return vals
    g = cx.table(path, raw, {"min", "max", "n", "spacing"}, {"min", "max", "n"})
    lo = float(cx.number((*path, "min"), g["min"], minimum=0, strict=True))
    hi = float(cx.number((*path, "max"), g["max"], minimum=lo, strict=True))
    n = int(cx.number((*path, "n"), g["n"], minimum=2, maximum=400, integer=True))
    spacing = cx.string((*path, "spacing"), g.get("spacing", "log"), ("log", "linear"))
    vals = np.geomspace(lo, hi, n) if spacing == "log" else np.linspace(lo, hi, n)
    return tuple(float(f"{v:.6g}") for v in vals)


def _staircase(cx, path: tuple, raw: Any) -> Staircase:
    s = cx.table(path, raw, {"start", "steps", "change_after", "down", "stop_reversals",
                             "discard", "min", "max"}, {"start", "steps", "max"})
    steps = _numbers(cx, (*path, "steps"), s["steps"], minimum=0, strict=True)
    change = s.get("change_after", [])
    if not isinstance(change, list) or not all(isinstance(c, int) and not isinstance(c, bool)
                                               for c in change):
        raise cx.error((*path, "change_after"), f"must be a list of reversal counts, got "
                       f"{change!r}")
    lo = float(cx.number((*path, "min"), s.get("min", 0.0), minimum=0))
    hi = float(cx.number((*path, "max"), s["max"], minimum=lo, strict=True))
    try:
        return Staircase(
            start=float(cx.number((*path, "start"), s["start"])), steps=steps,
            change_after=tuple(change),
            down=int(cx.number((*path, "down"), s.get("down", 3), minimum=1, maximum=6,
                               integer=True)),
            stop_reversals=int(cx.number((*path, "stop_reversals"), s.get("stop_reversals", 12),
                                         minimum=1, maximum=200, integer=True)),
            discard=int(cx.number((*path, "discard"), s.get("discard", 4), minimum=0,
                                  integer=True)),
            minimum=lo, maximum=hi)
    except ValueError as exc:
        raise cx.error(path, str(exc)) from None


def _questplus(cx, path: tuple, raw: Any, criterion: float) -> QuestPlus:
    q = cx.table(path, raw, {"intensities", "thresholds", "slopes", "lapses", "trials"},
                 {"intensities"})
    stims = _grid(cx, (*path, "intensities"), q["intensities"])
    thresholds = _grid(cx, (*path, "thresholds"), q["thresholds"]) if "thresholds" in q \
        else stims
    kw = {}
    if "slopes" in q:
        kw["slopes"] = _numbers(cx, (*path, "slopes"), q["slopes"], minimum=0, strict=True)
    if "lapses" in q:
        kw["lapses"] = _numbers(cx, (*path, "lapses"), q["lapses"], minimum=0, maximum=0.49)
    try:
        return QuestPlus(intensities=stims, thresholds=thresholds, criterion=criterion,
                         trials=int(cx.number((*path, "trials"), q.get("trials", 50),
                                              minimum=1, maximum=2000, integer=True)), **kw)
    except ValueError as exc:
        raise cx.error(path, str(exc)) from None


def adaptive_design(cx, path: tuple, p: Mapping, kind, ids: tuple[str, ...], samples,
                    criterion: float) -> AdaptiveDesign:
    """The :class:`~protocols.adaptive.AdaptiveDesign` of an adaptive phase ``p``."""
    other = [k for k in ("staircase", "questplus") if k != kind.procedure and k in p]
    if other:
        raise cx.error((*path, other[0]), f"a{'n' if kind.name[0] in 'aeiou' else ''} "
                       f"{kind.name} phase runs its '{kind.procedure}' table, not '{other[0]}'")
    if kind.procedure not in p:
        raise cx.error((*path, kind.procedure), f"missing: a {kind.name} phase sets its "
                       f"procedure in a '{kind.procedure}' table")
    if "parameter" not in p:
        raise cx.error((*path, "parameter"), "missing: the transient parameter the "
                       "comparison changes (frequency, decay, slope, …)")
    parameter = cx.string((*path, "parameter"), p["parameter"])
    for k, sid in enumerate(ids):
        s = samples[sid]
        value = getattr(s.scene.transient, parameter, None)
        if s.is_real or isinstance(value, bool) or not isinstance(value, int | float) \
                or not value:
            kinds = s.scene.transient.kind if s.scene.transient is not None else "no transient"
            raise cx.error((*path, "samples", k), f"sample {sid!r} is a standard of this "
                           f"phase: a virtual sample whose transient has a nonzero "
                           f"'{parameter}' (its transient: {kinds})")
    units = cx.string((*path, "units"), p.get("units", "log"), UNITS)
    dirs = p.get("directions", ["up"])
    if not isinstance(dirs, list) or not dirs or len(set(map(str, dirs))) != len(dirs):
        raise cx.error((*path, "directions"), f"must be a list of up and down, got {dirs!r}")
    dirs = [cx.string((*path, "directions", i), d, DIRECTIONS) for i, d in enumerate(dirs)]
    proc = _staircase(cx, (*path, "staircase"), p["staircase"]) \
        if kind.procedure == "staircase" else \
        _questplus(cx, (*path, "questplus"), p["questplus"], criterion)
    top = proc.maximum if isinstance(proc, Staircase) else proc.intensities[-1]
    catch = float(cx.number((*path, "catch"), p.get("catch", 0.0), minimum=0, maximum=0.5))
    design = AdaptiveDesign(
        parameter=parameter, units=units, procedure=proc,
        tracks=tuple(Track(s, d, float(getattr(samples[s].scene.transient, parameter)))
                     for s in ids for d in dirs),
        max_trials=int(cx.number((*path, "max_trials"), p.get("max_trials", 60), minimum=1,
                                 maximum=2000, integer=True)),
        catch=catch,
        catch_intensity=float(cx.number((*path, "catch_intensity"),
                                        p.get("catch_intensity", top), minimum=0,
                                        strict=True)),
        question=cx.string((*path, "question"),
                           p.get("question", QUESTIONS.get(parameter, "Which was larger?"))),
        presentation=cx.string((*path, "presentation"), p.get("presentation", "intervals"),
                               ("intervals", "surfaces")))
    for track in design.tracks:  # every comparison it can make is a valid transient
        for x in _extremes(design):
            try:
                _comparison(design, samples[track.standard], track, x)
            except (SceneError, ValueError, ZeroDivisionError) as exc:
                raise cx.error(path, f"track '{track.name}': the comparison at intensity "
                               f"{x:g} {units} is not a transient: {exc}") from None
    return design


def _extremes(design: AdaptiveDesign) -> list[float]:
    p = design.procedure
    lo, hi = (p.minimum, p.maximum) if isinstance(p, Staircase) else \
        (p.intensities[0], p.intensities[-1])
    return sorted({lo, hi, design.catch_intensity} if design.catch else {lo, hi})


def _comparison(design: AdaptiveDesign, standard, track: Track, x: float):
    v = value_at(getattr(standard.scene.transient, design.parameter), x, design.units,
                 track.direction)
    if not math.isfinite(v) or (design.units == "linear" and track.direction == "down"
                                and abs(v) <= 0):
        raise ValueError(f"{design.parameter} would be {v:g}")
    return comparison_sample(standard, design.parameter, v)


def extreme_samples(design: AdaptiveDesign, samples):
    """(what, sample) of each standard of ``design`` and each comparison it can come to at
    the ends of its procedure's range (and its catch intensity): what a device must render
    for the phase to run."""
    for track in design.tracks:
        std = samples[track.standard]
        yield f"track '{track.name}', its standard '{std.id}'", std
        for x in _extremes(design):
            s = _comparison(design, std, track, x)
            value = getattr(s.scene.transient, design.parameter)
            yield (f"track '{track.name}', its comparison at intensity {x:g} {design.units} "
                   f"({design.parameter} {value:g})"), s


def fit_options(cx, path: tuple, a: Mapping, criterion: float) -> dict:
    """An adaptive phase's ``analysis`` fit keys, with their defaults."""
    crit = float(cx.number((*path, "criterion"), a.get("criterion", criterion), minimum=0.5,
                           strict=True, maximum=0.99))
    return {"criterion": crit,
            "function": cx.string((*path, "function"), a.get("function", "weibull"), FITS),
            "lapse_max": float(cx.number((*path, "lapse_max"), a.get("lapse_max", 0.06),
                                         minimum=0, maximum=0.2))}
