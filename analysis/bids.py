"""Session folders as a BIDS dataset (Brain Imaging Data Structure, behavioural modality).

``hapticlab export DATA --format bids --out DIR`` writes::

    dataset_description.json  README  participants.tsv/.json  sessions.json
    task-<task>_beh.json  task-<task>_events.json
    sub-<label>/sub-<label>_sessions.tsv
    sub-<label>/ses-<n>/beh/sub-<label>_ses-<n>_task-<task>_beh.tsv      one row per attempt
    sub-<label>/ses-<n>/beh/sub-<label>_ses-<n>_task-<task>_events.tsv   the same, with onsets
    sub-<label>/ses-<n>/beh/sub-<label>_ses-<n>_task-<task>_recording-t<trial>w<k>_physio.tsv.gz
                                                          and .json: one per window kept in full

Decisions (BIDS 1.10):

* **Labels.** BIDS labels are letters and digits only. An id that is already one keeps it;
  any other (``P_01``, ``p-1``) loses what is not a letter or digit and gains ``x`` and four
  hex digits of its CRC-32, so its label does not depend on which other ids are exported
  with it (``P_01`` → ``P01xa8b3``, say). ``participants.tsv`` keeps the id as entered
  (``hapticlab_id``). The task is the protocol's name, so mapped (two protocols whose names
  map alike are refused); a session is its number.
* **Every attempt is a row**, valid or not, with the cells as trials.tsv has them (text,
  ``n/a`` where empty), ``invalid_reason`` where a row recorded valid cannot be analysed,
  and ``recording``: the physio recordings of its windows. Every session of the chosen
  participants is kept, interrupted ones and later sessions too (the design's rule of which
  session to analyse is the analysis's, not the data's); backup copies are not.
* **Onsets** are seconds from the session's start (``created_utc`` in session.json; the
  first attempt's start when absent), from each attempt's recorded start and end (ms; a
  time without a zone is taken as UTC, as the analysis does).
* **Traces.** Each window kept in full (``--traces full``) is one ``_physio.tsv.gz`` at the
  device's servo rate, in SI units (the recorded counts times their resolution).
  ``StartTime`` is the attempt's onset: the window's first sample comes after it (after the
  phase's instructions, if any, and the device's homing), by an amount the session files do
  not record. Windows kept as contact snippets (``--traces contacts``) are not continuous
  recordings and are left out, counted.
"""

from __future__ import annotations

import csv
import datetime as dt
import gzip
import json
import math
import re
import zipfile
import zlib
from pathlib import Path

import numpy as np
import pandas as pd

from .cells import column_meanings
from .load import LoadError, load_sessions, select_sessions
from .session_format import (
    META,
    TRIALS,
    SessionPathError,
    SessionRecord,
    inside_session,
    read_meta,
    read_trials,
)

__all__ = ["export_bids", "BIDS_VERSION", "bids_label"]

BIDS_VERSION = "1.10.0"

