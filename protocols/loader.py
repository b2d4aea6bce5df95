"""Load and validate protocol files.

Every problem raises :class:`ProtocolError` naming the file, the line, the field, the
offending value and what is allowed; nothing is half-loaded.

Size: just over 700 lines on purpose. One reader of one file format, its sections in the
order a protocol file has them, each checked with the same context (file, line, key) and
the same wording; the parts with a job of their own live beside it (the data it builds in
:mod:`.model`, the phase kinds in :mod:`.kinds`, the responses in :mod:`.responses`, the
texts in :mod:`.texts`).
"""

from __future__ import annotations

import dataclasses
import difflib
import hashlib
import itertools
import math
import re
import tomllib
from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Any

from device import DeviceInfo, LibraryTransient, Scene, SceneError
from device.errors import HapticlabError
from device.fileio import file_kind
from device.scene import AccelSinusoid, unknown_key

from ._adaptive_loader import ADAPTIVE_KEYS, adaptive_design, fit_options
from ._device_check import check_device
from ._toml_lines import key_lines, line_of
from .kinds import PROCEDURES, PhaseKind, phase_kind, phase_kinds
from .model import (
    ENTRIES,
    NORMALIZATIONS,
    REFERENCES,
    SCORINGS,
    SESSION_POLICIES,
    Answer,
    Attempts,
    Limits,
    Phase,
    PhaseDesign,
    Protocol,
    RatingScale,
    Sample,
    SaturationPolicy,
    Window,
)

__all__ = ["ProtocolError", "BUILTIN", "load_protocol", "parse_protocol", "protocol_text"]

BUILTIN = ("realism", "factorial", "identification", "comparison", "thresholds",
           "thresholds_quest")
_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
_MISSING = object()


class ProtocolError(HapticlabError, ValueError):
    """A protocol file is invalid.

    Attributes
    ----------
    source : str
        File name (or built-in name).
    line : int or None
        1-based line of the offending key, when known.
    field : str
        Dotted path of the field, e.g. ``phases[2].repetitions``.
    """

    def __init__(self, source: str, line: int | None, field: str, message: str):
        self.source, self.line, self.field = source, line, field
        where = f"{source}:{line}" if line else source
        super().__init__(f"{where}: {field}: {message}" if field else f"{where}: {message}")


def protocol_text(name_or_path: str | Path) -> tuple[str, str]:
    """Return (source name, text) of a built-in protocol name or a file path."""
    s = str(name_or_path)
    if s in BUILTIN:
        return f"{s}.toml", resources.files("protocols").joinpath(f"{s}.toml").read_text("utf-8")
    path = Path(s)
    kind = file_kind(path)
    if kind == "missing":
        hint = f"; built-in protocols: {', '.join(BUILTIN)}" if "/" not in s else ""
        raise ProtocolError(s, None, "", f"no such protocol file{hint}")
    if kind != "a regular file":  # a named pipe would block the read
        raise ProtocolError(s, None, "", f"not a regular file ({kind}); a protocol is a "
                                         ".toml text file")
    try:
        return str(path), path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ProtocolError(s, None, "", f"not a UTF-8 text file ({exc.reason})") from None
    except OSError as exc:
        raise ProtocolError(s, None, "", f"cannot be read ({exc.strerror})") from None


def load_protocol(name_or_path: str | Path, device: DeviceInfo | None = None) -> Protocol:
    """Load a built-in protocol (one of :data:`BUILTIN`, by name) or a protocol file.

    Parameters
    ----------
    name_or_path : str or path
    device : DeviceInfo, optional
        When given, the protocol's limits and each virtual sample's peak force at the
        design speed are checked against this device's rating.
    """
    source, text = protocol_text(name_or_path)
    return parse_protocol(text, source, device)


def _fmt_path(path: tuple) -> str:
    out = ""
    for p in path:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out


