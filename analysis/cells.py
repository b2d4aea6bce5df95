"""The response cells of a trial row, read by the rules a session recorded with them.

A session records, with each phase's design, what the phase's response fills in a trial row
(``design["phases"][i]["response"]``: its cells with their unit, meaning and rule, and how
an export makes a participant's cells of it; written from the response's one declaration,
:mod:`protocols.responses`). The analysis reads files only, so it applies the rules from
that record: the vocabulary below, implemented once here, is all a rule can say.

Sessions recorded before responses recorded themselves carry only the phase's ``dv``;
:data:`LEGACY` holds what each of those three responses recorded the first time one did,
which is what those sessions' rows meant.
"""

from __future__ import annotations

import math

__all__ = ["LEGACY", "recorded_response", "cell_problem", "row_problem", "response_columns",
           "column_meanings"]

_RT = {"unit": "s", "meaning": "from the answer screen's onset to the answer",
       "type": "number", "noun": "response time", "range": [0.0, None], "required": False}

#: the record of the three responses older sessions asked, by their phase's ``dv``
LEGACY: dict[str, dict] = {
    "rating": {"name": "rating", "cells": {
        "rating": {"unit": "scale points", "type": "integer", "range": "scale",
                   "meaning": "the participant's rating on the protocol's scale"},
        "response_time": _RT},
        "wide": {"value": "rating", "by": "sample", "unit": "scale points",
                 "meaning": "mean rating of sample {cell} over its repetitions",
                 "name": "{cell}"}},
    "answer": {"name": "answer", "cells": {
        "answer": {"unit": "", "meaning": "the names given to the surfaces, in order",
                   "type": "names", "among": "answer_choices", "count": "samples", "sep": ","},
        "response_time": _RT,
        "correct": {"unit": "0/1", "meaning": "1 when every surface was named right",
                    "type": "integer", "among": [0, 1],
                    "labels": {"0": "wrong", "1": "all named right"}}},
        "wide": {"value": "correct", "by": "repetition", "unit": "0/1",
                 "meaning": "proportion correct in repetition {cell}", "name": "rep{cell}"}},
    "choice": {"name": "choice", "cells": {
        "answer": {"unit": "", "meaning": "the sample chosen as more like real contact",
                   "type": "text", "noun": "choice", "among": "samples"},
        "response_time": _RT},
        "wide": {"value": "answer", "by": "chosen", "unit": "proportion",
                 "meaning": "share of its comparisons sample {cell} won", "name": "{cell}"}},
}


def recorded_response(phase: dict | None) -> dict | None:
    """The response a recorded phase design asks: its own record, or for an older session
    the :data:`LEGACY` one of its ``dv`` (None: the phase asks nothing)."""
    if not phase:
        return None
    if phase.get("response") is not None:
        return phase["response"]
    return LEGACY.get(phase.get("dv"))


def response_columns(phase: dict | None) -> dict[str, dict]:
    """Column → cell record of the response a recorded phase asks ({} when none)."""
    r = recorded_response(phase)
    return dict(r["cells"]) if r else {}


def _fmt(v: float) -> str:
    return f"{v:g}"


def _bounds(cell: dict, design: dict | None) -> tuple[float | None, float | None, str]:
    """(low, high, what they are called) of a number cell's range."""
    rng = cell.get("range")
    if rng == "scale":
        scale = (design or {}).get("scale") or {}
        if not scale:
            return None, None, ""
        return scale["min"], scale["max"], f"the scale {scale['min']}–{scale['max']}"
    if rng is None:
        return None, None, ""
    lo, hi = rng
    lo = None if lo is None or (isinstance(lo, float) and math.isinf(lo)) else lo
    hi = None if hi is None or (isinstance(hi, float) and math.isinf(hi)) else hi
    words = (f"{_fmt(lo)}–{_fmt(hi)}" if lo is not None and hi is not None else
             f"at least {_fmt(lo)}" if lo is not None else f"at most {_fmt(hi)}")
    return lo, hi, words


