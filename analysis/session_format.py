"""The session-file format: the one place that defines it, used by the recorder and the loader.

A session folder (``<data>/sub-<participant>/ses-<n>/``) holds:

``session.json``
    Metadata, written atomically: format version, app version, the protocol (name, file,
    SHA-256 and the **design** derived from it, which alone holds the rating scale and the
    answer choices), the session kind and responder, seed, participant, device, times,
    status (:class:`SessionStatus`). :data:`META_REQUIRED` lists the keys a reader needs;
    :func:`read_meta` reads older formats through :func:`upgrade_meta`.
``protocol.toml``
    The resolved protocol file the session ran, byte for byte (its SHA-256 is in
    session.json); resume uses this copy.
``trials.tsv``
    One row per attempt: tab-separated UTF-8, the header (:data:`COLUMNS`) first, each row
    written, flushed and fsynced before the next trial starts. A process killed mid-write
    leaves at most one torn last line, which :func:`read_trials` reports apart from the
    rows; a corrupt earlier line is a named error.
``traces/``
    Per attempt, the device's raw streams (compressed NumPy, written atomically).

Column types are in :data:`INT_COLUMNS` and :data:`FLOAT_COLUMNS` (empty means missing);
everything else is text.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Any

__all__ = ["FORMAT_VERSION", "SessionStatus", "upgrade_meta", "COLUMNS", "INT_COLUMNS",
           "FLOAT_COLUMNS", "KINDS", "META_REQUIRED",
           "TrialsFileError", "SessionMetaError", "TornLine", "header_line", "format_row",
           "read_trials", "read_meta", "session_kind", "canonical_bytes", "is_canonical",
           "TRIALS", "META", "PROTOCOL_COPY", "TRACES", "LOCK"]

#: 3: the rating scale and answer choices are written once, in the design (2 also wrote
#: them beside it, as protocol.rating and protocol.answer_choices); 2: the design and the
#: session kind are recorded
FORMAT_VERSION = 3
TRIALS, META, PROTOCOL_COPY, TRACES = "trials.tsv", "session.json", "protocol.toml", "traces"
LOCK = "session.lock"  #: held (flock) by the one process writing the session

COLUMNS = ("participant", "session", "phase", "trial_index", "item", "attempt", "sample",
           "block", "factors", "placement", "status", "n_taps", "tap_velocities", "peak_current",
           "rating", "response_time", "answer", "correct", "reason", "t_start", "t_end",
           "trace_file")
INT_COLUMNS = ("session", "trial_index", "attempt", "n_taps")
FLOAT_COLUMNS = ("peak_current", "rating", "response_time", "correct")

#: who answered: a person (``human``), a scripted responder testing the machinery
#: (``dry-run``), or the simulated participant model (``simulated``)
KINDS = ("human", "dry-run", "simulated")

class SessionStatus(StrEnum):
    """How a session stands (session.json ``status``); each value is the text written."""

    #: trials are being run, or the process stopped without a word (killed, power lost):
    #: ``hapticlab resume`` continues it
    RUNNING = "running"
    #: every trial the engine planned has its row
    COMPLETE = "complete"
    #: stopped early on purpose or by a fault (the operator's abort, a device error, no
    #: LSL recorder, Ctrl-C): ``hapticlab resume`` continues it
    INTERRUPTED = "interrupted"
    #: a run that Ctrl-C or a termination signal ended: the run's result says so (exit
    #: status 130); session.json records it as ``interrupted``, resumed the same way
    STOPPED = "stopped"


#: dotted keys of session.json that every reader relies on
META_REQUIRED = ("protocol.name", "protocol.sha256", "seed", "participant.id", "session",
                 "status")


class TrialsFileError(ValueError):
    """trials.tsv cannot be read: a missing or wrong header, or a corrupt line before the last
    (named by file and line number)."""


class SessionMetaError(ValueError):
    """session.json is missing, not JSON, or lacks a key every reader needs (named)."""


@dataclass(frozen=True)
class TornLine:
    """An incomplete last line: its line number and raw text."""

    line: int
    text: str


def header_line() -> str:
    """The header of trials.tsv, with its newline."""
    return "\t".join(COLUMNS) + "\n"


def _cell(column: str, v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.6g}"
    s = str(v)
    if any(c in s for c in "\t\n\r"):
        raise ValueError(f"trials.tsv column {column!r}: a tab or line break cannot be "
                         f"recorded: {s!r}")
    return s


def format_row(row: dict) -> str:
    """One trials.tsv line (with its newline) for ``row`` (column → value; missing: empty).

    Raises
    ------
    ValueError
        For an unknown column, or a value holding a tab or line break.
    """
    unknown = set(row) - set(COLUMNS)
    if unknown:
        raise ValueError(f"unknown trials.tsv columns: {sorted(unknown)}")
    return "\t".join(_cell(c, row.get(c)) for c in COLUMNS) + "\n"


def _text(raw: bytes) -> str:
    """trials.tsv's text with any line ending (LF, CRLF, a spreadsheet's lone CR) as LF and
    without a UTF-8 byte-order mark."""
    text = raw.decode("utf-8", errors="replace")
    if text.startswith("\ufeff"):
        text = text[1:]
    return text.replace("\r\n", "\n").replace("\r", "\n")


def canonical_bytes(rows: list[dict]) -> bytes:
    """trials.tsv as this format writes it: the header and ``rows``, LF endings, no BOM."""
    return (header_line() + "".join(format_row(r) for r in rows)).encode("utf-8")


def is_canonical(path: str | Path) -> bool:
    """True when the file is byte for byte what :func:`canonical_bytes` writes (or absent)."""
    path = Path(path)
    if not path.exists():
        return True
    raw = path.read_bytes()
    return not raw.startswith(b"\xef\xbb\xbf") and b"\r" not in raw


def _kind(path: Path) -> str:
    """What kind of file ``path`` is, in words (for an error message)."""
    import stat

    mode = path.stat().st_mode
    for test, name in ((stat.S_ISFIFO, "a named pipe"), (stat.S_ISDIR, "a directory"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def read_trials(path: str | Path) -> tuple[list[dict], TornLine | None]:
    """Rows of trials.tsv (dicts of text), and a torn last line if the writer was killed
    mid-line.

    Any line ending (LF, CRLF, CR) and a UTF-8 byte-order mark are accepted (a file opened and
    saved by a spreadsheet); :func:`canonical_bytes` is what a writer puts back. A header
    alone, or an empty file, means no rows.

    Raises
    ------
    TrialsFileError
        For a wrong header, or a malformed line that is not the last.
    """
    path = Path(path)
    if not path.exists():
        return [], None
    if not path.is_file():  # a FIFO or a device would block the read for ever
        raise TrialsFileError(f"{path}: not a regular file ({_kind(path)}); a session's "
                              "trials.tsv is a plain file — copy its contents into one")
    raw = _text(path.read_bytes())
    if not raw:
        return [], None
    complete = raw.endswith("\n")
    lines = raw.split("\n")
    if complete:
        lines = lines[:-1]
    header = lines[0].split("\t")
    if tuple(header) != COLUMNS:
        if len(lines) == 1 and not complete and header_line().startswith(lines[0]):
            return [], TornLine(1, lines[0])  # killed while writing the header
        unknown = [c for c in header if c not in COLUMNS]
        missing = [c for c in COLUMNS if c not in header]
        what = "; ".join(x for x in (f"missing {', '.join(missing)}" if missing else "",
                                     f"unknown {', '.join(unknown)}" if unknown else "") if x)
        raise TrialsFileError(f"{path}:1: not the trials.tsv header "
                              f"({what or 'columns in another order'})")
    rows: list[dict] = []
    torn = None
    for no, line in enumerate(lines[1:], start=2):
        fields = line.split("\t")
        last = no == len(lines)
        ok = len(fields) == len(COLUMNS) and (complete or not last)
        if ok:
            row = dict(zip(COLUMNS, fields, strict=True))
            try:
                int(row["trial_index"])
                int(row["attempt"])
            except ValueError:
                ok = False
        if not ok:
            if last:
                torn = TornLine(no, line)
                break
            raise TrialsFileError(f"{path}:{no}: corrupt line ({len(fields)} fields, expected "
                                  f"{len(COLUMNS)}): {line[:80]!r}")
        rows.append(row)
    return rows, torn


def _get(meta: dict, dotted: str) -> Any:
    cur: Any = meta
    for part in dotted.split("."):
        if not isinstance(cur, dict) or part not in cur:
            raise KeyError(dotted)
        cur = cur[part]
    return cur


def read_meta(path: str | Path) -> dict:
    """session.json as a dict, checked for :data:`META_REQUIRED`.

    Raises
    ------
    SessionMetaError
        Naming the file and what is wrong (missing, not JSON, a missing key).
    """
    path = Path(path)
    if path.exists() and not path.is_file():
        raise SessionMetaError(f"{path}: not a regular file ({_kind(path)})")
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise SessionMetaError(f"{path}: no session.json — not a session folder") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise SessionMetaError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(meta, dict):
        raise SessionMetaError(f"{path}: expected a JSON object, got {type(meta).__name__}")
    missing = []
    for key in META_REQUIRED:
        try:
            _get(meta, key)
        except KeyError:
            missing.append(key)
    if missing:
        raise SessionMetaError(f"{path}: missing key(s) {', '.join(missing)}")
    return upgrade_meta(meta, path)


def upgrade_meta(meta: dict, path: str | Path = "session.json") -> dict:
    """session.json of any format in this format's shape (the file is not changed).

    - format 1 (no ``format_version``, no ``kind``): the kind is inferred
      (:func:`session_kind`);
    - format 2: ``protocol.rating`` and ``protocol.answer_choices`` (written beside the
      design) are dropped where the design holds the same; a session with no design keeps
      none (nothing analyses it).

    ``upgraded_from`` names the format the file is in when it is older.

    Raises
    ------
    SessionMetaError
        When a format-2 file's two copies of the scale or the choices disagree (an edited
        file: which one the session ran cannot be told), naming both.
    """
    version = meta.get("format_version", 1)
    if not isinstance(version, int) or version > FORMAT_VERSION:
        raise SessionMetaError(f"{path}: format_version {version!r} is newer than this "
                               f"hapticlab reads ({FORMAT_VERSION}); update hapticlab")
    if version == FORMAT_VERSION:
        return meta
    meta = {**meta, "kind": session_kind(meta), "format_version": FORMAT_VERSION,
            "upgraded_from": version}
    proto = dict(meta["protocol"])
    design = proto.get("design")
    for old, new in (("rating", "scale"), ("answer_choices", "answer_choices")):
        if old not in proto:
            continue
        value = proto.pop(old)
        if isinstance(design, dict) and value is not None:
            held = design.get(new)
            same = held == value if old == "answer_choices" else (
                isinstance(held, dict) and all(held.get(k) == v for k, v in value.items()))
            if not same:
                raise SessionMetaError(f"{path}: protocol.{old} {value!r} disagrees with the "
                                       f"design's {new} {held!r}; correct one of them")
    meta["protocol"] = proto
    return meta


def session_kind(meta: dict) -> str:
    """The session's kind (:data:`KINDS`): recorded since format 2; inferred for older
    sessions from how they ran (a PsychoPy screen: a person)."""
    kind = meta.get("kind")
    if kind in KINDS:
        return kind
    if meta.get("ui") == "psychopy":
        return "human"
    return "simulated" if meta.get("responder") == "simulated" else "dry-run"