class _Ctx:
    def __init__(self, source: str, text: str):
        self.source = source
        self.lines = key_lines(text)

    def error(self, path: tuple, message: str) -> ProtocolError:
        return ProtocolError(self.source, line_of(self.lines, path), _fmt_path(path), message)

    def table(self, path: tuple, data: Any, allowed: set[str], required: set[str] = frozenset()
              ) -> Mapping[str, Any]:
        if not isinstance(data, Mapping):
            raise self.error(path, f"expected a table, got {data!r}")
        for key in data:
            if key not in allowed:
                raise self.error((*path, key), unknown_key(key, allowed))
        for key in sorted(required):
            if key not in data:
                raise self.error((*path, key), f"missing (required: "
                                 f"{', '.join(sorted(required))})")
        return data

    def number(self, path: tuple, value: Any, *, minimum: float | None = None,
               strict: bool = False, maximum: float | None = None,
               integer: bool = False) -> float:
        kind = "an integer" if integer else "a number"
        if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                (integer and not isinstance(value, int)):
            raise self.error(path, f"must be {kind}, got {value!r}")
        if not math.isfinite(value):
            raise self.error(path, f"must be finite, got {value!r}")
        if minimum is not None and (value <= minimum if strict else value < minimum):
            raise self.error(path, f"must be {'>' if strict else '>='} {minimum:g}, got {value!r}")
        if maximum is not None and value > maximum:
            raise self.error(path, f"must be <= {maximum:g}, got {value!r}")
        return value

    def string(self, path: tuple, value: Any, choices: tuple[str, ...] | None = None) -> str:
        if not isinstance(value, str) or not value.strip():
            raise self.error(path, f"must be a non-empty string, got {value!r}")
        if choices is not None and value not in choices:
            raise self.error(path, f"must be one of {', '.join(choices)}; got {value!r}")
        return value

    def boolean(self, path: tuple, value: Any) -> bool:
        if not isinstance(value, bool):
            raise self.error(path, f"must be true or false, got {value!r}")
        return value

    def ident(self, path: tuple, value: Any) -> str:
        s = self.string(path, value)
        if not _ID.match(s):
            raise self.error(path, f"must be letters, digits, '_', '-' or '.', got {s!r}")
        return s


_TOP = {"protocol", "window", "rating", "answer", "saturation", "operator", "limits", "display",
        "samples", "designs", "phases", "analysis", "attempts", "texts", "participant"}


def parse_protocol(text: str, source: str = "<protocol>", device: DeviceInfo | None = None
                   ) -> Protocol:
    """Parse and validate protocol TOML ``text`` (see :func:`load_protocol`)."""
    if not text.strip():
        raise ProtocolError(source, None, "", "the file is empty; a protocol needs at least "
                            "[protocol], samples and [[phases]]")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"line (\d+)", str(exc))
        raise ProtocolError(source, int(m.group(1)) if m else None, "",
                            f"not valid TOML: {exc}") from None
    except RecursionError:
        raise ProtocolError(source, None, "", "arrays or tables nested too deeply to read; a "
                            "protocol is a few levels deep") from None
    cx = _Ctx(source, text)
    cx.table((), data, _TOP, {"protocol", "phases"})
    head = cx.table(("protocol",), data["protocol"], {"name", "title", "description"}, {"name"})
    name = cx.ident(("protocol", "name"), head["name"])
    title = cx.string(("protocol", "title"), head.get("title", name))
    description = head.get("description", "")
    if not isinstance(description, str):
        raise cx.error(("protocol", "description"), "must be a string")

    window = _window(cx, data.get("window", {}))
    rating = _rating(cx, data["rating"]) if "rating" in data else None
    answer = _answer(cx, data["answer"]) if "answer" in data else None
    saturation = _saturation(cx, data.get("saturation", {}))
    attempts = _attempts(cx, data.get("attempts", {}))
    op = cx.table(("operator",), data.get("operator", {}), {"placeholders"})
    placeholders = tuple(op.get("placeholders", ()))
    for i, p in enumerate(placeholders):
        cx.string(("operator", "placeholders", i), p)
    if placeholders and (len(placeholders) < 2 or len(set(placeholders)) != len(placeholders)):
        raise cx.error(("operator", "placeholders"), "needs at least two distinct blocks so "
                       f"every virtual trial gets a physical swap, got {list(placeholders)}")
    limits = _limits(cx, data.get("limits", {}))
    disp = cx.table(("display",), data.get("display", {}), {"cursor"})
    cursor = cx.boolean(("display", "cursor"), disp.get("cursor", False))
    texts = _texts(cx, data.get("texts", {}))
    fields_ = _participant_fields(cx, data.get("participant", {}))
    ana = cx.table(("analysis",), data.get("analysis", {}), {"sessions"})
    sessions = cx.string(("analysis", "sessions"), ana.get("sessions", "first"),
                         SESSION_POLICIES)

    samples: dict[str, Sample] = {}
    for i, raw in enumerate(_array(cx, ("samples",), data.get("samples", []))):
        _add(cx, samples, _sample(cx, i, raw), ("samples", i, "id"))
    _link_libraries(cx, samples)
    _check_references(cx, samples)
    for i, raw in enumerate(_array(cx, ("designs",), data.get("designs", []))):
        for path, s in _design(cx, i, raw):
            _add(cx, samples, s, path)
    if not samples:
        raise cx.error((), "no samples: add [[samples]] or a [[designs]] table")

    phases = tuple(_phase(cx, i, raw, samples, answer, rating)
                   for i, raw in enumerate(_array(cx, ("phases",), data["phases"])))
    if not phases:
        raise cx.error(("phases",), "needs at least one phase")
    if rating is None and answer is None and not any(
            phase_kind(ph.kind).asks is not None for ph in phases):
        free = " or ".join(f"a {k.response} (kind = \"{k.name}\")"
                           for k in map(phase_kind, phase_kinds())
                           if k.asks is not None and k.needs is None)
        raise cx.error((), "a protocol needs a [rating] scale, an [answer] table or a "
                       f"phase that asks for {free}")
    names = [p.name for p in phases]
    for i, n in enumerate(names):
        if names.index(n) != i:
            raise cx.error(("phases", i, "name"), f"duplicate phase name {n!r}")
    for k in texts["instructions"]:
        if k not in names:
            raise cx.error(("texts", "instructions", k), f"no phase named {k!r}; phases: "
                           f"{', '.join(names)}")

    proto = Protocol(
        name=name, title=title, description=description.strip(), source=source,
        sha256=hashlib.sha256(text.encode("utf-8")).hexdigest(), samples=samples,
        phases=phases, window=window, rating=rating, answer=answer, saturation=saturation,
        placeholders=placeholders, limits=limits, cursor=cursor, sessions=sessions, text=text,
        attempts=attempts, texts=texts, participant_fields=fields_)
    if device is not None:
        check_device(cx, proto, device)
    return proto


