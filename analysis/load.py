"""Reading session folders into one long table, and choosing which sessions to analyse.

No I/O at import; reads only files. The format is :mod:`analysis.session_format`'s.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd

from ._kept import kept
from .cells import response_columns, row_problem
from .session_format import (
    COLUMNS,
    FLOAT_COLUMNS,
    INT_COLUMNS,
    KINDS,
    META,
    TRACES,
    TRIALS,
    SessionMetaError,
    SessionPathError,
    SessionRecord,
    SessionStatus,
    TrialsFileError,
    inside_session,
    read_meta,
    read_trial_fields,
)

__all__ = ["load_sessions", "select_sessions", "LoadError", "tap_velocities", "SESSION_COLUMNS",
           "DEVICE_COLUMNS"]

#: what a session recorded of the device it ran on (also a column of every row)
DEVICE_COLUMNS = ("device_backend", "device_id", "firmware", "simulated_plant",
                  "libraries")
#: firmware builds that serve the wire protocol with a simulated plant (nobody touches a
#: physical surface): the Python emulator and the reference firmware's host and QEMU builds
#: columns of ``load_sessions(...).attrs["session_table"]``, one row per session folder
SESSION_COLUMNS = ("session_dir", "participant", "session", "protocol", "protocol_sha256",
                   "kind", "responder", "status", "created_utc", "seed", "rows", "valid_rows",
                   "design_key", "folder_participant", *DEVICE_COLUMNS, "identity",
                   "identity_of", "rows_participant")
#: how a participant id that the folder name and the recorded session disagree on is taken
IDS = ("check", "record", "folder", "rows")


class LoadError(ValueError):
    """A session folder cannot be read (named by path and line), or no session was found."""


#: designs already keyed, by protocol SHA-256: [(design, key)] (sessions of one protocol
#: record equal designs; comparing dicts is cheaper than hashing their JSON again)
_KEYED: dict[str, list[tuple[dict, str]]] = {}


def _design_key(design: dict | None) -> str:
    if not design:
        return ""
    known = _KEYED.setdefault(str(design.get("sha256")), [])
    for d, k in known:
        if d == design:
            return k
    key = _hash_design(design)
    if len(known) < 8:
        known.append((design, key))
    return key


def _hash_design(design: dict) -> str:
    import json

    body = {k: v for k, v in design.items() if k not in ("sha256", "title")}
    if isinstance(body.get("phases"), list):  # a response's record follows from its kind
        body["phases"] = [{kk: vv for kk, vv in ph.items() if kk != "response"}
                          if isinstance(ph, dict) else ph for ph in body["phases"]]
    if isinstance(body.get("samples"), dict):  # physical values: recorded, not the design
        body["samples"] = {k: {kk: vv for kk, vv in v.items() if kk != "params"}
                           if isinstance(v, dict) else v for k, v in body["samples"].items()}
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()[:12]


def _device(meta: SessionRecord) -> dict[str, str]:
    """What a session recorded of its device: backend, model and serial number, firmware,
    whether the device was simulated (1: it said its contact was simulated — the simulated
    device, the emulator, a firmware build with its simulated plant, a bridge over an SDK's
    stand-in: nobody touched a physical surface; :attr:`SessionRecord.simulated_contact`),
    and the transient libraries it played (sample=sha256, first 12 hex digits)."""
    d = meta.device
    model, serial = str(d.get("model") or ""), str(d.get("serial_number") or "")
    libs = meta.libraries
    backend, firmware = str(d.get("backend") or ""), str(d.get("firmware") or "")
    return {"device_backend": backend,
            "device_id": " ".join(x for x in (model, serial and f"#{serial}") if x),
            "firmware": firmware,
            "simulated_plant": int(meta.simulated_contact),
            "libraries": ";".join(f"{sid}={str((lib or {}).get('sha256', ''))[:12]}"
                                  for sid, lib in sorted(libs.items()))}


def _folder_id(folder: Path) -> str:
    """The participant id a session folder's path names (``sub-<id>/ses-<n>``), or ''."""
    for part in (folder.parent.name, folder.name):
        if part.startswith("sub-"):
            return part[4:]
    return ""


def _invalid(row: list[str], phase: dict | None, design: dict | None) -> str:
    """Why a recorded valid attempt cannot be analysed ('' when it can): by the rules its
    phase's response recorded (:mod:`analysis.cells`); ``row`` is its fields."""
    if row[_STATUS] != "valid":
        return ""
    return row_problem(dict(zip(COLUMNS, row, strict=True)), phase, design)


