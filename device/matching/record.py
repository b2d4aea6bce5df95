"""The measurements a library build has finished, kept on disk as they are made.

A build is 12 sweeps and 8 tapping windows by default: two to three minutes on a device.
:class:`BuildRecord` writes each finished measurement to a file beside the library
(``<library>.partial.npz``, atomically), so a build that stops — a fault the operator does
not clear at once, the device unplugged, the program killed — loses only the measurement in
progress, and the same command resumes from the rest. The record is keyed by everything
that shapes the measurements (the device's identity, the source sample, the sweep levels
and repeats, the window count, the pipeline version); a record made with other settings is
set aside, never mixed in. It is deleted when the library is written.

File format (``.npz``, version 1): ``key_json`` (the key, canonical JSON),
``sweep_levels`` [N], ``sweep_repeats``, ``sweep_accel`` (n, L) [m/s²]; per tapping
window i: ``w{i}_accel`` [m/s²], ``w{i}_t`` [s], ``w{i}_contacts`` ((k, 2): time [s] and
incoming speed [m/s]) and ``w{i}_rate`` [Hz].
"""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from ..events import ContactEvent, WindowResult
from ..fileio import atomic_write

__all__ = ["BuildRecord", "RECORD_VERSION"]

RECORD_VERSION = 1


def _canonical(key: dict) -> str:
    return json.dumps({"record_version": RECORD_VERSION, **key}, sort_keys=True,
                      separators=(",", ":"), default=float)


class BuildRecord:
    """Finished measurements of one build (in memory only when ``path`` is None).

    Parameters
    ----------
    path : Path or None
        Where the record is kept.
    key : dict
        What the measurements depend on (JSON-serialisable).

    Attributes
    ----------
    resumed : int
        Measurements found from an earlier run of the same build.
    set_aside : str or None
        Why a record found at ``path`` was not used (other settings, unreadable).
    """

    def __init__(self, path: Path | None, key: dict):
        self.path = None if path is None else Path(path)
        self.key = _canonical(key)
        self._sweeps: dict[tuple[float, int], np.ndarray] = {}
        self._windows: list[dict[str, np.ndarray]] = []
        self.resumed = 0
        self.set_aside: str | None = None

    @classmethod
    def open(cls, path: Path | None, key: dict, restart: bool = False) -> BuildRecord:
        """The record at ``path`` for this ``key``: what an earlier run kept, or empty (a
        record of other settings, or ``restart``, starts afresh)."""
        rec = cls(path, key)
        if rec.path is None or not rec.path.exists():
            return rec
        if restart:
            rec.set_aside = "--restart"
            return rec
        try:
            with np.load(rec.path, allow_pickle=False) as z:
                if str(z["key_json"]) != rec.key:
                    rec.set_aside = "it was made with other settings or on another device"
                    return rec
                for lv, k, y in zip(z["sweep_levels"], z["sweep_repeats"], z["sweep_accel"],
                                    strict=True):
                    rec._sweeps[(float(lv), int(k))] = np.asarray(y, float)
                i = 0
                while f"w{i}_accel" in z.files:
                    rec._windows.append({n: np.asarray(z[f"w{i}_{n}"])
                                         for n in ("accel", "t", "contacts", "rate")})
                    i += 1
        except (OSError, ValueError, KeyError, zipfile.BadZipFile) as exc:
            rec._sweeps.clear()
            rec._windows.clear()
            rec.set_aside = f"it could not be read ({type(exc).__name__}: {exc})"
            return rec
        rec.resumed = rec.count
        return rec

    @property
    def count(self) -> int:
        """Measurements kept."""
        return len(self._sweeps) + len(self._windows)

    # ---------------------------------------------------------------- sweeps
    def sweep(self, level: float, repeat: int) -> np.ndarray | None:
        """The acceleration recorded for sweep ``repeat`` at ``level`` [N], or None."""
        return self._sweeps.get((float(level), int(repeat)))

    def add_sweep(self, level: float, repeat: int, accel: np.ndarray) -> None:
        self._sweeps[(float(level), int(repeat))] = np.asarray(accel, float)
        self.save()

    # ---------------------------------------------------------------- tapping windows
    @property
    def windows(self) -> list[WindowResult]:
        """The tapping windows kept, as results that :func:`segment_taps` reads."""
        out = []
        for w in self._windows:
            res = WindowResult(float(w["rate"]), None,
                               [ContactEvent(float(t), float(v)) for t, v in w["contacts"]])
            res.traces = {"accel": w["accel"], "t": w["t"]}
            out.append(res)
        return out

    def add_window(self, res: WindowResult) -> None:
        contacts = np.array([(c.t, c.velocity) for c in res.contacts], float).reshape(-1, 2)
        self._windows.append({"accel": np.asarray(res.traces["accel"], float),
                              "t": np.asarray(res.traces["t"], float), "contacts": contacts,
                              "rate": np.asarray(float(res.rate_hz))})
        self.save()

    # ---------------------------------------------------------------- file
    def save(self) -> None:
        """Write the record (atomically); nothing without a path."""
        if self.path is None:
            return
        arrays: dict[str, Any] = {"key_json": np.array(self.key)}
        keys = sorted(self._sweeps)
        arrays["sweep_levels"] = np.array([k[0] for k in keys], float)
        arrays["sweep_repeats"] = np.array([k[1] for k in keys], np.int64)
        arrays["sweep_accel"] = (np.stack([self._sweeps[k] for k in keys]) if keys
                                 else np.zeros((0, 0)))
        for i, w in enumerate(self._windows):
            for name, a in w.items():
                arrays[f"w{i}_{name}"] = a
        buf = io.BytesIO()
        np.savez(buf, **arrays)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(self.path, buf.getvalue())

    def discard(self) -> None:
        """Delete the record (the library it served is written)."""
        if self.path is not None:
            self.path.unlink(missing_ok=True)