def _array(cx: _Ctx, path: tuple, value: Any) -> list:
    if not isinstance(value, list):
        raise cx.error(path, f"expected an array of tables ([[{path[-1]}]]), got {value!r}")
    return value


def _add(cx: _Ctx, samples: dict, s: Sample, path: tuple) -> None:
    if s.id in samples:
        raise cx.error(path, f"duplicate sample id {s.id!r}")
    samples[s.id] = s


def _link_libraries(cx: _Ctx, samples: dict[str, Sample]) -> None:
    """Give each library transient the scene of the real sample it reproduces."""
    for i, (sid, s) in enumerate(list(samples.items())):
        tr = s.scene.transient
        if not isinstance(tr, LibraryTransient):
            continue
        src = samples.get(tr.source)
        if src is None or not src.is_real:
            real = [k for k, v in samples.items() if v.is_real]
            raise cx.error(("samples", i, "scene", "transient", "source"),
                           f"a library reproduces a real sample of this protocol; {tr.source!r} "
                           f"is {'not real' if src else 'unknown'} (real samples: "
                           f"{', '.join(real) or 'none'})")
        linked = dataclasses.replace(tr, source_scene=src.scene)
        samples[sid] = dataclasses.replace(s, scene=dataclasses.replace(s.scene, transient=linked))


#: the longest tapping window [s] and wait for the first contact [s] a protocol may ask:
#: the papers' windows last seconds; a full trace holds ~0.5 MB per second at 10 kHz, so
#: 10 minutes stays within a few hundred MB, and an hour's wait is a session gone wrong
MAX_WINDOW_S = 600.0
MAX_TIMEOUT_S = 3600.0


def _window(cx: _Ctx, raw: Any) -> Window:
    w = cx.table(("window",), raw, {"duration", "timeout"})
    return Window(
        duration=float(cx.number(("window", "duration"), w.get("duration", 5.0),
                                 minimum=0, strict=True, maximum=MAX_WINDOW_S)),
        timeout=float(cx.number(("window", "timeout"), w.get("timeout", 30.0),
                                minimum=0, strict=True, maximum=MAX_TIMEOUT_S)))