def session_files(root: Path) -> list[Path]:
    """Every ``session.json`` under ``root``, in path order, at any depth.

    A link to a folder outside ``root`` is followed (sessions kept on another disk); a link
    to a folder inside it is an alias of a folder read anyway and is not read twice, nor is
    any folder reached again through a loop of links. A session's ``traces/`` is not
    searched (it holds recordings, never sessions).
    """
    root = Path(root)
    top = root.resolve()
    seen: set[str] = set()
    found: list[Path] = []

    def walk(folder: Path, real: Path) -> None:
        if str(real) in seen:
            return
        seen.add(str(real))
        try:
            entries = sorted(os.scandir(folder), key=lambda e: e.name)
        except OSError as exc:
            raise LoadError(f"{folder}: cannot be read ({exc.strerror})") from None
        names = {e.name for e in entries}
        if META in names:
            found.append(folder / META)
        for e in entries:
            if not e.is_dir() or (e.name == TRACES and META in names):
                continue
            if not e.is_symlink():
                walk(folder / e.name, real / e.name)
                continue
            target = Path(os.path.realpath(e.path))
            if target == top or top in target.parents:
                continue  # an alias of a folder inside root: read there
            walk(folder / e.name, target)

    walk(root, top)
    return sorted(found)


def load_sessions(path: str | Path, drop_invalid: bool = False,
                  progress: Callable[[int, int], None] | None = None) -> pd.DataFrame:
    """All attempts of all sessions under ``path``, one row per attempt.

    Parameters
    ----------
    path : str or Path
        A folder holding ``sub-*/ses-*`` session folders at any depth.
    drop_invalid : bool
        A valid attempt that cannot be analysed (a rating off the recorded scale, not a
        number or not finite; an answer that names the wrong surfaces) is an error naming its
        file and line (default); True marks such rows not valid instead, with their reason
        in ``invalid_reason`` and in ``attrs["invalid_rows"]``.
    progress : callable (done, total), optional
        Called after each session folder is read.

    Returns
    -------
    DataFrame
        The trials.tsv columns, typed (``trial_index``, ``attempt``, ``n_taps``,
        ``session`` int; ``rating``, ``response_time``, ``peak_current``, ``correct`` float,
        NaN when empty), plus ``valid`` (status is valid), ``repetition`` (from the item
        key), one column per factor a sample carries (e.g. ``frequency`` = low/high), and
        from session.json: ``protocol``, ``protocol_sha256``, ``design_key`` (sessions
        with the same design share it), ``seed``, ``group``, ``scale`` ("min-max"),
        ``kind`` (human, dry-run or simulated), ``responder``, ``device_backend``,
        ``session_status``, ``session_dir``.

        ``result.attrs``: ``session_table`` (DataFrame, one row per session folder, columns
        :data:`SESSION_COLUMNS`; ``identity`` names the first row whose participant,
        session or protocol disagrees with session.json, '' when none does), ``designs``
        (design key → the design recorded with the sessions), ``torn`` (torn last lines,
        by file), ``files`` (SHA-256 of every file read), ``sessions`` (count),
        ``invalid_rows`` (list of dicts: ``file``, ``line``, ``participant``, ``phase``,
        ``sample``, ``reason``).

    Raises
    ------
    LoadError
        No folder, no session, or a session file that cannot be read (named).

    Examples
    --------
    >>> import analysis as A
    >>> d = A.load_sessions(A.datasets.sessions_path())
    >>> d.attrs["sessions"], sorted(d["participant"].unique())
    (3, ['P01', 'P02', 'P03'])
    >>> print(d.attrs["session_table"][["participant", "kind", "status"]].to_string(index=False))
    participant      kind   status
            P01 simulated complete
            P02 simulated complete
            P03 simulated complete
    """
    root = Path(path)
    if not root.exists():
        raise LoadError(f"{root}: no such folder")
    if not root.is_dir():
        raise LoadError(f"{root}: not a folder")
    found = session_files(root)
    if not found:
        raise LoadError(f"{root}: no sessions (sub-*/ses-*/session.json) found")
    torn, files, sessions, designs, invalid = {}, {}, [], {}, []
    chunks: list[pd.DataFrame] = []  # rows as frames of ~50,000: no dict per row is kept
    pending: list[list[str]] = []
    reasons: list[str] = []
    counts: list[int] = []  # rows per session, in order
    checked: dict[str, dict[tuple, str]] = {}  # design key → cells → why not analysable
    spots: dict[tuple[str, str], tuple[int, ...]] = {}  # (design key, phase) → columns
    for n, mpath in enumerate(found, start=1):
        folder = mpath.parent
        digests: dict[str, str] = {}  # the SHA-256 of every file read, as it was read
        try:
            meta = read_meta(mpath, digests)
        except SessionMetaError as exc:
            raise LoadError(str(exc)) from None
        tpath = folder / TRIALS
        try:
            rows, t = read_trial_fields(tpath, digests)
            inside_session(folder, TRACES)  # the recordings too are the session's own
        except (TrialsFileError, SessionPathError) as exc:
            raise LoadError(str(exc)) from None
        if t is not None:
            torn[str(tpath)] = t.text
        for f in (mpath, tpath):
            if str(f) in digests:
                files[str(f.relative_to(root))] = digests[str(f)]
        proto = meta.protocol
        design = proto.design
        key = _design_key(design)
        if key:
            designs.setdefault(key, design)
        status = str(meta.status)
        sessions.append({
            "session_dir": str(folder), "participant": meta.participant.id,
            "session": meta.session, "protocol": proto.name,
            "protocol_sha256": proto.sha256, "kind": meta.kind,
            "responder": meta.responder or "", "status": status,
            "created_utc": meta.times.created_utc or "",
            "seed": meta.seed, "rows": len(rows),
            "valid_rows": sum(r[_STATUS] == "valid" for r in rows), "design_key": key,
            "folder_participant": _folder_id(folder), **_device(meta),
            **_identity(meta, rows, tpath), "group": meta.participant.group,
            "scale": (f"{proto.scale['min']}-{proto.scale['max']}" if proto.scale else "")})
        counts.append(len(rows))
        phases = {p["name"]: p for p in (design or {}).get("phases", [])}
        seen = checked.setdefault(key, {})  # the same cells in the same design: one verdict
        for line, r in enumerate(rows, start=2):
            if r[_STATUS] != "valid":
                reasons.append("")
                continue
            spot = spots.get((key, r[_PHASE]))
            if spot is None:  # where this phase's response is written
                spot = spots[key, r[_PHASE]] = tuple(
                    COLUMNS.index(c) for c in response_columns(phases.get(r[_PHASE]))
                    if c in COLUMNS)
            cells = (r[_PHASE], r[_SAMPLE], *(r[i] for i in spot))
            why = seen.get(cells)
            if why is None:
                why = seen[cells] = _invalid(r, phases.get(r[_PHASE]), design)
            reasons.append(why)
            if why:
                invalid.append({"file": str(tpath), "line": line, "participant": r[_PID],
                                "phase": r[_PHASE], "sample": r[_SAMPLE], "reason": why})
        pending += rows
        if len(pending) >= 50_000:
            chunks.append(pd.DataFrame(pending, columns=list(COLUMNS)))
            pending = []
        if progress is not None:
            progress(n, len(found))
    if invalid and not drop_invalid:
        first = invalid[0]
        more = f" (and {len(invalid) - 1} more row(s))" if len(invalid) > 1 else ""
        raise LoadError(f"{first['file']}:{first['line']}: {first['reason']}{more}; correct "
                        "the file, or analyse with --drop-invalid to leave such rows out "
                        "(each is then listed in the report)")
    chunks.append(pd.DataFrame(pending, columns=list(COLUMNS)))
    full = pd.DataFrame(sessions)
    table = full[list(SESSION_COLUMNS)].copy()
    data = pd.concat(chunks, ignore_index=True) if len(chunks) > 1 else chunks[0]
    data["invalid_reason"] = pd.array(reasons, dtype="str")
    # what each session recorded once, on every one of its rows
    at = np.repeat(np.arange(len(full)), counts)
    full["responder"] = np.where(full["kind"] == "human", "person", full["responder"])
    for c, src in (("protocol", "protocol"), ("protocol_sha256", "protocol_sha256"),
                   ("design_key", "design_key"), ("seed", "seed"), ("group", "group"),
                   ("scale", "scale"), *((c, c) for c in DEVICE_COLUMNS), ("kind", "kind"),
                   ("responder", "responder"), ("session_status", "status"),
                   ("session_dir", "session_dir")):
        data[c] = full[src].to_numpy()[at]
    for c in INT_COLUMNS:
        data[c] = pd.to_numeric(data[c], errors="coerce").fillna(0).astype(int)
    for c in FLOAT_COLUMNS:
        data[c] = pd.to_numeric(data[c].replace("", np.nan), errors="coerce")
    data["valid"] = (data["status"] == "valid") & (data["invalid_reason"] == "")
    rep = data["item"].astype(str).str.extract(r"#(\d+)$")[0]
    data["repetition"] = pd.to_numeric(rep, errors="coerce").fillna(0).astype(int)
    codes, texts = pd.factorize(data["factors"].fillna(""))  # a few distinct strings
    parsed = [dict(kv.split("=", 1) for kv in str(s).split(";") if "=" in kv) for s in texts]
    for name in sorted({k for d in parsed for k in d}):
        levels = np.array([d.get(name, "") for d in parsed] + [""], dtype=object)
        data[name] = pd.array(levels[codes], dtype="str")  # code -1 (none): ''
    data.attrs.update({k: kept(v) for k, v in (  # shared by every frame made from data
        ("session_table", table), ("designs", designs), ("torn", torn), ("files", files),
        ("sessions", len(table)), ("invalid_rows", invalid))})
    return data


