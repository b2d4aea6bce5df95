"""Session folders as a BIDS dataset (Brain Imaging Data Structure, behavioural modality).

``hapticlab export DATA --format bids --out DIR`` writes::

    dataset_description.json  README  participants.tsv/.json  task-<task>_beh.json
    task-<task>_events.json
    sub-<label>/sub-<label>_sessions.tsv
    sub-<label>/ses-<n>/beh/sub-<label>_ses-<n>_task-<task>_beh.tsv      one row per attempt
    sub-<label>/ses-<n>/beh/sub-<label>_ses-<n>_task-<task>_events.tsv   the same, with onsets
    sub-<label>/ses-<n>/beh/sub-<label>_ses-<n>_task-<task>_recording-<trial>_physio.tsv.gz
                                                          and .json: one per kept window

Decisions (BIDS 1.10):

* **Labels.** BIDS labels are letters and digits only. A participant id with anything else
  (``P_01``, ``p-1``) loses it, and one that then collides with another, or is left
  empty, gets a number appended; ``participants.tsv`` keeps the id as entered
  (``hapticlab_id``), so the mapping is written down. The task is the protocol's name, so
  mapped; a session is its number.
* **Every attempt is a row**, valid or not (``status`` and ``reason`` say which), as
  trials.tsv has them: a raw dataset, not the analysis's selection. Empty cells are
  ``n/a``.
* **Onsets** are seconds from the session's start (``created_utc`` in session.json; the
  first trial's start when absent), from each attempt's recorded start and end (ms).
* **Traces.** Each window kept in full (``--traces full``) is one ``_physio.tsv.gz`` at the
  device's servo rate, in SI units (the recorded counts times their resolution), with
  ``StartTime`` the attempt's start in seconds from the session's (the window begins then,
  to the millisecond the trial's start is recorded in); windows kept as
  contact snippets (``--traces contacts``) are not continuous recordings and are left out
  (counted in the return value).
"""

from __future__ import annotations

import datetime as dt
import gzip
import json
import re
from pathlib import Path

import numpy as np
import pandas as pd

from .load import load_sessions, select_sessions
from .session_format import META, read_meta

__all__ = ["export_bids", "BIDS_VERSION", "bids_label"]

BIDS_VERSION = "1.10.0"

#: the trials.tsv columns in _beh.tsv and _events.tsv, with their descriptions and units
BEH_COLUMNS = {
    "trial_index": ("", "trial number in the session (1, 2, ...)"),
    "phase": ("", "the protocol's phase"),
    "item": ("", "the trial's item: <phase>/<sample>#<repetition>"),
    "attempt": ("", "attempt number of this item (a redrawn or stopped trial runs again)"),
    "sample": ("", "the sample felt (a real block or a rendering; the protocol names them); "
               "identification trials list the surfaces"),
    "block": ("", "block (the factorial's material); n/a when the phase has none"),
    "placement": ("", "what the operator placed on the device (a real sample, or a "
                  "placeholder)"),
    "status": ("", "valid, or why the attempt does not count"),
    "n_taps": ("", "taps in the window"),
    "tap_velocities": ("", "incoming speed of each tap [m/s], semicolon-separated (text: "
                       "BIDS gives a column one unit only where every value is one number)"),
    "peak_current": ("A", "largest amplifier current commanded in the window"),
    "rating": ("", "the participant's rating on the protocol's scale (participants.json "
               "and the sidecar give its anchors)"),
    "response_time": ("s", "from the rating screen to the answer"),
    "answer": ("", "identification: the materials named for the surfaces, in order"),
    "correct": ("", "identification: 1 when every surface was named right, else 0"),
    "reason": ("", "why an attempt is not valid, in words"),
}


def bids_label(text: str) -> str:
    """``text`` with everything but ASCII letters and digits left out."""
    return re.sub(r"[^A-Za-z0-9]", "", text)


def _labels(ids: list[str]) -> dict[str, str]:
    """A BIDS label per participant id: unique, letters and digits only."""
    out: dict[str, str] = {}
    taken: set[str] = set()
    for pid in sorted(set(ids)):
        base = bids_label(pid) or "x"
        label, n = base, 1
        while label.lower() in taken:  # BIDS labels must differ also in case on some disks
            n += 1
            label = f"{base}{n}"
        taken.add(label.lower())
        out[pid] = label
    return out


def _na(v):
    if v is None:
        return "n/a"
    if isinstance(v, float) and not np.isfinite(v):
        return "n/a"
    if isinstance(v, str) and v == "":
        return "n/a"
    return v


def _write_tsv(path: Path, table: pd.DataFrame) -> None:
    text = table.map(_na).to_csv(sep="\t", index=False, lineterminator="\n", na_rep="n/a")
    path.write_text(text, encoding="utf-8")