#: the trials.tsv columns in _beh.tsv and _events.tsv: (unit, description)
BEH_COLUMNS = {
    "trial_index": ("", "trial number in the session (1, 2, ...)"),
    "phase": ("", "the protocol's phase"),
    "item": ("", "the trial's item: <phase>/<sample>#<repetition>"),
    "attempt": ("", "attempt number of this item (a redrawn or stopped trial runs again)"),
    "sample": ("", "the sample felt (a real block or a rendering; the protocol names them); "
               "identification trials list the surfaces; comparison trials, the two "
               "samples in the order felt"),
    "block": ("", "block (the factorial's material); n/a when the phase has none"),
    "factors": ("", "the sample's factor levels as recorded (name=level, semicolon-separated)"),
    "placement": ("", "what the operator placed on the device (a real sample, or a "
                  "placeholder)"),
    "status": ("", "valid, or why the attempt does not count"),
    "n_taps": ("", "taps in the window"),
    "tap_velocities": ("", "incoming speed of each tap [m/s], semicolon-separated (text: "
                       "BIDS gives a column a unit only where every value is one number)"),
    "peak_current": ("A", "largest amplifier current commanded in the window"),
    # a response's columns: described by the responses the task's phases recorded
    # (analysis.cells.column_meanings); these where none of them fills the column
    "rating": ("", "the participant's rating on the protocol's scale"),
    "response_time": ("s", "from the answer screen's onset to the answer"),
    "answer": ("", "the participant's answer"),
    "correct": ("", "1 when the answer was right, else 0"),
    "track": ("", "adaptive phases: the track (<standard>-<up|down>); n/a otherwise"),
    "intensity": ("", "adaptive phases: the intensity presented, in the phase's units "
                  "(log10 ratio, dB or the parameter's own; the task's sidecar gives them)"),
    "state": ("", "adaptive phases: the procedure after the answer (JSON)"),
    "reason": ("", "why an attempt is not valid, in words"),
}
EXTRA_COLUMNS = {
    "invalid_reason": ("", "why an attempt recorded valid cannot be analysed (a rating off "
                       "the scale, not a number); n/a when it can"),
    "recording": ("", "the _physio recordings of the attempt's windows (recording labels, "
                  "semicolon-separated); n/a when none was kept in full"),
}


def bids_label(text: str) -> str:
    """A BIDS label for ``text``: itself when it is letters and digits only, else those
    letters and digits, ``x`` and four hex digits of its CRC-32 (so the label of one id
    never depends on the others).

    Parameters
    ----------
    text : str

    Returns
    -------
    str

    Examples
    --------
    >>> bids_label("P01"), bids_label("P_01") == bids_label("P_01"), bids_label("P_01")[:4]
    ('P01', True, 'P01x')
    """
    if re.fullmatch(r"[A-Za-z0-9]+", text):
        return text
    return re.sub(r"[^A-Za-z0-9]", "", text) + f"x{zlib.crc32(text.encode()) & 0xFFFF:04x}"


def _labels(ids: list[str]) -> dict[str, str]:
    """A BIDS label per participant id; two ids with one label (letters and digits alike,
    in any case) are an error that names them."""
    out = {pid: bids_label(pid) for pid in sorted(set(ids))}
    seen: dict[str, str] = {}
    for pid, label in out.items():
        other = seen.setdefault(label.lower(), pid)
        if other != pid:
            raise LoadError(f"participants '{other}' and '{pid}' would share the BIDS label "
                            f"sub-{label} (labels are letters and digits, and folders may not "
                            "tell case apart): rename one before exporting")
    return out


def _recording(trace_file: str) -> str:
    """The recording label of a window's trace file: trial-0012-1.npz → t0012w1."""
    m = re.fullmatch(r"trial-(\d+)(?:-(\d+))?", Path(trace_file).stem)
    if m is None:
        return bids_label(Path(trace_file).stem)
    return f"t{m.group(1)}w{m.group(2) or 0}"


def _utc(text: str, where: str) -> dt.datetime | None:
    """An ISO time as UTC (a time without a zone is UTC); None for an empty cell."""
    if not text:
        return None
    try:
        t = dt.datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise LoadError(f"{where}: '{text}' is not an ISO time") from None
    return t.replace(tzinfo=dt.UTC) if t.tzinfo is None else t.astimezone(dt.UTC)


def _na(v):
    """A TSV cell: 'n/a' for a missing or empty value (BIDS), else the value."""
    if v is None or v is pd.NA or v == "" or (isinstance(v, float) and math.isnan(v)):
        return "n/a"
    return v


def _write_tsv(path: Path, table: pd.DataFrame) -> None:
    """``table`` as BIDS TSV (:func:`_write_rows`)."""
    _write_rows(path, list(table.columns), table.itertuples(index=False, name=None))