_PID, _SES, _PHASE, _SAMPLE, _STATUS = (COLUMNS.index(c) for c in (
    "participant", "session", "phase", "sample", "status"))


def _identity(meta: SessionRecord, rows: list[list[str]], path: Path) -> dict[str, str]:
    """Whether every row of ``path`` belongs to the session session.json records: its
    participant, its session number, and its protocol (a row's phase and samples must be
    in the recorded design).

    Returns
    -------
    dict
        ``identity``: the first disagreement in words, naming the line ('' when none);
        ``identity_of``: what disagrees (``participant``, ``session``, ``protocol``, '');
        ``rows_participant``: when the rows disagree only by naming one other participant
        throughout, that id (the analyst may trust it: ``--ids rows``), else ''.
    """
    pid, ses = meta.participant.id, str(meta.session)
    design = meta.protocol.design or {}
    phases = {p["name"] for p in design.get("phases", [])}
    samples = set(design.get("samples") or {})
    # an adaptive phase's comparison is its standard made for one trial: <standard>@<value>
    adaptive = {p["name"] for p in design.get("phases", []) if p.get("adaptive")}
    first = ""
    named = {r[_PID] for r in rows}
    for line, r in enumerate(rows, start=2):
        if r[_SES] != ses:
            return {"identity": f"{path}:{line}: the row names session {r[_SES]!r}, "
                                f"session.json {ses!r}", "identity_of": "session",
                    "rows_participant": ""}
        if phases and r[_PHASE] not in phases:
            return {"identity": f"{path}:{line}: phase {r[_PHASE]!r} is not a phase of "
                                f"protocol {meta.protocol.name!r} as session.json records it",
                    "identity_of": "protocol", "rows_participant": ""}
        felt = r[_SAMPLE].split("+")
        if r[_PHASE] in adaptive:
            felt = [x.split("@", 1)[0] for x in felt]
        if samples and any(x not in samples for x in felt):
            return {"identity": f"{path}:{line}: sample {r[_SAMPLE]!r} is not a sample of "
                                f"protocol {meta.protocol.name!r} as session.json records it",
                    "identity_of": "protocol", "rows_participant": ""}
        if not first and r[_PID] != pid:
            first = (f"{path}:{line}: the row names participant {r[_PID]!r}, session.json "
                     f"{pid!r}" + ("" if len(named) == 1 else
                                   f" (the rows name {len(named)} participants)"))
    return {"identity": first, "identity_of": "participant" if first else "",
            "rows_participant": next(iter(named)) if first and len(named) == 1 else ""}