def _rating(cx: _Ctx, raw: Any) -> RatingScale:
    r = cx.table(("rating",), raw, {"min", "max", "question", "anchors", "entry"},
                 {"min", "max", "question"})
    lo = int(cx.number(("rating", "min"), r["min"], integer=True))
    hi = int(cx.number(("rating", "max"), r["max"], integer=True))
    if lo >= hi:
        raise cx.error(("rating", "max"), f"scale max must be greater than min ({lo}), got {hi}")
    if hi - lo > 1000 or max(abs(lo), abs(hi)) > 99_999:
        raise cx.error(("rating", "max"), f"a scale of {hi - lo + 1} points ({lo}–{hi}) is "
                       "not a rating scale; at most 1001 points of up to 5 digits")
    anchors: dict[int, str] = {}
    raw_anchors = r.get("anchors", {})
    if not isinstance(raw_anchors, Mapping):
        raise cx.error(("rating", "anchors"), "must be a table of \"value\" = \"text\"")
    for key, text in raw_anchors.items():
        try:
            k = int(key)
        except ValueError:
            raise cx.error(("rating", "anchors", key), "anchor keys must be scale values "
                           f"{lo}–{hi}, got {key!r}") from None
        if not lo <= k <= hi:
            raise cx.error(("rating", "anchors", key), f"anchor {k} is outside the scale {lo}–{hi}")
        anchors[k] = cx.string(("rating", "anchors", key), text)
    entry = cx.string(("rating", "entry"), r.get("entry", "auto"), ENTRIES)
    if entry == "keys" and not (0 <= lo and hi <= 9):
        raise cx.error(("rating", "entry"), f"one number key cannot enter {lo}–{hi}; use "
                       "\"typed\" (digits and ENTER) or \"slider\"")
    return RatingScale(lo, hi, cx.string(("rating", "question"), r["question"]), anchors,
                       entry)


def _answer(cx: _Ctx, raw: Any) -> Answer:
    a = cx.table(("answer",), raw, {"kind", "choices"}, {"kind", "choices"})
    kind = cx.string(("answer", "kind"), a["kind"], ("identify",))
    choices = a["choices"]
    if not isinstance(choices, list) or len(choices) < 2:
        raise cx.error(("answer", "choices"), f"needs at least two names, got {choices!r}")
    names = tuple(cx.ident(("answer", "choices", i), c) for i, c in enumerate(choices))
    if len({n.lower() for n in names}) != len(names):
        raise cx.error(("answer", "choices"), f"names must be distinct, got {list(names)}")
    if len(names) > 9:
        raise cx.error(("answer", "choices"), f"{len(names)} names cannot each have a number "
                       "key (1–9); at most 9")
    return Answer(kind, names)


def _saturation(cx: _Ctx, raw: Any) -> SaturationPolicy:
    s = cx.table(("saturation",), raw, {"action", "tone", "max_attempts"})
    cap = s.get("max_attempts", 3)
    if cap == "none":
        n = None  # the paper's redraw without a cap (the engine keeps a safety stop)
    else:
        if isinstance(cap, int) and not isinstance(cap, bool) and cap < 1:
            raise cx.error(("saturation", "max_attempts"), f"a redraw cap of {cap} would never "
                           "run the item; must be >= 1, or \"none\" for no cap")
        if isinstance(cap, str):
            raise cx.error(("saturation", "max_attempts"), f"must be an integer >= 1 or "
                           f"\"none\", got {cap!r}")
        n = int(cx.number(("saturation", "max_attempts"), cap, minimum=1, integer=True))
    return SaturationPolicy(
        action=cx.string(("saturation", "action"), s.get("action", "redraw"), ("redraw", "keep")),
        tone=cx.boolean(("saturation", "tone"), s.get("tone", True)), max_attempts=n)


def _attempts(cx: _Ctx, raw: Any) -> Attempts:
    a = cx.table(("attempts",), raw, {"max_timeouts", "max_device_failures"})
    return Attempts(**{k: int(cx.number(("attempts", k), a.get(k, 3), minimum=1, integer=True))
                       for k in ("max_timeouts", "max_device_failures")})


