"""Crash-safe writing of session folders; the format itself is :mod:`analysis.session_format`.

* ``trials.tsv`` — created with its header, fsynced together with the folder, before anything
  else is recorded; then one row per attempt, each written, flushed and fsynced before the
  next trial starts. A process killed mid-write leaves at most one torn last line, which
  :meth:`SessionFiles.set_aside_torn` moves to ``trials.torn.tsv``.
* ``session.json`` — metadata, written atomically (temporary file, fsync, rename, fsync of
  the folder), rewritten at start, on resume and at the end.
* ``protocol.toml`` — the protocol file the session runs, copied byte for byte.
* Every file is the session's own: a link that leads out of the folder (to another
  session's trials, a shared disk, someone's file) is refused by name before anything is
  read or written (:meth:`SessionFiles.check_own`), and a trials.tsv hard-linked to another
  name (a backup made with ``cp -al``) gets its own copy before rows are appended to it.
* ``traces/`` — per attempt, the device's raw streams as compressed NumPy (``.npz``), also
  written atomically, each recording its own file: the recorder never overwrites one. A
  trace no row names (the process stopped between the two) is moved to
  ``traces/unrecorded/`` before a resume, never deleted.
"""

from __future__ import annotations

import datetime as dt
import fcntl
import fnmatch
import io
import json
import os
from pathlib import Path

import numpy as np

from analysis.session_format import (
    COLUMNS,
    LOCK,
    META,
    PROTOCOL_COPY,
    TRACES,
    TRIALS,
    SessionMetaError,
    SessionPathError,
    SessionRecord,
    TornLine,
    TrialsFileError,
    canonical_bytes,
    format_row,
    header_line,
    inside_session,
    is_canonical,
    read_meta,
    read_trials,
)
from device.fileio import atomic_write

from .errors import SessionFileError, SessionInUseError, io_error

__all__ = ["COLUMNS", "SessionFiles", "new_session_dir", "atomic_write", "TornLine",
           "read_trials", "TrialsFileError"]