def _whose(table: pd.DataFrame, ids: str) -> tuple[pd.DataFrame, list[str]]:
    """Whom each session's rows are analysed under, as ``ids`` chooses (see
    :func:`select_sessions`), and why a session is left out for its identity ('' when it
    is not): a row whose session number or protocol disagrees with session.json, or, with
    ``ids="check"``, a folder, a record and rows that do not name one participant. The
    table gains ``recorded_participant`` (session.json's id); ``participant`` becomes the
    id chosen."""
    table = table.assign(recorded_participant=table["participant"])
    chosen, whose = [], []
    for r in table.itertuples():
        record, folder, rows = r.participant, r.folder_participant, r.rows_participant
        clash = bool(folder) and folder != record
        why, who = "", record
        if r.identity_of and r.identity_of != "participant":
            why = (f"{r.identity}: the rows do not belong to the session its session.json "
                   "records; correct or remove them (there is nothing to choose between)")
        elif ids == "check" and r.identity_of == "participant":
            options = [f"--ids record (analyse as {record})"]
            if rows:
                options.append(f"--ids rows (as {rows})")
            if clash:
                options.append(f"--ids folder (as {folder})")
            why = f"{r.identity}: choose with {' or '.join(options)}"
        elif ids == "check" and clash:
            why = (f"folder sub-{folder} holds participant {record}'s session "
                   f"(session.json, trials.tsv): choose with --ids record (analyse as "
                   f"{record}) or --ids folder (as {folder})")
        elif ids == "folder" and folder:
            who = folder
        elif ids == "rows" and r.identity_of == "participant":
            if rows:
                who = rows
            else:
                why = (f"{r.identity}: --ids rows cannot choose, the rows name several "
                       "participants; choose with --ids record or --ids folder")
        chosen.append(who)
        whose.append(why)
    table["participant"] = chosen
    return table, whose