def _limits(cx: _Ctx, raw: Any) -> Limits:
    li = cx.table(("limits",), raw, {"max_current", "design_speed"})
    mc = li.get("max_current")
    return Limits(
        max_current=None if mc is None else float(
            cx.number(("limits", "max_current"), mc, minimum=0, strict=True)),
        design_speed=float(cx.number(("limits", "design_speed"), li.get("design_speed", 0.11),
                                     minimum=0, strict=True)))


def _scene(cx: _Ctx, path: tuple, name: str, raw: Any) -> Scene:
    if not isinstance(raw, Mapping):
        raise cx.error(path, f"expected a scene table, got {raw!r}")
    try:
        return Scene.from_dict({"name": name, **raw}, where="scene")
    except SceneError as exc:  # the loader names the place itself: file, line and key path
        raise cx.error((*path, *exc.part, *((exc.field,) if exc.field else ())),
                       exc.reason) from None


def _sample(cx: _Ctx, i: int, raw: Any) -> Sample:
    path = ("samples", i)
    s = cx.table(path, raw, {"id", "scene", "placement", "block", "factors", "reference",
                             "rated"}, {"id", "scene"})
    sid = cx.ident((*path, "id"), s["id"])
    scene = _scene(cx, (*path, "scene"), sid, s["scene"])
    placement = s.get("placement", sid if scene.is_real else None)
    if placement is not None:
        placement = cx.string((*path, "placement"), placement)
    block = cx.ident((*path, "block"), s["block"]) if "block" in s else None
    raw_f = s.get("factors", {})
    if not isinstance(raw_f, Mapping):
        raise cx.error((*path, "factors"), "must be a table of factor = \"level\", got "
                       f"{raw_f!r}")
    factors = {}
    for k, v in raw_f.items():
        if k == "sample" or not _ID.match(k):
            raise cx.error((*path, "factors", k), "a factor name is letters, digits, '_', '-' "
                           "or '.', and not 'sample' (the one-way factor)")
        factors[k] = cx.ident((*path, "factors", k), v)
    reference = cx.ident((*path, "reference"), s["reference"]) if "reference" in s else None
    rated = cx.boolean((*path, "rated"), s.get("rated", True))
    return Sample(id=sid, scene=scene, placement=placement, block=block, factors=factors,
                  reference=reference, rated=rated)


_FACTORS = ("frequency", "decay", "slope")


def _design(cx: _Ctx, i: int, raw: Any) -> list[tuple[tuple, Sample]]:
    path = ("designs", i)
    d = cx.table(path, raw, {"kind", "spring", "factors", "materials"},
                 {"kind", "spring", "factors", "materials"})
    cx.string((*path, "kind"), d["kind"], ("factorial",))
    spring = float(cx.number((*path, "spring"), d["spring"], minimum=0))
    factors = d["factors"]
    if not isinstance(factors, list) or sorted(factors) != sorted(_FACTORS):
        raise cx.error((*path, "factors"), f"a factorial design varies {', '.join(_FACTORS)}; "
                       f"got {factors!r}")
    out: list[tuple[tuple, Sample]] = []
    for j, m in enumerate(_array(cx, (*path, "materials"), d["materials"])):
        mp = (*path, "materials", j)
        m = cx.table(mp, m, {"id", "reference", *_FACTORS}, {"id", *_FACTORS})
        mid = cx.ident((*mp, "id"), m["id"])
        levels = {}
        for f in _FACTORS:
            pair = m[f]
            if not isinstance(pair, list) or len(pair) != 2:
                raise cx.error((*mp, f), f"needs two levels [a, b], got {pair!r}")
            a, b = (float(cx.number((*mp, f, k), v)) for k, v in enumerate(pair))
            if abs(a) == abs(b):
                raise cx.error((*mp, f), f"the two levels must differ, got {pair!r}")
            levels[f] = sorted((a, b), key=abs)  # low, high by magnitude
        ref_id = None
        if "reference" in m:
            ref_id = f"{mid}-real"
            ref_scene = _scene(cx, (*mp, "reference"), ref_id, {"material": m["reference"]})
            out.append(((*mp, "reference"), Sample(
                id=ref_id, scene=ref_scene, placement=f"real {mid} block", block=mid,
                rated=False)))
        for combo in itertools.product((0, 1), repeat=3):
            vals = {f: levels[f][c] for f, c in zip(_FACTORS, combo, strict=True)}
            code = "".join("LH"[c] for c in combo)
            try:
                tr = AccelSinusoid(slope=vals["slope"], decay=vals["decay"],
                                   frequency=vals["frequency"])
            except SceneError as exc:
                raise cx.error((*mp, exc.field) if exc.field else mp, exc.reason) from None
            sid = f"{mid}-{code}"
            out.append(((*mp, "id"), Sample(
                id=sid, scene=Scene(sid, spring=spring, transient=tr), block=mid,
                factors={f: ("low", "high")[c] for f, c in zip(_FACTORS, combo, strict=True)},
                params=vals, reference=ref_id)))
    return out


