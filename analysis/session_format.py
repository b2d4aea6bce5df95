"""The session-file format: the one place that defines it, used by the recorder and the loader.

A session folder (``<data>/sub-<participant>/ses-<n>/``) holds:

``session.json``
    Metadata, one :class:`SessionRecord` (read and written by its fields, never by key),
    written atomically: format version, app version, the protocol (name, file, SHA-256 and
    the **design** derived from it, which alone holds the rating scale and the answer
    choices), the session kind and responder, seed, participant, device, times, status
    (:class:`SessionStatus`). :data:`META_REQUIRED` lists the keys a reader needs;
    :func:`read_meta` reads older formats through :func:`upgrade_meta`; keys it does not
    know are kept.
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

Size: just over 700 lines on purpose. DESIGN.md gives the session files one owner: the
record and its parts, the rows, their checks and the upgrade of every older format are read
together when the format changes, so they stay in this one module.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from collections.abc import Callable
from dataclasses import MISSING, dataclass, field, fields
from enum import StrEnum
from pathlib import Path
from typing import Any, ClassVar

__all__ = ["FORMAT_VERSION", "SessionStatus", "SessionRecord", "ProtocolRecord",
           "ParticipantRecord", "TimesRecord", "upgrade_meta", "COLUMNS", "OLDER_COLUMNS",
           "INT_COLUMNS",
           "FLOAT_COLUMNS", "KINDS", "META_REQUIRED",
           "TrialsFileError", "SessionMetaError", "TornLine", "header_line", "format_row",
           "format_cell",
           "read_trials", "read_trial_fields", "read_meta", "session_kind", "canonical_bytes",
           "is_canonical",
           "TRIALS", "META", "PROTOCOL_COPY", "TRACES", "LOCK", "ROW_STATUSES",
           "SessionPathError", "inside_session", "CAPABILITIES", "device_capabilities"]

#: 4: the device's capabilities are recorded (``device.simulated_contact``, ``seeded``,
#: ``virtual_time``: what it said it is, never inferred from its name); 3: the rating scale
#: and answer choices are written once, in the design (2 also wrote them beside it, as
#: protocol.rating and protocol.answer_choices); 2: the design and the session kind are
#: recorded
FORMAT_VERSION = 4

#: the capabilities a device states (:class:`device.DeviceInfo`), as session.json's
#: ``device`` records them since format 4
CAPABILITIES = ("simulated_contact", "seeded", "virtual_time")
#: the firmware texts of older files' simulated devices (format < 4, which recorded no
#: capabilities): the Python emulator, and the reference firmware's builds with the simulated
#: plant: host (host-F4: host-board; host-san), QEMU's stm32, and the bridges over the SDKs'
#: stand-ins (dhd-stub, cut to 16 bytes; hd-stub; hd-tsan). Each was seeded at its start.
_SIMULATED_FIRMWARE = re.compile(r"^(emulator|hlfw-[0-9.]+ (host|stm32|dhd-stu|hd-stub|hd-tsan))")
TRIALS, META, PROTOCOL_COPY, TRACES = "trials.tsv", "session.json", "protocol.toml", "traces"
LOCK = "session.lock"  #: held (flock) by the one process writing the session

COLUMNS = ("participant", "session", "phase", "trial_index", "item", "attempt", "sample",
           "block", "factors", "placement", "status", "n_taps", "tap_velocities", "peak_current",
           "rating", "response_time", "answer", "correct", "reason", "t_start", "t_end",
           "trace_file", "track", "intensity", "state")
#: the header before adaptive phases recorded their procedure (``track``, ``intensity``,
#: ``state``): read with those cells empty, and rewritten with them before a resume appends
OLDER_COLUMNS = COLUMNS[:-3]
INT_COLUMNS = ("session", "trial_index", "attempt", "n_taps")
FLOAT_COLUMNS = ("peak_current", "rating", "response_time", "correct", "intensity")

#: every status a row of trials.tsv may carry, as the recorder writes it (lower case): the
#: values of the engine's named statuses (:class:`protocols.TrialStatus`: an attempt's
#: outcomes, then the control entries — a pause, a resume, a reference block tapped), in
#: their order. analysis imports nothing of ours: a test holds the two equal.
ROW_STATUSES = ("valid", "saturated", "excluded_saturated", "requeued", "timed_out",
                "excluded_timeout", "aborted_device", "excluded_device", "skipped", "estop",
                "paused", "resumed", "reference")

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


class SessionPathError(ValueError):
    """A session's file would be read or written outside its folder: a symbolic link that
    leads out of it, or a name in trials.tsv that climbs out (``../``, an absolute path)."""


def inside_session(folder: str | Path, name: str | Path) -> Path:
    """``folder/name``, checked to stay in the session folder once every link is followed.

    A session folder's files are the session's own: a link inside the folder to another of
    its files is followed; one that leads out of it (or a name with ``..`` or an absolute
    path) is refused, so that nothing outside is read as the session's or written over.
    The folder itself may be reached through links (a data folder on another disk).

    Raises
    ------
    SessionPathError
        Naming the path, where it leads, and what to do.
    """
    folder = Path(folder)
    path = folder / name
    if isinstance(name, str) and name and "/" not in name and name not in (".", "..") \
            and not os.path.islink(path):
        return path  # a plain name in the folder that is no link: in it (one lstat)
    root = folder.resolve()
    real = path.resolve()
    if real == root or root in real.parents:
        return path
    rel = Path(name)
    if rel.is_absolute() or ".." in rel.parts:
        how = f"names {real}"
    else:
        steps = [folder.joinpath(*rel.parts[:i]) for i in range(1, len(rel.parts) + 1)]
        link = next((p for p in steps if p.is_symlink()), path)
        how = f"is a link to {real}" if link == path else \
            f"goes through the link {link} (to {link.resolve()})"
    raise SessionPathError(f"{path}: {how}, outside the session folder {folder}; a "
                           "session's files are its own and are read and written only "
                           "inside it — copy the file into the folder in place of the link "
                           "(nothing was read or written through it)")


@dataclass(frozen=True)
class TornLine:
    """An incomplete last line: its line number and raw text."""

    line: int
    text: str


def header_line() -> str:
    """The header of trials.tsv, with its newline."""
    return "\t".join(COLUMNS) + "\n"


def format_cell(column: str, v: Any) -> str:
    """The text trials.tsv records for value ``v`` of ``column`` ('' for None).

    Raises
    ------
    ValueError
        For a value holding a tab or line break.
    """
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
    return "\t".join(format_cell(c, row.get(c)) for c in COLUMNS) + "\n"


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
    return not raw.startswith(b"\xef\xbb\xbf") and b"\r" not in raw and (
        not raw or raw.startswith(header_line().encode()))


def _file_type(path: Path) -> str:
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
    rows, torn = read_trial_fields(path)
    return [dict(zip(COLUMNS, f, strict=True)) for f in rows], torn


#: where the checked columns are in a row's fields
_AT = {c: i for i, c in enumerate(COLUMNS)}


def read_trial_fields(path: str | Path, digests: dict | None = None
                      ) -> tuple[list[list[str]], TornLine | None]:
    """As :func:`read_trials`, each row as its fields in :data:`COLUMNS` order (what a
    reader of many sessions keeps: no dict per row); ``digests`` as :func:`read_meta`."""
    path = Path(path)
    try:
        inside_session(path.parent, path.name)
    except SessionPathError as exc:
        raise TrialsFileError(str(exc)) from None
    if not path.exists():
        return [], None
    if not path.is_file():  # a FIFO or a device would block the read for ever
        raise TrialsFileError(f"{path}: not a regular file ({_file_type(path)}); a session's "
                              "trials.tsv is a plain file — copy its contents into one")
    data = path.read_bytes()
    if digests is not None:
        digests[str(path)] = hashlib.sha256(data).hexdigest()
    raw = _text(data)
    if not raw:
        return [], None
    complete = raw.endswith("\n")
    lines = raw.split("\n")
    if complete:
        lines = lines[:-1]
    header = lines[0].split("\t")
    older = tuple(header) == OLDER_COLUMNS
    if tuple(header) != COLUMNS and not older:
        if len(lines) == 1 and not complete and header_line().startswith(lines[0]):
            return [], TornLine(1, lines[0])  # killed while writing the header
        unknown = [c for c in header if c not in COLUMNS]
        missing = [c for c in COLUMNS if c not in header]
        what = "; ".join(x for x in (f"missing {', '.join(missing)}" if missing else "",
                                     f"unknown {', '.join(unknown)}" if unknown else "") if x)
        raise TrialsFileError(f"{path}:1: not the trials.tsv header "
                              f"({what or 'columns in another order'})")
    rows: list[list[str]] = []
    torn = None
    # an older header (without the adaptive columns): its rows padded with their empty cells
    width = len(OLDER_COLUMNS) if older else len(COLUMNS)
    pad = [""] * (len(COLUMNS) - width)
    ti, at = _AT["trial_index"], _AT["attempt"]
    for no, line in enumerate(lines[1:], start=2):
        fields = line.split("\t")
        last = no == len(lines)
        ok = len(fields) == width and (complete or not last)
        if ok:
            try:
                int(fields[ti])
                int(fields[at])
            except ValueError:
                ok = False
        if not ok:
            if last:
                torn = TornLine(no, line)
                break
            raise TrialsFileError(f"{path}:{no}: corrupt line ({len(fields)} fields, expected "
                                  f"{width}): {line[:80]!r}")
        fields += pad
        _check_row(fields, path, no)
        rows.append(fields)
    return rows, torn


_STATUS_SET = frozenset(ROW_STATUSES)


def _check_row(fields: list[str], path: Path, no: int) -> None:
    """A complete row's status is one this format writes, and its whole-number columns are
    whole numbers (or empty): anything else is an edited file, named with its line."""
    status = fields[_AT["status"]]
    if status not in _STATUS_SET:
        canon = status.strip().lower()
        hint = (f"; the recorder writes {canon!r} (lower case, no spaces): an edit or a "
                "spreadsheet changed it — correct the file" if canon in ROW_STATUSES else "")
        raise TrialsFileError(f"{path}:{no}: status {status!r} is not one of "
                              f"{', '.join(ROW_STATUSES)}{hint}")
    for c in ("session", "n_taps"):
        v = fields[_AT[c]]
        if v and not (v.isascii() and v.isdigit()):
            raise TrialsFileError(f"{path}:{no}: {c} {v!r} is not a whole number")
    trace = fields[_AT["trace_file"]]
    if trace and (trace.startswith(("/", "\\")) or ".." in trace.replace("\\", "/").split("/")):
        raise TrialsFileError(f"{path}:{no}: trace_file {trace!r} names a file outside the "
                              f"session folder; the recorder writes {TRACES}/<name>")


def _get(meta: dict, dotted: str) -> Any:
    cur: Any = meta
    for part in dotted.split("."):
        if not isinstance(cur, dict) or part not in cur:
            raise KeyError(dotted)
        cur = cur[part]
    return cur


def _whole(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


#: what a field's value must be, in words, and the test of it
_TEXT = ("text", lambda v: isinstance(v, str))
_OBJECT = ("an object", lambda v: isinstance(v, dict))
_LIST = ("a list", lambda v: isinstance(v, list))
_WHOLE = ("a whole number", _whole)


@dataclass(kw_only=True)
class _Record:
    """A part of session.json with its own fields; keys this hapticlab does not know are
    kept in ``extra`` and written back as they came. A field whose value is None and whose
    name is in ``_OMIT`` is not written (it was not there), unless it came as null. A null
    where a field has a value of its own (an object, a list) reads as that value; a null
    where the field has none (the seed) is an error naming the key."""

    extra: dict = field(default_factory=dict)
    #: known keys that came as null and are written back so (the others' null is None)
    _nulls: set = field(default_factory=set, repr=False, compare=False)

    _CHECKS: ClassVar[dict[str, tuple[str, Callable[[Any], bool]]]] = {}
    _OMIT: ClassVar[tuple[str, ...]] = ()
    _PARTS: ClassVar[dict[str, type]] = {}

    @classmethod
    def _from(cls, d: Any, where: str, path: Path | str) -> Any:
        if not isinstance(d, dict):
            raise SessionMetaError(f"{path}: {where or 'the file'} is not an object")
        known = [f for f in fields(cls) if not f.name.startswith("_") and f.name != "extra"]
        kw: dict[str, Any] = {}
        nulls = set()
        for f in known:
            if f.name not in d:
                continue
            v = d[f.name]
            key = f"{where}.{f.name}" if where else f.name
            if v is None:  # a null where the field has a value of its own: that value
                if f.default is MISSING and f.default_factory is MISSING:
                    raise SessionMetaError(f"{path}: {key} is null; expected "
                                           f"{cls._CHECKS.get(f.name, ('a value',))[0]}")
                if f.default is None:
                    nulls.add(f.name)  # written back as it came
                    kw[f.name] = None
                continue
            if f.name in cls._PARTS:
                v = cls._PARTS[f.name]._from(v, key, path)
            elif f.name in cls._CHECKS:
                words, ok = cls._CHECKS[f.name]
                if not ok(v):
                    raise SessionMetaError(f"{path}: {key} is {v!r}; expected {words}")
            kw[f.name] = v
        names = {f.name for f in known}
        return cls(**kw, extra={k: v for k, v in d.items() if k not in names}, _nulls=nulls)

    def to_json(self) -> dict:
        """The JSON object of this part (statuses as their text)."""
        out = dict(self.extra)
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in ("extra", "_nulls") or (
                    v is None and f.name in self._OMIT and f.name not in self._nulls):
                continue
            out[f.name] = v.to_json() if isinstance(v, _Record) else v
        return out


@dataclass(kw_only=True)
class ProtocolRecord(_Record):
    """The protocol a session ran: its name, the file's SHA-256, where it came from, the
    copy's name in the folder, and the design derived from it (the one place of the
    rating scale and the answer choices)."""

    name: str
    sha256: str
    ref: str | None = None
    source: str | None = None
    copy: str | None = None
    design: dict | None = None

    _CHECKS = {"name": _TEXT, "sha256": _TEXT, "ref": _TEXT, "source": _TEXT, "copy": _TEXT,
               "design": _OBJECT}
    _OMIT = ("ref", "source", "copy", "design")

    @property
    def scale(self) -> dict:
        """The rating scale (``min``, ``max``, ``question``, ...); empty when none."""
        return dict((self.design or {}).get("scale") or {})


@dataclass(kw_only=True)
class ParticipantRecord(_Record):
    """Who took part: the ID, the counterbalancing row, the group, the details asked at the
    start (``info``) and the debrief's answer."""

    id: str
    counterbalance_row: int | None = None
    group: str = ""
    info: dict | None = None
    debrief: Any = None

    _CHECKS = {"counterbalance_row": _WHOLE, "group": _TEXT, "info": _OBJECT}
    _OMIT = ("info", "debrief")

    @classmethod
    def _from(cls, d: Any, where: str, path: Path | str) -> ParticipantRecord:
        rec = super()._from(d, where, path)
        if not isinstance(rec.id, (str, int)) or isinstance(rec.id, bool):
            raise SessionMetaError(f"{path}: {where}.id is {rec.id!r}; expected text")
        rec.id = str(rec.id)
        rec.group = rec.group or ""
        return rec


