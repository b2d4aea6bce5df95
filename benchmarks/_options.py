"""The benchmarks' options: which benchmark reads each, and the check of every value.

A bad value is a named error (:class:`app.errors.UsageError`: the option, the value and what
it takes) before anything runs, and an option given to a benchmark that does not read it is
named too rather than silently dropped. What can only be checked once a benchmark has
measured something (a ``--points`` number beyond the write points a session has) is checked
there, as soon as it is known.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

__all__ = ["READ_BY", "LOAD_ONLY", "BOUNDARY_WORDS", "check_options", "parse_points"]

#: option → the benchmarks that read it (``json`` is read by every one)
READ_BY = {"repeats": ("accuracy", "analysis", "demo", "link", "scale", "sim"),
           "fuzz": ("link",), "kills": ("crash",), "points": ("crash",),
           "boundaries": ("crash",),
           "seeds": ("causes", "factorial", "orderings", "thresholds"),
           "sessions": ("thresholds",), "firmware": ("link",),
           "load": ("link",), "targets": ("link",), "seconds": ("link",),
           "baseline": ("link",), "no_window": ("link",), "rows": ("scale",)}
#: options of ``link`` that only its ``--load`` run reads
LOAD_ONLY = ("targets", "seconds", "baseline", "no_window")


def _error(text: str):
    from app.errors import UsageError

    return UsageError(text)


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def _whole(name: str, v: Any, least: int) -> None:
    if isinstance(v, bool) or not isinstance(v, int) or v < least:
        raise _error(f"{_flag(name)} {v!r}: a whole number >= {least}")


def _numbers(text: str) -> list[int] | None:
    """Comma-separated whole numbers >= 0, or None when ``text`` is not that."""
    parts = [p.strip() for p in str(text).split(",")]
    if not parts or not all(p.isascii() and p.isdigit() for p in parts):
        return None
    return [int(p) for p in parts]


def parse_points(text: str, n: int | None = None, flag: str = "--points",
                 item: str = "point", items: str = "write points",
                 each: str = "kills after each of them") -> list[int] | None:
    """``--points`` (``--boundaries`` with its own words): None for ``all``, else the
    numbers (1-based, each once, in the order given); with ``n``, each must be one of the
    session's ``n`` write points (rows).

    Raises
    ------
    UsageError
        Not ``all`` nor whole numbers >= 1; a number beyond ``n`` (naming how many there are).
    """
    if str(text).strip() == "all":
        return None
    points = _numbers(text)
    if points is None or not points or min(points) < 1:
        raise _error(f"{flag} {text!r}: all, or {item} numbers >= 1 separated by commas "
                     "(e.g. 3,17)")
    if n is not None:
        beyond = [p for p in points if p > n]
        if beyond:
            raise _error(f"{flag} {text}: {item} {beyond[0]} is beyond this session's {n} "
                         f"{items} (1..{n}); 'all' {each}")
    return list(dict.fromkeys(points))


#: :func:`parse_points`' words for ``--boundaries`` (bench crash: the rows cut after)
BOUNDARY_WORDS = {"flag": "--boundaries", "item": "row", "items": "rows a cut can follow",
                  "each": "cuts after each of them"}


def check_options(what: str, options: Mapping[str, Any], defaults: Mapping[str, Any]
                  ) -> dict[str, Any]:
    """Every option of ``bench what`` checked; returns the options with the defaults filled
    in.

    Parameters
    ----------
    what : str
        The benchmark.
    options : mapping
        The options given (a value equal to its default counts as not given).
    defaults : mapping
        Every option and its default (:data:`app.api.BENCH_OPTIONS`).

    Raises
    ------
    UsageError
        An unknown option, a bad value, or an option ``what`` does not read (naming the
        benchmarks that do).
    """
    from ._common import parse_seeds

    unknown = sorted(set(options) - set(defaults))
    if unknown:
        raise _error(f"benchmark option(s) {', '.join(unknown)} do not exist; the options: "
                     f"{', '.join(defaults)}")
    given = {k: v for k, v in options.items() if v != defaults[k]}
    for name in given:
        readers = READ_BY.get(name)
        if readers is not None and what not in readers:
            raise _error(f"bench {what} does not read {_flag(name)} ({', '.join(readers)} "
                         f"{'does' if len(readers) == 1 else 'do'})")
    if what == "link" and given.get("load") is None:
        stray = [n for n in LOAD_ONLY if n in given]
        if stray:
            raise _error(f"{_flag(stray[0])} is read only with --load (bench link --load "
                         "0,1,2 …)")
    opts = {**defaults, **options}
    _whole("repeats", opts["repeats"], 1)
    _whole("fuzz", opts["fuzz"], 0)
    _whole("kills", opts["kills"], 1)
    _whole("sessions", opts["sessions"], 1)
    if opts["points"] is not None:
        parse_points(opts["points"])
    if opts["boundaries"] is not None:
        parse_points(opts["boundaries"], **BOUNDARY_WORDS)
    chosen = [n for n in ("kills", "points", "boundaries") if n in given]
    if len(chosen) > 1:
        raise _error(f"{' and '.join(_flag(n) for n in chosen)} are different crash "
                     "benchmarks: give one")
    if opts["seeds"] is not None:
        parse_seeds(opts["seeds"], [])
    if opts["firmware"] not in (None, "host", "qemu"):
        raise _error(f"--firmware {opts['firmware']!r}: one of host, qemu")
    if opts["load"] is not None and not _numbers(opts["load"]):
        raise _error(f"--load {opts['load']!r}: competing processes as whole numbers >= 0 "
                     "separated by commas (e.g. 0,1,2,4)")
    if opts["targets"] is not None:
        from .link_load import TARGETS as LINK_TARGETS

        names = [t.strip() for t in str(opts["targets"]).split(",")]
        bad = [t for t in names if t not in LINK_TARGETS]
        if bad:
            raise _error(f"--targets {opts['targets']!r}: unknown {', '.join(bad)}; choose "
                         f"from {', '.join(LINK_TARGETS)}")
    s = opts["seconds"]
    if isinstance(s, bool) or not isinstance(s, (int, float)) or not math.isfinite(s) or s <= 0:
        shown = f"{s:g}" if isinstance(s, float) else repr(s)
        raise _error(f"--seconds {shown}: a number of seconds > 0")
    if opts.get("rows") is not None:
        from .scale import parse_rows

        parse_rows(opts["rows"])
    for name in ("json", "baseline", "no_window"):
        if not isinstance(opts[name], bool):
            raise _error(f"{_flag(name)} {opts[name]!r}: true or false")
    return opts