def _json(path: Path, data: dict) -> None:
    path.write_text(json.dumps(data, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")


def _utc(text) -> dt.datetime | None:
    if not isinstance(text, str) or not text:
        return None
    return dt.datetime.fromisoformat(text.replace("Z", "+00:00"))


def _physio(z, onset: float) -> tuple[pd.DataFrame, dict] | None:
    """A full window's trace as SI columns, and its sidecar (``StartTime``: ``onset``, the
    attempt's start in seconds from the session's, to the millisecond the trial records);
    None for contact snippets."""
    if "sample_index" in z:
        return None
    enc = float(z["encoder_resolution"])
    cols = {"position": ("m", z["position_counts"] * enc),
            "velocity": ("m/s", z["velocity"]), "force_cmd": ("N", z["force_cmd"]),
            "force_out": ("N", z["force_out"]), "current": ("A", z["current"])}
    if "accel_counts" in z:
        cols["accel"] = ("m/s^2", z["accel_counts"] * float(z["accel_lsb"]))
    cols["flags"] = ("", z["flags"])
    table = pd.DataFrame({k: np.asarray(v) for k, (_u, v) in cols.items()})
    side = {"SamplingFrequency": float(z["rate_hz"]),
            "StartTime": round(onset, 3),
            "Columns": list(table.columns),
            **{k: {"Units": u} for k, (u, _v) in cols.items() if u},
            "flags": {"Description": "bit 0 contact, 1 saturated, 2 transient playing, 3 "
                                     "output zeroed by a fault, 4 enable ramp"}}
    return table, side


def export_bids(data_dir: str | Path, out: str | Path, **filters) -> dict:
    """Write the sessions of ``data_dir`` to ``out`` as a BIDS dataset.

    Parameters
    ----------
    data_dir : path
        Folder of session folders.
    out : path
        The dataset's folder (created; files hapticlab writes there are replaced).
    **filters
        protocol, kind, status, participants, since, until, ids, sim_device: as the report,
        but ``status`` is ``all`` unless given (a raw dataset keeps interrupted sessions;
        sessions.tsv says how each ended).

    Returns
    -------
    dict
        ``files`` (list of Path written), ``labels`` (participant id → BIDS label; ids that
        changed are the ones to read about), ``traces_left_out`` (windows kept as contact
        snippets, not continuous), ``sessions`` (count).
    """
    data = load_sessions(data_dir, drop_invalid=True)
    chosen = {k: v for k, v in filters.items() if v is not None}
    chosen.setdefault("status", "all")
    selected, _table = select_sessions(data, **chosen)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    labels = _labels([str(p) for p in selected["participant"].unique()])
    written: list[Path] = []
    left_out = 0
    tasks: dict[str, dict] = {}
    people: dict[str, dict] = {}
    visits: dict[str, list[dict]] = {}
    for folder, rows in selected.groupby("session_dir", sort=True):
        folder = Path(folder)
        meta = read_meta(folder / META)
        pid = str(rows["participant"].iloc[0])
        sub = labels[pid]
        ses = str(int(rows["session"].iloc[0]))
        proto = meta["protocol"]["name"]
        task = bids_label(proto) or "task"
        tasks.setdefault(task, {"protocol": proto, "meta": meta, "factors": set()})
        start = _utc(meta.get("times", {}).get("created_utc")) or \
            min((_utc(t) for t in rows["t_start"] if _utc(t)), default=None)
        base = out / f"sub-{sub}" / f"ses-{ses}" / "beh"
        base.mkdir(parents=True, exist_ok=True)
        stem = f"sub-{sub}_ses-{ses}_task-{task}"
        factors = [c for c in rows.columns if c in ("frequency", "decay", "slope")]
        tasks[task]["factors"].update(factors)
        beh = rows[[c for c in BEH_COLUMNS if c in rows.columns] + factors].copy()
        beh = beh.sort_values(["trial_index", "attempt"], kind="stable")
        for c in ("n_taps", "trial_index", "attempt"):
            beh[c] = beh[c].astype("Int64")
        p = base / f"{stem}_beh.tsv"
        _write_tsv(p, beh)
        written.append(p)
        t0 = [_utc(t) for t in rows.sort_values(["trial_index", "attempt"])["t_start"]]
        t1 = [_utc(t) for t in rows.sort_values(["trial_index", "attempt"])["t_end"]]
        if start is not None and all(t0) and all(t1):
            ev = beh.copy()
            ev.insert(0, "onset", [round((a - start).total_seconds(), 3) for a in t0])
            ev.insert(1, "duration", [round((b - a).total_seconds(), 3)
                                      for a, b in zip(t0, t1, strict=True)])
            ev.insert(2, "trial_type", beh["sample"].to_numpy())
            p = base / f"{stem}_events.tsv"
            _write_tsv(p, ev)
            written.append(p)
        for row in rows.itertuples():
            name = getattr(row, "trace_file", "")
            if not isinstance(name, str) or not name or not (folder / name).exists():
                continue
            begun = _utc(row.t_start)
            if start is None or begun is None:
                continue
            with np.load(folder / name) as z:
                got = _physio(z, (begun - start).total_seconds())
            if got is None:
                left_out += 1
                continue
            table, side = got
            rec = bids_label(Path(name).stem)
            p = base / f"{stem}_recording-{rec}_physio.tsv.gz"
            text = table.to_csv(sep="\t", header=False, index=False, lineterminator="\n",
                                float_format="%.9g")
            # no file name and no time in the gzip header (BIDS): the same data, the same bytes
            with open(p, "wb") as raw, gzip.GzipFile(filename="", mode="wb", fileobj=raw,
                                                       mtime=0) as gz:
                gz.write(text.encode("utf-8"))
            written.append(p)
            q = p.with_name(p.name.replace(".tsv.gz", ".json"))
            _json(q, side)
            written.append(q)
        who = meta.get("participant", {})
        people.setdefault(pid, {"participant_id": f"sub-{sub}", "hapticlab_id": pid,
                                "group": who.get("group", "") or ""})
        visits.setdefault(sub, []).append({
            "session_id": f"ses-{ses}",
            "acq_time": start.astimezone(dt.UTC).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3]
            if start else "n/a",
            "protocol": proto, "kind": meta.get("kind", ""), "status": meta.get("status", ""),
            "device": f"{meta.get('device', {}).get('model', '')} "
                      f"({meta.get('device', {}).get('serial_number', '')})".strip()})
    if visits:
        p = out / "sessions.json"  # inherited by every sub-*/sub-*_sessions.tsv
        _json(p, {"acq_time": {"Description": "when the session began (UTC)"},
                  "protocol": {"Description": "the hapticlab protocol the session ran"},
                  "kind": {"Description": "who answered",
                           "Levels": {"human": "a person", "dry-run": "a scripted responder "
                                      "testing the machinery", "simulated": "the simulated "
                                      "participant model"}},
                  "status": {"Description": "how the session ended (complete, interrupted, "
                                            "stopped, ...)"},
                  "device": {"Description": "the device's model and serial number"}})
        written.append(p)
    for sub, rows_ in visits.items():
        p = out / f"sub-{sub}" / f"sub-{sub}_sessions.tsv"
        _write_tsv(p, pd.DataFrame(rows_))
        written.append(p)
    written += _top_level(out, people, tasks)
    return {"files": written, "labels": labels, "traces_left_out": left_out,
            "sessions": int(selected["session_dir"].nunique())}


def _scale(meta: dict) -> dict:
    rating = meta["protocol"].get("design", {}).get("rating") or {}
    lo, hi = rating.get("min"), rating.get("max")
    if lo is None or hi is None:
        return {}
    levels = {str(v): str(v) for v in range(int(lo), int(hi) + 1)}
    for k, v in (rating.get("anchors") or {}).items():
        levels[str(k)] = f"{k}: {v}"
    return levels


def _top_level(out: Path, people: dict, tasks: dict) -> list[Path]:
    from app import __version__ as version

    written = []
    p = out / "dataset_description.json"
    _json(p, {"Name": "hapticlab sessions: " + ", ".join(sorted(t["protocol"]
                                                               for t in tasks.values())),
              "BIDSVersion": BIDS_VERSION, "DatasetType": "raw",
              "License": "n/a: set by the lab that shares it",
              "Authors": ["n/a: the lab that ran the sessions"],
              "GeneratedBy": [{"Name": "hapticlab", "Version": str(version),
                               "Description": "hapticlab export DATA --format bids"}]})
    written.append(p)
    p = out / "README"
    p.write_text("Sessions recorded with hapticlab, a psychophysics application for haptic "
                 "contact realism, exported with `hapticlab export DATA --format bids`.\n"
                 "Each beh/ folder holds one row per attempt (_beh.tsv), the same rows with "
                 "onsets (_events.tsv), and the force-feedback device's traces of each "
                 "tapping window kept in full (_physio.tsv.gz).\nparticipants.tsv maps each "
                 "BIDS label to the participant id as entered (hapticlab_id).\n",
                 encoding="utf-8")
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
    for task, info in tasks.items():
        meta = info["meta"]
        cols = {c: {"Description": d, **({"Units": u} if u else {})}
                for c, (u, d) in BEH_COLUMNS.items()}
        scale = _scale(meta)
        if scale:
            cols["rating"]["Levels"] = scale
        for f in sorted(info["factors"]):
            cols[f] = {"Description": f"factorial level of the vibration's {f}",
                       "Levels": {"low": "the lower level", "high": "the higher level"}}
        side = {"TaskName": task, "TaskDescription": f"hapticlab protocol '{info['protocol']}'",
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
