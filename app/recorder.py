"""Crash-safe session files (DESIGN.md): ``sub-<id>/ses-<n>/{session.json, trials.tsv, traces/}``.

* ``trials.tsv`` — one row per attempt, tab-separated, UTF-8, a header line first. Each row
  is written, flushed and fsynced before the next trial starts; a process killed
  mid-write leaves at most one torn last line, which :func:`read_trials` sets aside and
  reports (a corrupt earlier line is a named error).
* ``session.json`` — metadata, written atomically (temporary file, fsync, rename, fsync of
  the folder), rewritten at start, on resume and at the end.
* ``traces/`` — per attempt, the device's raw streams as compressed NumPy (``.npz``), also
  written atomically: ``t, position, velocity, force_cmd, force_out, current, accel,
  flags`` (and the simulator's ``true_*``), plus ``contacts_t``, ``contacts_v``.
"""

from __future__ import annotations

import io
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from device.fileio import atomic_write  # the recorder's durable write (re-exported)

__all__ = ["COLUMNS", "SessionFiles", "TrialsFileError", "read_trials", "new_session_dir",
           "atomic_write", "TornLine"]

COLUMNS = ("participant", "session", "phase", "trial_index", "item", "attempt", "sample",
           "block", "factors", "placement", "status", "n_taps", "tap_velocities", "peak_current",
           "rating", "response_time", "answer", "correct", "reason", "t_start", "t_end",
           "trace_file")


class TrialsFileError(ValueError):
    """trials.tsv has a corrupt line before its last (named by file and line number)."""


@dataclass(frozen=True)
class TornLine:
    """An incomplete last line set aside: its line number and raw text."""

    line: int
    text: str


def new_session_dir(data: Path, participant: str) -> tuple[Path, int]:
    """Create ``data/sub-<participant>/ses-<n>/`` with the next free n (never reusing one)."""
    sub = Path(data) / f"sub-{participant}"
    sub.mkdir(parents=True, exist_ok=True)
    n = 1
    while True:
        d = sub / f"ses-{n}"
        try:
            d.mkdir()  # atomic: two runners cannot get the same session
            (d / "traces").mkdir()
            return d, n
        except FileExistsError:
            n += 1


def _fmt(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.6g}"
    s = str(v)
    if any(c in s for c in "\t\n\r"):
        raise ValueError(f"a tab or newline cannot go into trials.tsv: {s!r}")
    return s


class SessionFiles:
    """The files of one session folder."""

    def __init__(self, folder: Path):
        self.folder = Path(folder)
        self.trials = self.folder / "trials.tsv"
        self.meta = self.folder / "session.json"
        self.traces = self.folder / "traces"

    def write_meta(self, meta: dict) -> None:
        atomic_write(self.meta, json.dumps(meta, indent=2, sort_keys=True).encode("utf-8"))

    def read_meta(self) -> dict:
        try:
            return json.loads(self.meta.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise FileNotFoundError(f"{self.meta}: no session.json — not a session folder") \
                from None
        except json.JSONDecodeError as exc:
            raise ValueError(f"{self.meta}: not valid JSON ({exc})") from None

    def append_row(self, row: dict) -> None:
        """Append one attempt and make it durable before returning."""
        unknown = set(row) - set(COLUMNS)
        if unknown:
            raise ValueError(f"unknown trials.tsv columns: {sorted(unknown)}")
        new = not self.trials.exists()
        line = "\t".join(_fmt(row.get(c)) for c in COLUMNS) + "\n"
        with open(self.trials, "a", encoding="utf-8", newline="") as f:
            if new:
                f.write("\t".join(COLUMNS) + "\n")
            f.write(line)
            f.flush()
            os.fsync(f.fileno())
        if new:
            dfd = os.open(self.folder, os.O_RDONLY)
            try:
                os.fsync(dfd)
            finally:
                os.close(dfd)

    def save_trace(self, name: str, traces: dict, contacts: list) -> str:
        buf = io.BytesIO()
        np.savez_compressed(buf, contacts_t=np.array([c.t for c in contacts]),
                            contacts_v=np.array([c.velocity for c in contacts]),
                            **{k: np.asarray(v) for k, v in traces.items()})
        atomic_write(self.traces / name, buf.getvalue())
        return f"traces/{name}"

    def set_aside_torn(self) -> TornLine | None:
        """Remove a torn last line from trials.tsv (kept in trials.torn.tsv); report it."""
        rows, torn = read_trials(self.trials)
        if torn is None:
            return None
        raw = self.trials.read_bytes()
        keep = raw[: raw.rstrip(b"\n").rfind(b"\n") + 1] if not raw.endswith(b"\n") \
            else raw[: raw[:-1].rfind(b"\n") + 1]
        with open(self.folder / "trials.torn.tsv", "a", encoding="utf-8") as f:
            f.write(torn.text + "\n")
            f.flush()
            os.fsync(f.fileno())
        atomic_write(self.trials, keep)
        return torn


def read_trials(path: Path) -> tuple[list[dict], TornLine | None]:
    """Rows of trials.tsv, and a torn last line if the writer was killed mid-line.

    Raises
    ------
    TrialsFileError
        For a missing or wrong header, or a malformed line that is not the last.
    """
    path = Path(path)
    if not path.exists():
        return [], None
    raw = path.read_bytes().decode("utf-8", errors="replace")
    if not raw:
        return [], None
    complete = raw.endswith("\n")
    lines = raw.split("\n")
    if complete:
        lines = lines[:-1]
    header = lines[0].split("\t")
    if tuple(header) != COLUMNS:
        if len(lines) == 1 and not complete:
            return [], TornLine(1, lines[0])
        raise TrialsFileError(f"{path}:1: header is not the trials.tsv header "
                              f"({len(header)} columns, expected {len(COLUMNS)})")
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