def cell_problem(text: str, column: str, cell: dict, row: dict, design: dict | None) -> str:
    """Why the recorded ``text`` of ``column`` in a valid ``row`` cannot be analysed ('' when
    it can), by the rule of ``cell`` (a recorded cell, :class:`protocols.responses.Cell`)."""
    noun = cell.get("noun") or column
    text = (text or "").strip()
    if not text:
        return f"a valid trial without a {noun}" if cell.get("required", True) else ""
    kind = cell.get("type", "text")
    among = cell.get("among")
    felt = [s for s in str(row.get("sample", "")).split("+") if s]
    if kind in ("integer", "number"):
        try:
            v = float(text)
        except ValueError:
            return f"{noun} {text!r} is not a number"
        if not math.isfinite(v):
            return f"{noun} {text} is not a finite number"
        lo, hi, words = _bounds(cell, design)
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            return f"{noun} {text} is outside {words}"
        if kind == "integer" and v != int(v):
            return (f"{noun} {text} is not a point of the scale" if cell.get("range") == "scale"
                    else f"{noun} {text} is not a whole number")
        if isinstance(among, list) and not any(math.isclose(v, float(a)) for a in among):
            return f"{noun} is {text!r}, not {' or '.join(_fmt(float(a)) for a in among)}"
        return ""
    if kind == "names":
        names = [a for a in text.split(cell.get("sep", ",")) if a]
        if cell.get("count") == "samples" and len(names) != len(felt):
            return f"{noun} {text!r} names {len(names)} surfaces, the trial had {len(felt)}"
        values = _among(among, felt, design)
        bad = [a for a in names if values is not None and a not in values]
        if bad:
            return f"{noun} names {', '.join(bad)}, not among {', '.join(values)}"
        return ""
    values = _among(among, felt, design)
    if values is not None and text not in values:
        if among == "samples":
            return f"the {noun} {text!r} is not one of the samples felt ({', '.join(felt)})"
        return f"{noun} {text!r} is not one of {', '.join(values)}"
    return ""


def _among(among, felt: list[str], design: dict | None) -> list[str] | None:
    """The values a text or names cell may take (None: any)."""
    if among == "samples":
        return felt
    if among == "answer_choices":
        return list((design or {}).get("answer_choices") or []) or None
    if isinstance(among, list):
        return [str(a) for a in among]
    return None


def row_problem(row: dict, phase: dict | None, design: dict | None) -> str:
    """Why a recorded valid attempt cannot be analysed ('' when it can): the first cell of
    its phase's response that breaks its rule."""
    if row.get("status") != "valid":
        return ""
    for column, cell in response_columns(phase).items():
        why = cell_problem(str(row.get(column, "")), column, cell, row, design)
        if why:
            return why
    return ""


def column_meanings(phases: list[dict]) -> tuple[dict[str, tuple[str, str]], dict[str, dict]]:
    """What the response columns of the recorded phase designs ``phases`` hold, for a
    codebook or a sidecar: (column → (unit, meaning), column → value labels). A column that
    several responses fill with different meanings gets each in turn, by phase kind
    (``identification: …; comparison: …``)."""
    seen: dict[str, dict[str, tuple[str, str]]] = {}
    labels: dict[str, dict] = {}
    for phase in phases:
        for col, cell in response_columns(phase).items():
            seen.setdefault(col, {})[phase.get("kind") or phase.get("dv")] = (
                cell.get("unit", ""), cell.get("meaning", ""))
            if cell.get("labels"):
                labels.setdefault(col, {}).update(cell["labels"])
    out = {}
    for col, by_kind in seen.items():
        units = sorted({u for u, _ in by_kind.values()} - {""})
        meanings = list(dict.fromkeys(m for _, m in by_kind.values()))
        text = meanings[0] if len(meanings) == 1 else \
            "; ".join(f"{k}: {m}" for k, (_, m) in by_kind.items())
        out[col] = (" or ".join(units), text)
    return out, labels