def _date(text: str | None, name: str) -> dt.datetime | None:
    if text is None:
        return None
    try:
        d = dt.datetime.fromisoformat(str(text))
    except ValueError:
        raise LoadError(f"--{name}: expected a date (YYYY-MM-DD) or an ISO time, got "
                        f"{text!r}") from None
    return d if d.tzinfo else d.replace(tzinfo=dt.UTC)


def select_sessions(data: pd.DataFrame, protocol: str | list[str] | None = None,
                    kind: str | None = None, status: str = "complete",
                    participants: list[str] | None = None, since: str | None = None,
                    until: str | None = None, ids: str = "check", sim_device: bool = False,
                    every_session: bool = False) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Choose which sessions to analyse, and say why each is in or out.

    Parameters
    ----------
    data : DataFrame
        From :func:`load_sessions`.
    protocol : str or list of str, optional
        Protocol names to keep (default: all).
    kind : {'human', 'dry-run', 'simulated', 'all'}, optional
        Default: ``human`` when any human session exists, else ``simulated``, else
        ``dry-run`` — people's data are never pooled with rehearsals unless asked.
    status : {'complete', 'all'}
        ``complete`` (default) leaves out interrupted and running sessions.
    participants : list of str, optional
        Participant ids to keep.
    since, until : str, optional
        Dates (``YYYY-MM-DD``, UTC) or ISO times bounding when a session was created
        (``until`` a date includes that whole day).
    ids : {'check', 'record', 'folder', 'rows'}
        Whom a session's rows are pooled under when its folder (``sub-<id>``), its
        session.json and its trials.tsv rows do not name the same participant (an operator
        typed the wrong ``--participant``, then renamed the folder; rows copied from another
        session): with ``check`` (default) it is left out and named with the first row or
        name that disagrees; ``record`` trusts session.json, ``folder`` the folder's name,
        ``rows`` the one id the rows name. A row whose session number or protocol (a phase
        or sample the recorded design does not have) disagrees with session.json leaves its
        session out whatever ``ids`` says: there is nothing to choose between.
    sim_device : bool
        Keep people's (human) sessions on a simulated device (one that said its contact
        was simulated: nobody touched a physical surface). Default False: they are left
        out of a human analysis and named — a rehearsal is not a participant.
    every_session : bool
        Keep every session of a participant, whatever the design says it analyses (its
        ``sessions`` rule: the first complete one, or all); a raw export (BIDS) does.
        Backup copies (the same participant, seed and rows) are still left out.

    Returns
    -------
    (DataFrame, DataFrame)
        The rows of the included sessions, and the selection table: the session table's
        columns plus ``included`` (bool) and ``reason`` (why it is out, or how it is in).
        A participant with several sessions of one design is analysed as the design
        declares (``sessions``: ``first`` keeps the earliest complete one — an interrupted
        session before it is left out, and named — ``all`` pools them as repetitions); a
        session whose participant, protocol, seed and rows equal another's (a backup copy)
        is left out as a duplicate.

    Examples
    --------
    >>> import analysis as A
    >>> d = A.load_sessions(A.datasets.sessions_path())
    >>> rows, table = A.select_sessions(d, participants=["P01", "P02"])
    >>> print(table[["participant", "included", "reason"]].to_string(index=False))
    participant  included                                               reason
            P01      True kind simulated (the default: no human sessions here)
            P02      True kind simulated (the default: no human sessions here)
            P03     False                             participant not selected
    """
    table = data.attrs["session_table"].copy()
    kind, kind_note = _chosen_kind(table, kind, sim_device)
    _check_choices(ids, status)
    table, whose = _whose(table, ids)
    window = _created_window(since, until)
    protos = [protocol] if isinstance(protocol, str) else protocol
    why = [_left_out_because(r, protos=protos, kind=kind, status=status,
                             participants=participants, window=window, sim_device=sim_device)
           for r in table.itertuples()]
    table["reason"] = [who or w for who, w in zip(whose, why, strict=True)]
    table["included"] = table["reason"] == ""
    _leave_out_backups(table, data)
    if not every_session:
        _apply_session_rules(table, data.attrs.get("designs", {}))
    for i in table.index[table["included"] & (table["reason"] == "")]:
        table.loc[i, "reason"] = kind_note
    return _rows_of(table, data), table


# the steps of select_sessions, in its order


def _chosen_kind(table: pd.DataFrame, kind: str | None, sim_device: bool) -> tuple[str, str]:
    """The kind of session to analyse and how the table says so: the one asked for, or by
    default people's when any exist (people on a simulated device count only when asked
    for), else simulated, else dry runs."""
    if kind is not None:
        if kind not in (*KINDS, "all"):
            raise LoadError(f"--kind must be one of {', '.join(KINDS)} or all, got {kind!r}")
        return kind, f"kind {kind}"
    counted = (table["kind"] != "human") | (table["simulated_plant"] == 0) | sim_device
    present = set(table["kind"][counted])
    kind = next((k for k in ("human", "simulated", "dry-run") if k in present), "human")
    return kind, f"kind {kind} (the default: " + ("people's sessions exist)" if kind == "human"
                                                   else "no human sessions here)")


def _check_choices(ids: str, status: str) -> None:
    if ids not in IDS:
        raise LoadError(f"--ids must be one of {', '.join(IDS)}, got {ids!r}")
    if status not in ("complete", "all"):
        raise LoadError(f"--status must be complete or all, got {status!r}")


def _created_window(since: str | None, until: str | None
                    ) -> tuple[dt.datetime | None, dt.datetime | None]:
    """[since, until) as times; ``until`` a date includes that whole day."""
    t0, t1 = _date(since, "since"), _date(until, "until")
    if t1 is not None and len(str(until)) <= 10:
        t1 = t1 + dt.timedelta(days=1)
    return t0, t1


def _left_out_because(r, *, protos, kind: str, status: str, participants, window,
                      sim_device: bool) -> str:
    """Why the session of row ``r`` is left out ('' when it is not), by the first criterion
    it fails, in the order the report lists them (whose session it is comes first:
    :func:`_whose`)."""
    t0, t1 = window
    created = _date(r.created_utc, "created") if r.created_utc else None
    if protos is not None and r.protocol not in protos:
        return f"protocol {r.protocol} not selected"
    if kind != "all" and r.kind != kind:
        return f"{r.kind} session (selected: {kind})"
    if r.kind == "human" and r.simulated_plant and not sim_device:
        return (f"a person on a simulated device ({r.device_backend}, {r.firmware}): no "
                "physical contact; include with --sim-device")
    if status == "complete" and r.status != SessionStatus.COMPLETE:
        return f"status {r.status or 'unknown'} (selected: complete sessions)"
    if participants is not None and r.participant not in participants:
        return "participant not selected"
    if t0 is not None and (created is None or created < t0):
        return f"created {r.created_utc or 'at an unknown time'}, before --since"
    if t1 is not None and (created is None or created >= t1):
        return f"created {r.created_utc or 'at an unknown time'}, after --until"
    if r.rows == 0:
        return "no recorded attempts"
    return ""


def _leave_out_backups(table: pd.DataFrame, data: pd.DataFrame) -> None:
    """Backup copies left out (in place): the same participant, protocol, seed and rows in
    two folders; the copy nearest the top of the folder is kept (a backup usually sits
    deeper)."""
    fingerprints: dict[tuple, str] = {}
    prints = session_fingerprints(data)  # every session's at once: one pass over the rows
    order = sorted(table.index[table["included"]],
                   key=lambda i: (len(Path(table.at[i, "session_dir"]).parts),
                                  table.at[i, "session_dir"]))
    for i, r in table.loc[order].iterrows():
        key = (r.participant, r.protocol_sha256, r.seed, prints.get(r.session_dir))
        if key in fingerprints:
            table.loc[i, ["included", "reason"]] = (False, f"duplicate of {fingerprints[key]} "
                                                           "(same participant, seed and rows)")
        else:
            fingerprints[key] = r.session_dir


def _apply_session_rules(table: pd.DataFrame, designs: dict) -> None:
    """Several sessions of a participant under one design, as the design declares (in
    place): ``first`` keeps the first complete one (the first of any when none is), ``all``
    pools them as repetitions."""
    inc = table[table["included"]].sort_values(["created_utc", "session"])
    for (_pid, key), g in inc.groupby(["participant", "design_key"], sort=False):
        if len(g) < 2:
            continue
        policy = (designs.get(key) or {}).get("sessions", "first")
        if policy != "first":
            for i in g.index:
                table.loc[i, "reason"] = (f"one of {len(g)} sessions of this participant, "
                                          "pooled as repetitions (the protocol analyses all)")
            continue
        done = [i for i in g.index if g.loc[i, "status"] == SessionStatus.COMPLETE]
        first = done[0] if done else g.index[0]
        what = "first complete session" if done else "first session (none is complete)"
        for i in g.index:
            if i == first:
                continue
            when = "a later" if g.index.get_loc(i) > g.index.get_loc(first) else \
                f"an earlier {g.loc[i, 'status'] or 'unfinished'}"
            table.loc[i, ["included", "reason"]] = (
                False, f"{when} session of {g.loc[i, 'participant']} (the protocol analyses "
                       f"each participant's {what}: {table.loc[first, 'session_dir']})")


def _rows_of(table: pd.DataFrame, data: pd.DataFrame) -> pd.DataFrame:
    """The rows of the included sessions, each under the id chosen for its session
    (``ids``); the selection table in its attrs."""
    keep = set(table.loc[table["included"], "session_dir"])
    out = data[data["session_dir"].isin(keep)].copy()
    chosen = table["included"] & (table["participant"] != table["recorded_participant"]) | (
        table["included"] & (table["identity_of"] == "participant"))
    if chosen.any():  # the rows follow the id chosen for their session (--ids)
        rename = dict(zip(table.loc[chosen, "session_dir"], table.loc[chosen, "participant"],
                          strict=True))
        hit = out["session_dir"].isin(rename)
        out.loc[hit, "participant"] = out.loc[hit, "session_dir"].map(rename)
    out.attrs = dict(data.attrs)
    out.attrs["selection"] = kept(table)
    return out


#: what a backup copy repeats: the rows' attempts and answers
_COPIED = ["item", "attempt", "status", "rating", "answer", "tap_velocities"]


def session_fingerprints(data: pd.DataFrame) -> dict[str, int]:
    """A 64-bit fingerprint of each session's rows (:data:`_COPIED`, in order), by
    ``session_dir``, computed for all sessions at once: two folders holding the same rows
    get the same number (a backup copy), others differ but by a chance of about 2⁻⁶⁴."""
    if data.empty:
        return {}
    pos = data.groupby("session_dir", sort=False).cumcount()
    cells = data[_COPIED].astype(str).assign(_pos=pos.to_numpy())
    h = pd.util.hash_pandas_object(cells, index=False).to_numpy(np.uint64)
    sums = pd.Series(h, index=data.index).groupby(data["session_dir"].to_numpy(),
                                                  sort=False).sum()
    return {str(k): int(v) for k, v in sums.items()}


def tap_velocities(data: pd.DataFrame) -> np.ndarray:
    """All incoming speeds [m/s] listed in the rows of ``data``."""
    out = [float(v) for s in data["tap_velocities"].fillna("") for v in s.split(";") if v]
    return np.asarray(out)