def _write_rows(path: Path, columns: list[str], rows) -> None:
    """Rows as BIDS TSV ('n/a' for what is missing), written with the csv module: pandas'
    writer cost 9 ms a file, minutes for the files of 21,700 sessions."""
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f, delimiter="\t", lineterminator="\n")
        w.writerow(columns)
        w.writerows([_na(v) for v in row] for row in rows)


def _json(path: Path, data: dict) -> None:
    path.write_text(json.dumps(data, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")


def _physio(path: Path, onset: float) -> tuple[pd.DataFrame, dict] | None:
    """One window's trace file as SI columns, and its sidecar.

    Parameters
    ----------
    path : Path
        A ``traces/*.npz`` the runner wrote.
    onset : float [s]
        The attempt's onset from the session's start (``StartTime``).

    Returns
    -------
    (DataFrame, dict) or None
        None for contact snippets (not a continuous recording).

    Raises
    ------
    LoadError
        The file cannot be read, or lacks a stream (named).
    """
    try:
        with np.load(path) as z:
            if "sample_index" in z:
                return None
            enc = float(z["encoder_resolution"])
            cols = {"position": ("m", z["position_counts"] * enc),
                    "velocity": ("m/s", z["velocity"]), "force_cmd": ("N", z["force_cmd"]),
                    "force_out": ("N", z["force_out"]), "current": ("A", z["current"])}
            if "accel_counts" in z:
                cols["accel"] = ("m/s^2", z["accel_counts"] * float(z["accel_lsb"]))
            cols["flags"] = ("", z["flags"])
            rate = float(z["rate_hz"])
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
        raise LoadError(f"{path}: not a readable trace file ({type(exc).__name__}: {exc})") \
            from None
    table = pd.DataFrame({k: np.asarray(v) for k, (_u, v) in cols.items()})
    side = {"SamplingFrequency": rate, "StartTime": round(onset, 3),
            "Columns": list(table.columns),
            **{k: {"Units": u} for k, (u, _v) in cols.items() if u},
            "flags": {"Description": "bit 0 contact, 1 saturated, 2 transient playing, 3 "
                                     "output zeroed by a fault, 4 enable ramp"}}
    return table, side


def _write_physio(path: Path, table: pd.DataFrame, side: dict) -> list[Path]:
    text = table.to_csv(sep="\t", header=False, index=False, lineterminator="\n",
                        float_format="%.9g")
    # no file name and no time in the gzip header (BIDS): the same data, the same bytes
    with open(path, "wb") as raw, gzip.GzipFile(filename="", mode="wb", fileobj=raw,
                                               mtime=0) as gz:
        gz.write(text.encode("utf-8"))
    side_path = path.with_name(path.name.replace(".tsv.gz", ".json"))
    _json(side_path, side)
    return [path, side_path]


def export_bids(data_dir: str | Path, out: str | Path, progress=None, **filters) -> dict:
    """Write the sessions of ``data_dir`` to ``out`` as a BIDS dataset.

    Parameters
    ----------
    data_dir : str or Path
        Folder of session folders.
    out : str or Path
        The dataset's folder: new, or empty.
    progress : callable (step, done, total), optional
        Told how far the work has got: each session folder read, then written.
    **filters
        protocol, kind, status, participants, since, until, ids, sim_device: as the report,
        but ``status`` is ``all`` unless given, and every session of a participant is kept.

    Returns
    -------
    dict
        ``files`` (list of Path written), ``labels`` (participant id → BIDS label),
        ``sessions`` (count), ``traces_left_out`` (windows kept as contact snippets),
        ``traces_missing`` (trace files trials.tsv names that are not there),
        ``events_without_onset`` (attempts without a recorded start: n/a onsets),
        ``torn`` (torn last lines of trials.tsv, set aside, by file), ``left_out`` (session
        folder → why, for the sessions not exported).

    Raises
    ------
    LoadError
        No session chosen, ``out`` not empty, two sessions or ids that would share a BIDS
        name, a trace or time that cannot be read (each named).

    Examples
    --------
    >>> import tempfile, analysis as A
    >>> from analysis.bids import export_bids
    >>> res = export_bids(A.datasets.sessions_path(), tempfile.mkdtemp() + "/bids")
    >>> res["sessions"], sorted(res["labels"].values())
    (3, ['P01', 'P02', 'P03'])
    """
    out = Path(out)
    if out.exists() and any(out.iterdir()):
        raise LoadError(f"{out}: not empty; a BIDS export goes to a new or empty folder (a "
                        "stale subject left beside a fresh one would be read as data)")
    tell = progress or (lambda step, done, total: None)
    data = load_sessions(data_dir, drop_invalid=True,
                         progress=lambda n, total: tell("loading sessions", n, total))
    chosen = {k: v for k, v in filters.items() if v is not None}
    chosen.setdefault("status", "all")
    selected, table = select_sessions(data, every_session=True, **chosen)
    if selected.empty:
        why = "; ".join(f"{r.session_dir}: {r.reason}" for r in table.itertuples()) or "none"
        raise LoadError(f"{data_dir}: no session chosen for the BIDS export ({why})")
    labels = _labels([str(p) for p in selected["participant"].unique()])
    out.mkdir(parents=True, exist_ok=True)
    res = {"files": [], "labels": labels, "traces_left_out": 0, "traces_missing": 0,
           "events_without_onset": 0, "torn": dict(data.attrs.get("torn", {})),
           "left_out": {r.session_dir: r.reason for r in table.itertuples()
                        if not r.included}}
    tasks: dict[str, dict] = {}
    people: dict[str, dict] = {}
    visits: dict[str, list[dict]] = {}
    names: dict[tuple, str] = {}
    # what a session's export needs of the loaded rows: its participant (as chosen, --ids)
    # and why a row is not analysable; by position, not a frame per session
    pids = selected["participant"].astype(str).to_numpy()
    why = (selected["invalid_reason"].fillna("").astype(str).to_numpy()
           if "invalid_reason" in selected else np.full(len(selected), "", dtype=object))
    at = selected.groupby("session_dir", sort=True).indices
    for n, (folder, rows) in enumerate(at.items(), start=1):
        _session(Path(folder), (str(pids[rows[0]]), list(why[rows])), labels, tasks, people,
                 visits, names, out, res)
        tell("writing the sessions", n, len(at))
    if visits:
        res["files"].append(_sessions_json(out))
    for sub, rows in visits.items():
        p = out / f"sub-{sub}" / f"sub-{sub}_sessions.tsv"
        _write_tsv(p, pd.DataFrame(rows))
        res["files"].append(p)
    res["files"] += _top_level(out, people, tasks)
    res["sessions"] = len(names)
    return res


def _trace_files(folder: Path, pattern: str, where: str) -> list[Path]:
    """The trace files a row names (a glob for several windows), each checked to be in the
    session folder once links are followed."""
    files = sorted(folder.glob(pattern))
    for f in files:
        try:
            inside_session(folder, f.relative_to(folder))
        except SessionPathError as exc:
            raise LoadError(f"{where}: {exc}") from None
    return files


def _session(folder: Path, loaded: tuple[str, list[str]], labels: dict, tasks: dict,
             people: dict, visits: dict, names: dict, out: Path, res: dict) -> None:
    """One session folder into the dataset (see :func:`export_bids`); ``loaded``: the
    participant its rows were loaded under and each row's ``invalid_reason``."""
    meta = read_meta(folder / META)
    raw, _torn = read_trials(folder / TRIALS)
    pid, invalid = loaded
    if len(raw) != len(invalid):  # both without a torn last line: one row per attempt
        raise LoadError(f"{folder / TRIALS}: {len(raw)} rows, but {len(invalid)} were loaded")
    sub, ses = labels[pid], str(meta.session)
    proto = meta.protocol.name
    task = re.sub(r"[^A-Za-z0-9]", "", proto) or "task"
    known = tasks.setdefault(task.lower(), {"task": task, "protocol": proto, "meta": meta})
    if known["protocol"] != proto:
        raise LoadError(f"protocols '{known['protocol']}' and '{proto}' would share the BIDS "
                        f"task label '{task}': rename one before exporting")
    task = known["task"]
    key = (sub, ses, task)
    if key in names:
        raise LoadError(f"{names[key]} and {folder} are both session {ses} of participant "
                        f"'{pid}' in protocol '{proto}': BIDS has one place for it; export "
                        "them apart (--since/--until) or renumber one")
    names[key] = str(folder)
    where = folder / TRIALS
    start = _utc(meta.times.created_utc or "", str(folder / META)) or \
        min((t for r in raw if (t := _utc(r["t_start"], str(where)))), default=None)
    base = out / f"sub-{sub}" / f"ses-{ses}" / "beh"
    base.mkdir(parents=True, exist_ok=True)
    stem = f"sub-{sub}_ses-{ses}_task-{task}"
    recordings = []
    for line, r in enumerate(raw, start=2):
        got = []
        if r["trace_file"]:
            files = _trace_files(folder, r["trace_file"], f"{where}:{line}")
            res["traces_missing"] += 0 if files else 1
            begun = _utc(r["t_start"], f"{where}:{line}")
            for f in files:
                phys = _physio(f, (begun - start).total_seconds()
                               if begun and start else 0.0)
                if phys is None:
                    res["traces_left_out"] += 1
                    continue
                label = _recording(f.name)
                res["files"] += _write_physio(
                    base / f"{stem}_recording-{label}_physio.tsv.gz", *phys)
                got.append(label)
        recordings.append(";".join(got))
    beh = [[r[c] for c in BEH_COLUMNS] + [bad, rec]
           for r, bad, rec in zip(raw, invalid, recordings, strict=True)]
    columns = [*BEH_COLUMNS, "invalid_reason", "recording"]
    p = base / f"{stem}_beh.tsv"
    _write_rows(p, columns, beh)
    res["files"].append(p)
    events = []
    for line, (r, row) in enumerate(zip(raw, beh, strict=True), start=2):
        a, b = _utc(r["t_start"], f"{where}:{line}"), _utc(r["t_end"], f"{where}:{line}")
        onset = round((a - start).total_seconds(), 3) if a and start else None
        res["events_without_onset"] += onset is None
        events.append([onset, round((b - a).total_seconds(), 3) if a and b else None,
                       r["sample"], *row])
    p = base / f"{stem}_events.tsv"
    _write_rows(p, ["onset", "duration", "trial_type", *columns], events)
    res["files"].append(p)
    group = meta.participant.group
    person = people.setdefault(pid, {"participant_id": f"sub-{sub}", "hapticlab_id": pid,
                                     "group": group})
    if person["group"] != group:
        raise LoadError(f"participant '{pid}' is in group '{person['group']}' in one session "
                        f"and '{group}' in {folder}: BIDS has one group per participant")
    device = meta.device
    visits.setdefault(sub, []).append({
        "session_id": f"ses-{ses}",
        "acq_time": start.strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z" if start else None,
        "protocol": proto, "kind": meta.kind, "status": str(meta.status),
        "device": " ".join(x for x in (device.get("model"), device.get("serial_number"))
                           if x) or None,
        "hapticlab_folder": str(folder)})


def _sessions_json(out: Path) -> Path:
    p = out / "sessions.json"  # inherited by every sub-*/sub-*_sessions.tsv
    _json(p, {"acq_time": {"Description": "when the session began (UTC)"},
              "protocol": {"Description": "the protocol the session ran (hapticlab's name)"},
              "kind": {"Description": "who answered",
                       "Levels": {"human": "a person", "dry-run": "a scripted responder "
                                  "testing the machinery", "simulated": "the simulated "
                                  "participant model"}},
              "status": {"Description": "how the session ended (complete, interrupted, ...)"},
              "device": {"Description": "the device's model and serial number"},
              "hapticlab_folder": {"Description": "the session folder it was exported from"}})
    return p


def _scale(meta: SessionRecord) -> dict:
    """The rating scale's levels from the recorded design (empty: none recorded)."""
    scale = meta.protocol.scale
    lo, hi = scale.get("min"), scale.get("max")
    if lo is None or hi is None:
        return {}
    levels = {str(v): f"{v} on the {lo}–{hi} scale" for v in range(int(lo), int(hi) + 1)}
    if scale.get("question"):
        levels[str(lo)] += f" (asked: {scale['question']})"
    return levels


def _top_level(out: Path, people: dict, tasks: dict) -> list[Path]:
    from importlib.metadata import PackageNotFoundError, version

    try:
        ours = version("hapticlab")
    except PackageNotFoundError:
        ours = "unknown"
    written = []
    p = out / "dataset_description.json"
    _json(p, {"Name": "hapticlab sessions: " + ", ".join(sorted(t["protocol"]
                                                               for t in tasks.values())),
              "BIDSVersion": BIDS_VERSION, "DatasetType": "raw",
              "License": "n/a: set by the lab that shares it",
              "Authors": ["n/a: the lab that ran the sessions"],
              "GeneratedBy": [{"Name": "hapticlab", "Version": ours,
                               "Description": "hapticlab export DATA --out DIR --format "
                                              "bids"}]})
    written.append(p)
    p = out / "README"
    p.write_text("Sessions recorded with hapticlab, a psychophysics application for haptic "
                 "contact realism, exported by its export command in the format bids.\n"
                 "Each beh/ folder holds one row per attempt (_beh.tsv), the same rows with "
                 "onsets (_events.tsv), and the force-feedback device's traces of each "
                 "tapping window kept in full (_physio.tsv.gz, named in the rows' "
                 "`recording` column).\nparticipants.tsv maps each BIDS label to the "
                 "participant id as entered (hapticlab_id).\n", encoding="utf-8")
    written.append(p)
    p = out / "participants.tsv"
    _write_tsv(p, pd.DataFrame(sorted(people.values(), key=lambda r: r["participant_id"])))
    written.append(p)
    p = out / "participants.json"
    _json(p, {"hapticlab_id": {"Description": "the participant id as entered in hapticlab "
                                              "(BIDS labels keep letters and digits only)"},
              "group": {"Description": "participant group as given at the session (e.g. "
                                       "expert, novice); n/a when none"}})
    written.append(p)
    for info in tasks.values():
        task, meta = info["task"], info["meta"]
        # a response column's description from what the task's phases recorded; its unit
        # as BIDS takes it (BEH_COLUMNS: none for points of a scale or 0/1)
        answers, _labels = column_meanings((meta.protocol.design or {}).get("phases") or [])
        cols = {c: {"Description": answers[c][1] if c in answers else d,
                    **({"Units": u} if u else {})}
                for c, (u, d) in {**BEH_COLUMNS, **EXTRA_COLUMNS}.items()}
        scale = _scale(meta)
        if scale:
            cols["rating"]["Levels"] = scale
        units = [f"{ph['name']}: {ph['adaptive']['units']}" for ph in
                 (meta.protocol.design or {}).get("phases") or [] if ph.get("adaptive")]
        if units:  # an adaptive phase's intensity is in its own units
            cols["intensity"]["Description"] += f" — {'; '.join(units)}"
        side = {"TaskName": task,
                "TaskDescription": f"the protocol '{info['protocol']}' of hapticlab",
                **cols}
        p = out / f"task-{task}_beh.json"
        _json(p, side)
        written.append(p)
        ev = {"onset": {"Description": "start of the attempt (its tapping window and rating)",
                        "Units": "s"},
              "duration": {"Description": "from the attempt's start to its end", "Units": "s"},
              "trial_type": {"Description": "the sample felt"}, **cols}
        p = out / f"task-{task}_events.json"
        _json(p, {"TaskName": task, "TaskDescription": side["TaskDescription"], **ev})
        written.append(p)
    return written