@dataclass(kw_only=True)
class TimesRecord(_Record):
    """When the session was created and finished (ISO 8601, UTC; None: not finished)."""

    created_utc: str | None = None
    finished_utc: str | None = None

    _CHECKS = {"created_utc": _TEXT, "finished_utc": _TEXT}


@dataclass(kw_only=True)
class SessionRecord(_Record):
    """session.json: what a session is, and how it stands. The recorder writes it
    (:meth:`to_json`), every reader reads it (:func:`read_meta`), older files through
    :func:`upgrade_meta`; keys it does not know are kept (``extra``).

    Attributes
    ----------
    protocol, participant, times : the parts above
    session : int
        The session's number for this participant (``ses-<n>``).
    seed : int
        The recorded seed every random draw of the session comes from.
    status : SessionStatus
    kind : str
        Who answered (:data:`KINDS`).
    device : dict
        The spec it was opened with (``spec``) and what the device said of itself.
    libraries : dict
        The transient libraries played, by sample (file and SHA-256).
    resumes, interruptions, notes, warnings : list
        Each resume (when, after how many attempts, on which device); why each run
        stopped early; the operator's notes; what the device could not do as asked.
    traces_mode : str or None
        ``full``, ``contacts`` or ``none`` (None: not recorded, before format 2).
    limits : dict or None
        The current limit applied and why.
    summary : str or None
        The words a complete session ended with.
    lsl : dict or None
        The markers' stream and each run of it.
    discrimination : dict or None
        A simulated participant's JNDs as measured (Weber fractions at 75 % correct by
        transient parameter) when it drew its own around them instead of the assumed ones
        (app.observer); None: the assumed ones.
    """

    protocol: ProtocolRecord
    participant: ParticipantRecord
    session: int
    seed: int
    status: SessionStatus
    kind: str = "dry-run"
    format_version: int = FORMAT_VERSION
    upgraded_from: int | None = None
    app: dict = field(default_factory=dict)
    libraries: dict = field(default_factory=dict)
    rng: str | None = None
    device: dict = field(default_factory=dict)
    ui: str | None = None
    responder: str | None = None
    audio: bool = False
    packages: dict | None = None
    python: str | None = None
    os: str | None = None
    times: TimesRecord = field(default_factory=TimesRecord)
    resumes: list = field(default_factory=list)
    timing: dict = field(default_factory=dict)
    link: dict = field(default_factory=dict)
    traces_mode: str | None = None
    limits: dict | None = None
    summary: str | None = None
    lsl: dict | None = None
    interruptions: list | None = None
    notes: list | None = None
    warnings: list | None = None
    discrimination: dict | None = None

    _CHECKS = {"session": _WHOLE, "seed": _WHOLE, "kind": ("one of " + ", ".join(KINDS),
                                                         lambda v: v in KINDS),
               "format_version": _WHOLE, "upgraded_from": _WHOLE, "app": _OBJECT,
               "libraries": _OBJECT, "rng": _TEXT, "device": _OBJECT, "ui": _TEXT,
               "responder": _TEXT, "audio": ("true or false", lambda v: isinstance(v, bool)),
               "packages": _OBJECT, "python": _TEXT, "os": _TEXT, "resumes": _LIST,
               "timing": _OBJECT, "link": _OBJECT, "traces_mode": _TEXT, "limits": _OBJECT,
               "summary": _TEXT, "lsl": _OBJECT, "interruptions": _LIST, "notes": _LIST,
               "warnings": _LIST, "discrimination": _OBJECT}
    _OMIT = ("upgraded_from", "rng", "ui", "responder", "packages", "python", "os",
             "traces_mode", "limits", "summary", "lsl", "interruptions", "notes", "warnings",
             "discrimination")
    _PARTS = {"protocol": ProtocolRecord, "participant": ParticipantRecord,
              "times": TimesRecord}

    @classmethod
    def from_json(cls, meta: dict, path: Path | str = META) -> SessionRecord:
        """The record of session.json's object ``meta`` in any format (upgraded).

        Raises
        ------
        SessionMetaError
            Naming the file and the key: a key every reader needs missing, a value of the
            wrong type, a status this format does not name, a newer format.
        """
        if not isinstance(meta, dict):
            raise SessionMetaError(f"{path}: expected a JSON object, got "
                                   f"{type(meta).__name__}")
        missing = []
        for key in META_REQUIRED:
            try:
                _get(meta, key)
            except KeyError:
                missing.append(key)
        if missing:
            raise SessionMetaError(f"{path}: missing key(s) {', '.join(missing)}")
        meta = upgrade_meta(meta, path)
        rec = cls._from({"kind": session_kind(meta), **meta}, "", path)
        try:
            rec.status = SessionStatus(rec.status)
        except ValueError:
            raise SessionMetaError(f"{path}: status is {rec.status!r}; expected one of "
                                   f"{', '.join(s.value for s in SessionStatus)}") from None
        return rec

    @property
    def device_spec(self) -> str:
        """The device spec the session was opened with (``serial:/dev/ttyACM0``)."""
        return str(self.device.get("spec") or "")

    @property
    def simulated_contact(self) -> bool:
        """Whether the session's device was simulated — nobody touched a physical surface
        (as the device said; for a file older than format 4, from what it recorded:
        :func:`device_capabilities`)."""
        return bool(self.device.get("simulated_contact"))

    def interrupted(self, why: str) -> None:
        """A run stopped early (``why``): resumed as any interruption."""
        self.status = SessionStatus.INTERRUPTED
        self.interruptions = [*(self.interruptions or []), why]

    def add_notes(self, notes: list[str]) -> None:
        """The operator's notes, after any earlier ones."""
        self.notes = [*(self.notes or []), *notes]

    def add_warnings(self, warnings: list[str]) -> None:
        """What the device could not do as asked, each once, after any earlier ones."""
        self.warnings = list(dict.fromkeys([*(self.warnings or []), *warnings]))