def new_session_dir(data: Path, participant: str) -> tuple[Path, int]:
    """Create ``data/sub-<participant>/ses-<n>/`` with the next free n (never reusing one)."""
    sub = Path(data) / f"sub-{participant}"
    try:
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
    except OSError as exc:
        raise io_error(exc, "cannot create the session folder") from None


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

    #: what a session folder holds besides the traces (the torn lines set aside, the lock)
    _OWN = (TRIALS, META, PROTOCOL_COPY, TRACES, LOCK, "trials.torn.tsv")

    def check_own(self) -> None:
        """Every file this session reads or writes stays in its folder once links are
        followed: its files, ``traces/`` and every trace in it.

        Raises
        ------
        SessionFileError
            Naming the link and where it leads (nothing was read or written through it).
        """
        try:
            for name in self._OWN:
                inside_session(self.folder, name)
            for sub in (self.traces, self.traces / "unrecorded"):
                if sub.is_dir():
                    for f in sorted(sub.iterdir()):
                        inside_session(self.folder, f.relative_to(self.folder))
        except SessionPathError as exc:
            raise SessionFileError(str(exc)) from None

    # ------------------------------------------------------------------ one writer
    def lock(self) -> None:
        """Become the one process writing this session (an exclusive ``flock`` on
        ``session.lock``, released by the kernel when the process ends, even by kill -9),
        once :meth:`check_own` found no file leading out of the folder.

        Raises
        ------
        SessionInUseError
            Naming the process that holds it and since when.
        SessionFileError
            A file of the session is a link out of its folder.
        """
        self.check_own()
        try:
            # O_NOFOLLOW: a link put there after the check is not followed either
            fd = os.open(self.folder / LOCK, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o666)
        except OSError as exc:
            raise io_error(exc, "cannot take the session's lock") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 200).decode("utf-8", "replace").split("\t")
            os.close(fd)
            pid = holder[0].strip() or "?"
            since = holder[1].strip() if len(holder) > 1 else "an unknown time"
            raise SessionInUseError(f"{self.folder}: session in use by PID {pid} since "
                                    f"{since}; wait for it to end (or stop that process)") \
                from None
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\t{dt.datetime.now(dt.UTC).isoformat(timespec='seconds')}"
                     "\n".encode())
        self._lock_fd = fd

    def release(self) -> None:
        fd = getattr(self, "_lock_fd", None)
        if fd is not None:
            os.close(fd)  # closing the descriptor releases the flock
            self._lock_fd = None

    # ------------------------------------------------------------------ writing
    def start(self, protocol_text: str) -> None:
        """A new session: the protocol copy and the trials header, durable with the folder
        before anything else is recorded."""
        try:
            atomic_write(self.protocol, protocol_text.encode("utf-8"))
            with open(self.trials, "x", encoding="utf-8", newline="") as f:
                f.write(header_line())
                f.flush()
                os.fsync(f.fileno())
            _fsync_dir(self.folder)
        except OSError as exc:
            raise io_error(exc, "cannot start the session's files") from None

    def repair(self) -> list[str]:
        """Make trials.tsv canonical before a resume appends to it: a missing or empty file
        gets its header (a crash or a full disk before the first row); CRLF or CR endings
        and a byte-order mark (a spreadsheet saved it) are rewritten as this format writes
        them; a file hard-linked to another name gets its own copy (the other is left as it
        was). Returns what was done, for the operator."""
        done = []
        try:
            if not self.trials.exists() or self.trials.stat().st_size == 0:
                atomic_write(self.trials, header_line().encode("utf-8"))
                done.append("wrote the missing header of trials.tsv")
            elif not is_canonical(self.trials):
                rows, torn = self.read_rows()
                if torn is None:
                    atomic_write(self.trials, canonical_bytes(rows))
                    done.append("rewrote trials.tsv with LF line endings, no byte-order "
                                "mark and the current header (the adaptive procedures' "
                                "columns empty in earlier rows)")
            if self.trials.exists() and os.stat(self.trials).st_nlink > 1:
                atomic_write(self.trials, self.trials.read_bytes())  # a new inode: its own
                done.append("trials.tsv was a hard link shared with another name (a backup?): "
                            "the session now has its own copy, and the other name keeps the "
                            "rows it had")
        except OSError as exc:
            raise io_error(exc, "cannot repair trials.tsv") from None
        done += self._set_aside_unrecorded_traces()
        return done

    def _set_aside_unrecorded_traces(self) -> list[str]:
        """Traces no row of trials.tsv names (the process stopped after writing the trace,
        before the row) go to ``traces/unrecorded/``: the attempt runs again and writes its
        own, and nothing recorded is lost."""
        rows, _ = self.read_rows()
        named = [r["trace_file"] for r in rows if r.get("trace_file")]
        moved = self.set_aside(f"{TRACES}/{f.name}" for f in sorted(self.traces.glob("*.npz"))
                               if not any(fnmatch.fnmatchcase(f"{TRACES}/{f.name}", pat)
                                          for pat in named))
        if not moved:
            return []
        return [f"moved {len(moved)} trace file(s) no row names (the session stopped between "
                f"trace and row) to {TRACES}/unrecorded/: {', '.join(moved)}"]

    def set_aside(self, names) -> list[str]:
        """Move trace files (``traces/<name>``, as :meth:`save_trace` returns them) that no
        row names to ``traces/unrecorded/`` (a name taken there gets a number): an attempt
        that ended without its row runs again under the same names. Returns where they went.
        """
        moved = []
        try:
            for rel in names:
                f = self.folder / rel
                if not f.exists():
                    continue
                aside = self.traces / "unrecorded"
                aside.mkdir(exist_ok=True)
                target = aside / f.name
                n = 1
                while target.exists():
                    n += 1
                    target = aside / f"{f.stem}.{n}{f.suffix}"
                os.rename(f, target)
                moved.append(f"{TRACES}/{target.relative_to(self.traces)}")
        except OSError as exc:
            raise io_error(exc, "cannot set an unrecorded trace aside") from None
        return moved

    def write_meta(self, meta: SessionRecord) -> None:
        """session.json from ``meta``, atomically (the old file or the new, never half)."""
        try:
            atomic_write(self.meta, json.dumps(meta.to_json(), indent=2,
                                               sort_keys=True).encode("utf-8"))
        except OSError as exc:
            raise io_error(exc, "cannot write session.json") from None

    def read_meta(self) -> SessionRecord:
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
        try:
            new = not self.trials.exists() or self.trials.stat().st_size == 0
            with open(self.trials, "a", encoding="utf-8", newline="") as f:
                if new:
                    f.write(header_line())
                f.write(line)
                f.flush()
                os.fsync(f.fileno())
            if new:
                _fsync_dir(self.folder)
        except OSError as exc:
            raise io_error(exc, "cannot record the attempt in trials.tsv") from None

    def save_trace(self, name: str, traces: dict, contacts: list) -> str:
        """Write one recording to ``traces/<name>``; returns the path trials.tsv names.

        Raises
        ------
        SessionFileError
            ``traces/<name>`` exists: a recording never replaces another.
        """
        buf = io.BytesIO()
        np.savez_compressed(buf, contacts_t=np.array([c.t for c in contacts]),
                            contacts_v=np.array([c.velocity for c in contacts]),
                            **{k: np.asarray(v) for k, v in traces.items()})
        try:
            atomic_write(self.traces / name, buf.getvalue(), overwrite=False)
        except FileExistsError:
            raise SessionFileError(f"{self.traces / name}: exists; a recording never "
                                   "overwrites another (nothing was replaced)") from None
        except OSError as exc:
            raise io_error(exc, "cannot save the attempt's traces") from None
        return f"{TRACES}/{name}"

    def set_aside_torn(self) -> TornLine | None:
        """Remove a torn last line from trials.tsv (kept in trials.torn.tsv); report it."""
        rows, torn = self.read_rows()
        if torn is None:
            return None
        try:
            with open(self.folder / "trials.torn.tsv", "a", encoding="utf-8") as f:
                f.write(torn.text + "\n")
                f.flush()
                os.fsync(f.fileno())
            atomic_write(self.trials, canonical_bytes(rows))  # what is complete, canonical
        except OSError as exc:
            raise io_error(exc, "cannot set the torn line of trials.tsv aside") from None
        return torn
