"""Crash-safe writing of session folders; the format itself is :mod:`analysis.session_format`.

* ``trials.tsv`` — created with its header, fsynced together with the folder, before anything
  else is recorded; then one row per attempt, each written, flushed and fsynced before the
  next trial starts. A process killed mid-write leaves at most one torn last line, which
  :meth:`SessionFiles.set_aside_torn` moves to ``trials.torn.tsv``.
* ``session.json`` — metadata, written atomically (temporary file, fsync, rename, fsync of
  the folder), rewritten at start, on resume and at the end.
* ``protocol.toml`` — the protocol file the session runs, copied byte for byte.
* ``traces/`` — per attempt, the device's raw streams as compressed NumPy (``.npz``), also
  written atomically.
"""

from __future__ import annotations

import io
import json
import os
from pathlib import Path

import numpy as np

from analysis.session_format import (
    COLUMNS,
    META,
    PROTOCOL_COPY,
    TRACES,
    TRIALS,
    SessionMetaError,
    TornLine,
    TrialsFileError,
    format_row,
    header_line,
    read_meta,
    read_trials,
)
from device.fileio import atomic_write

from .errors import SessionFileError

__all__ = ["COLUMNS", "SessionFiles", "new_session_dir", "atomic_write", "TornLine",
           "read_trials", "TrialsFileError"]


def new_session_dir(data: Path, participant: str) -> tuple[Path, int]:
    """Create ``data/sub-<participant>/ses-<n>/`` with the next free n (never reusing one)."""
    sub = Path(data) / f"sub-{participant}"
    sub.mkdir(parents=True, exist_ok=True)
    n = 1
    while True:
        d = sub / f"ses-{n}"
        try:
            d.mkdir()  # atomic: the claim; two runners cannot get the same session
            (d / TRACES).mkdir()
            return d, n
        except FileExistsError:
            n += 1


def _fsync_dir(folder: Path) -> None:
    dfd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(dfd)
    finally:
        os.close(dfd)


class SessionFiles:
    """The files of one session folder."""

    def __init__(self, folder: Path):
        self.folder = Path(folder)
        self.trials = self.folder / TRIALS
        self.meta = self.folder / META
        self.protocol = self.folder / PROTOCOL_COPY
        self.traces = self.folder / TRACES

    def start(self, protocol_text: str) -> None:
        """A new session: the protocol copy and the trials header, durable with the folder
        before anything else is recorded."""
        atomic_write(self.protocol, protocol_text.encode("utf-8"))
        with open(self.trials, "x", encoding="utf-8", newline="") as f:
            f.write(header_line())
            f.flush()
            os.fsync(f.fileno())
        _fsync_dir(self.folder)

    def write_meta(self, meta: dict) -> None:
        atomic_write(self.meta, json.dumps(meta, indent=2, sort_keys=True).encode("utf-8"))

    def read_meta(self) -> dict:
        try:
            return read_meta(self.meta)
        except SessionMetaError as exc:
            raise SessionFileError(str(exc)) from None

    def read_rows(self) -> tuple[list[dict], TornLine | None]:
        try:
            return read_trials(self.trials)
        except TrialsFileError as exc:
            raise SessionFileError(str(exc)) from None

    def append_row(self, row: dict) -> None:
        """Append one attempt and make it durable before returning."""
        line = format_row(row)
        new = not self.trials.exists() or self.trials.stat().st_size == 0
        with open(self.trials, "a", encoding="utf-8", newline="") as f:
            if new:
                f.write(header_line())
            f.write(line)
            f.flush()
            os.fsync(f.fileno())
        if new:
            _fsync_dir(self.folder)

    def save_trace(self, name: str, traces: dict, contacts: list) -> str:
        buf = io.BytesIO()
        np.savez_compressed(buf, contacts_t=np.array([c.t for c in contacts]),
                            contacts_v=np.array([c.velocity for c in contacts]),
                            **{k: np.asarray(v) for k, v in traces.items()})
        atomic_write(self.traces / name, buf.getvalue())
        return f"{TRACES}/{name}"

    def set_aside_torn(self) -> TornLine | None:
        """Remove a torn last line from trials.tsv (kept in trials.torn.tsv); report it."""
        rows, torn = self.read_rows()
        if torn is None:
            return None
        raw = self.trials.read_bytes()
        keep = raw[: raw.rstrip(b"\n").rfind(b"\n") + 1] if not raw.endswith(b"\n") \
            else raw[: raw[:-1].rfind(b"\n") + 1]
        with open(self.folder / "trials.torn.tsv", "a", encoding="utf-8") as f:
            f.write(torn.text + "\n")
            f.flush()
            os.fsync(f.fileno())
        atomic_write(self.trials, keep if keep else header_line().encode("utf-8"))
        return torn