def _phase(cx: _Ctx, i: int, raw: Any, samples: Mapping[str, Sample], answer: Answer | None,
           rating: RatingScale | None) -> Phase:
    path = ("phases", i)
    p = cx.table(path, raw, {"name", "kind", "samples", "repetitions", "order", "blocks",
                             "block_order", "no_repeat", "analysis", "references",
                             *ADAPTIVE_KEYS},
                 {"name", "samples"})
    name = cx.ident((*path, "name"), p["name"])
    kind = phase_kind(cx.string((*path, "kind"), p.get("kind", phase_kinds()[0]),
                                phase_kinds()))
    sel = p["samples"]
    if sel == "all":
        ids = tuple(s.id for s in samples.values() if s.rated)
    elif isinstance(sel, list) and sel:
        ids = []
        for k, sid in enumerate(sel):
            if not isinstance(sid, str) or sid not in samples:
                hint = difflib.get_close_matches(str(sid), list(samples), n=1)
                raise cx.error((*path, "samples", k), f"unknown sample {sid!r}"
                               + (f"; did you mean '{hint[0]}'?" if hint else ""))
            ids.append(sid)
        ids = tuple(ids)
    else:
        raise cx.error((*path, "samples"), f"must be \"all\" or a list of sample ids, got {sel!r}")
    reps = int(cx.number((*path, "repetitions"), p.get("repetitions", 1), minimum=1,
                         integer=True))
    order = cx.string((*path, "order"), p.get("order", "random"), ("random", "fixed"))
    blocks = p.get("blocks")
    if blocks is not None:
        cx.string((*path, "blocks"), blocks, ("block",))
        missing = [s for s in ids if samples[s].block is None]
        if missing:
            raise cx.error((*path, "blocks"), f"samples {missing} belong to no block (a "
                           "factorial design's materials are blocks; [[samples]] take "
                           "block = \"name\")")
    block_order = cx.string((*path, "block_order"), p.get("block_order", "random"),
                            ("random", "fixed", "williams"))
    no_repeat = cx.boolean((*path, "no_repeat"), p.get("no_repeat", False))
    if no_repeat:
        _check_no_repeat(cx, (*path, "no_repeat"), kind, order, reps, ids,
                         [samples[s].block for s in ids] if blocks else [None] * len(ids))
    if kind.needs == "answer":
        if answer is None:
            raise cx.error((*path, "kind"), f"a{_an(kind.name)} {kind.name} phase needs an "
                           "[answer] table")
        if set(ids) != set(answer.choices):
            raise cx.error((*path, "samples"), f"the surfaces {sorted(ids)} must be the answer "
                           f"choices {sorted(answer.choices)}")
    elif kind.needs == "rating" and rating is None:
        raise cx.error((*path, "kind"), f"a{_an(kind.name)} {kind.name} phase needs a "
                       "[rating] scale")
    if kind.items == "pairs":
        if len(ids) < 2:
            raise cx.error((*path, "samples"), f"a{_an(kind.name)} {kind.name} phase pairs "
                           f"its samples: it needs two at least, got {list(ids)}")
        if blocks is not None:
            raise cx.error((*path, "blocks"), f"a{_an(kind.name)} {kind.name} phase's "
                           "trials are pairs, drawn across the phase: it has no blocks")
        real = [sid for sid in ids if samples[sid].is_real]
        if real:
            raise cx.error((*path, "samples"), f"{real}: a{_an(kind.name)} {kind.name} "
                           "phase compares renderings, felt one after the other on the same "
                           "block; a real sample cannot be swapped in between the two")
    adaptive, criterion = None, 0.75
    if kind.items == "adaptive":
        if blocks is not None:
            raise cx.error((*path, "blocks"), f"a {kind.name} phase interleaves its tracks "
                           "across the phase: it has no blocks")
        raw = p.get("analysis", {})
        crit = raw.get("criterion", 0.75) if isinstance(raw, Mapping) else 0.75
        adaptive = adaptive_design(cx, path, p, kind, ids, samples,
                                   crit if isinstance(crit, float) and 0.5 < crit < 1 else 0.75)
        criterion = adaptive.procedure.target if kind.procedure == "staircase" \
            else adaptive.procedure.criterion
    else:
        for key in ADAPTIVE_KEYS:
            if key in p:
                raise cx.error((*path, key), f"only an adaptive phase (kind "
                               f"{' or '.join(PROCEDURES)}) takes '{key}'")
    design = _phase_design(cx, (*path, "analysis"), p.get("analysis", {}), kind, ids, samples,
                           criterion)
    has_refs = any(samples[s].reference for s in ids) and kind.references
    default = kind.default_references if has_refs else "none"
    references = cx.string((*path, "references"), p.get("references", default), REFERENCES)
    if references != "none" and not has_refs:
        raise cx.error((*path, "references"), "none of the phase's samples has a 'reference' "
                       "(the real block to compare with)")
    return Phase(name=name, kind=kind.name, samples=ids, repetitions=reps, order=order,
                 blocks=blocks, block_order=block_order, no_repeat=no_repeat, design=design,
                 references=references, adaptive=adaptive)