def read_meta(path: str | Path, digests: dict | None = None) -> SessionRecord:
    """session.json's record, checked and upgraded (:meth:`SessionRecord.from_json`);
    with ``digests``, the SHA-256 of the bytes read is put there under ``str(path)`` (a
    reader that records what it read need not read it twice).

    Raises
    ------
    SessionMetaError
        Naming the file and what is wrong (missing, not JSON, a missing key or a value of
        the wrong type).
    """
    path = Path(path)
    try:
        inside_session(path.parent, path.name)
    except SessionPathError as exc:
        raise SessionMetaError(str(exc)) from None
    if path.exists() and not path.is_file():
        raise SessionMetaError(f"{path}: not a regular file ({_file_type(path)})")
    try:
        raw = path.read_bytes()
        if digests is not None:
            digests[str(path)] = hashlib.sha256(raw).hexdigest()
        meta = json.loads(raw.decode("utf-8"))
    except FileNotFoundError:
        raise SessionMetaError(f"{path}: no session.json — not a session folder") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise SessionMetaError(f"{path}: not valid JSON ({exc})") from None
    return SessionRecord.from_json(meta, path)


def upgrade_meta(meta: dict, path: str | Path = "session.json") -> dict:
    """session.json of any format in this format's shape (the file is not changed).

    - format 1 (no ``format_version``, no ``kind``): the kind is inferred
      (:func:`session_kind`);
    - format 2: ``protocol.rating`` and ``protocol.answer_choices`` (written beside the
      design) are dropped where the design holds the same; a session with no design keeps
      none (nothing analyses it);
    - format 3 and older: the device's capabilities, which it did not record, are read from
      what it did (:func:`device_capabilities`).

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
    if isinstance(meta.get("device"), dict):
        meta["device"] = {**device_capabilities(meta["device"]), **meta["device"]}
    return meta


def device_capabilities(device: dict) -> dict[str, bool]:
    """The capabilities (:data:`CAPABILITIES`) of a device an older session file recorded
    (format < 4) from the facts it recorded: its backend and firmware texts. The simulated
    device (backend ``sim``) is simulated, seeded and in virtual time; the emulator and the
    firmware's builds with the simulated plant are simulated and seeded (in real time); any
    other device is taken as physical.

    A file of format 4 or later records them as the device said; this is for older files.
    """
    backend, firmware = str(device.get("backend") or ""), str(device.get("firmware") or "")
    virtual = backend == "sim"
    simulated = virtual or _SIMULATED_FIRMWARE.match(firmware) is not None
    return {"simulated_contact": simulated, "seeded": simulated, "virtual_time": virtual}


def session_kind(meta: dict) -> str:
    """The session's kind (:data:`KINDS`): recorded since format 2; inferred for older
    sessions from how they ran (a PsychoPy screen: a person)."""
    kind = meta.get("kind")
    if kind in KINDS:
        return kind
    if meta.get("ui") == "psychopy":
        return "human"
    return "simulated" if meta.get("responder") == "simulated" else "dry-run"