def _an(word: str) -> str:
    return "n" if word[:1] in "aeiou" else ""


def _check_no_repeat(cx: _Ctx, path: tuple, kind: PhaseKind, order: str, reps: int,
                     ids: tuple[str, ...], blocks: list[str | None]) -> None:
    """``no_repeat`` needs a drawn order of one-sample trials and, in every block, a
    second sample to put between a sample's repetitions."""
    if kind.items != "each":
        raise cx.error(path, f"applies to phases of one sample a trial (a{_an(kind.name)} "
                       f"{kind.name} trial has {'every surface' if kind.surfaces else 'two'})")
    if order != "random":
        raise cx.error(path, "needs order = \"random\" (a fixed order is as written)")
    if reps > 1:
        for block in dict.fromkeys(blocks):
            members = [s for s, b in zip(ids, blocks, strict=True) if b == block]
            if len(members) == 1:
                where = f"block {block!r} has" if block is not None else "the phase has"
                raise cx.error(path, f"{where} one sample ({members[0]!r}) repeated {reps} "
                               "times: nothing can go between its repetitions")


def _check_references(cx: _Ctx, samples: dict[str, Sample]) -> None:
    for i, (sid, s) in enumerate(samples.items()):
        if s.reference is None:
            continue
        ref = samples.get(s.reference)
        if ref is None or not ref.is_real:
            raise cx.error(("samples", i, "reference"), f"sample {sid!r}: the reference must "
                           f"be a real sample of this protocol, got {s.reference!r}")


def _texts(cx: _Ctx, raw: Any) -> dict:
    from .texts import DEFAULT_TEXTS, resolve_texts

    t = cx.table(("texts",), raw, {*DEFAULT_TEXTS, "instructions"})
    over = {k: cx.string(("texts", k), v) for k, v in t.items() if k != "instructions"}
    ins = cx.table(("texts", "instructions"), t.get("instructions", {}),
                   set(t.get("instructions", {})) if isinstance(t.get("instructions"), Mapping)
                   else set())
    return resolve_texts(over, {k: cx.string(("texts", "instructions", k), v)
                                for k, v in ins.items()})


def _participant_fields(cx: _Ctx, raw: Any) -> dict:
    p = cx.table(("participant",), raw, {"fields"})
    fields_ = p.get("fields", {})
    if not isinstance(fields_, Mapping):
        raise cx.error(("participant", "fields"), "must be a table: name = \"default\" or "
                       "name = [\"choice\", …]")
    out = {}
    for k, v in fields_.items():
        if not _ID.match(k):
            raise cx.error(("participant", "fields", k), "a field name is letters, digits, "
                           "'_', '-' or '.'")
        if isinstance(v, list):
            if not v or not all(isinstance(c, str) and c for c in v):
                raise cx.error(("participant", "fields", k), "choices must be non-empty "
                               f"strings, got {v!r}")
        elif not isinstance(v, str):
            raise cx.error(("participant", "fields", k), f"must be a default text or a list of "
                           f"choices, got {v!r}")
        out[k] = v
    return out


def _phase_design(cx: _Ctx, path: tuple, raw: Any, kind: PhaseKind, ids: tuple[str, ...],
                  samples: Mapping[str, Sample], criterion: float = 0.75) -> PhaseDesign:
    """A phase's ``analysis`` table: what it measures and how it is analysed."""
    a = cx.table(path, raw, {"role", "within", "by", "normalize", "scoring", "criterion",
                             "function", "lapse_max"})
    asks = kind.asks
    if asks is None:
        if a:
            raise cx.error(path, f"a{_an(kind.name)} {kind.name} phase is not rated or "
                           "answered: nothing to analyse")
        return PhaseDesign(role="none", dv=kind.dv, within=(), scoring=None)
    role = cx.string((*path, "role"), a.get("role", "analysed"), ("analysed", "practice"))
    for key in a:
        if key != "role" and key not in asks.options:
            takes = ", ".join(f"'{o}'" for o in ("role", *asks.options))
            raise cx.error((*path, key), f"a{_an(kind.name)} {kind.name} phase is analysed "
                           f"{asks.analysed}; it takes {takes}")
    if "criterion" in asks.options:  # an adaptive phase: a psychometric fit per track
        return PhaseDesign(role=role, dv=kind.dv, within=(), scoring=None,
                           fit=fit_options(cx, path, a, criterion))
    if "scoring" in asks.options:
        scoring = cx.string((*path, "scoring"), a.get("scoring", "all_correct"), SCORINGS)
        return PhaseDesign(role=role, dv=kind.dv, within=(), scoring=scoring)
    if "within" not in asks.options:
        return PhaseDesign(role=role, dv=kind.dv, within=(), scoring=None)
    within = a.get("within", ["sample"])
    if not isinstance(within, list) or not within or not all(isinstance(w, str) for w in within):
        raise cx.error((*path, "within"), f"must be [\"sample\"] or a list of factor names, "
                       f"got {within!r}")
    if len(set(within)) != len(within):
        raise cx.error((*path, "within"), f"factors repeat: {within}")
    by = a.get("by")
    if by is not None:
        cx.string((*path, "by"), by, ("block",))
        missing = [s for s in ids if samples[s].block is None]
        if missing:
            raise cx.error((*path, "by"), f"samples {missing} belong to no block")
    normalize = cx.string((*path, "normalize"), a.get("normalize", "none"), NORMALIZATIONS)
    if within != ["sample"]:
        if "sample" in within:
            raise cx.error((*path, "within"), "'sample' is the one-way design on its own; "
                           "with other factors, list only the factors")
        if len(within) > 3:
            raise cx.error((*path, "within"), f"at most three within factors, got {within}")
        for sid in ids:
            lacking = [f for f in within if f not in samples[sid].factors]
            if lacking:
                raise cx.error((*path, "within"), f"sample {sid!r} has no level of "
                               f"{', '.join(lacking)} (give it factors = {{ ... }})")
        groups: dict = {}
        for sid in ids:
            groups.setdefault(samples[sid].block if by else None, []).append(sid)
        for block, members in groups.items():
            levels = [sorted({samples[s].factors[f] for s in members}) for f in within]
            combos = {tuple(samples[s].factors[f] for f in within) for s in members}
            where = f" in block {block!r}" if block else ""
            if any(len(lv) < 2 for lv in levels):
                one = [f for f, lv in zip(within, levels, strict=True) if len(lv) < 2]
                raise cx.error((*path, "within"), f"factor(s) {', '.join(one)} have a single "
                               f"level{where}: nothing to compare")
            if len(combos) != math.prod(len(lv) for lv in levels) or \
                    len(combos) != len(members):
                raise cx.error((*path, "within"), f"the samples{where} do not cross the "
                               f"factors {within} (each combination of levels exactly once): "
                               f"{len(members)} samples, {len(combos)} distinct combinations "
                               f"of {' × '.join(str(len(lv)) for lv in levels)}")
    elif by is not None:
        raise cx.error((*path, "by"), "'by' splits a factorial design; a one-way design over "
                       "samples compares every sample of the phase")
    return PhaseDesign(role=role, dv=kind.dv, within=tuple(within), by=by,
                       normalize=normalize)
