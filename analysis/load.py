"""Reading session folders (DESIGN.md) into one long table. No I/O at import; reads only files."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pandas as pd

__all__ = ["load_sessions", "LoadError", "tap_velocities"]


class LoadError(ValueError):
    """A session folder cannot be read (named by path and line)."""


def _read_tsv(path: Path) -> tuple[pd.DataFrame, str | None]:
    text = path.read_text(encoding="utf-8", errors="replace")
    torn = None
    if text and not text.endswith("\n"):
        cut = text.rfind("\n") + 1
        torn, text = text[cut:], text[:cut]
    lines = text.splitlines()
    if not lines:
        return pd.DataFrame(), torn
    header = lines[0].split("\t")
    rows = []
    for no, line in enumerate(lines[1:], start=2):
        f = line.split("\t")
        if len(f) != len(header):
            raise LoadError(f"{path}:{no}: corrupt line ({len(f)} fields, expected "
                            f"{len(header)})")
        rows.append(f)
    return pd.DataFrame(rows, columns=header), torn


def load_sessions(path: str | Path) -> pd.DataFrame:
    """All attempts of all sessions under ``path``, one row per attempt.

    Returns
    -------
    DataFrame
        The trials.tsv columns, typed (``trial_index``, ``attempt``, ``n_taps`` int;
        ``rating``, ``response_time``, ``peak_current``, ``correct`` float, NaN when empty),
        plus ``valid`` (status is valid), ``repetition`` (identification items), one column
        per factor of a factorial design (e.g. ``frequency`` = low/high), and from
        session.json: ``protocol``, ``protocol_sha256``, ``seed``, ``group``, ``scale``
        ("min-max"), ``device_backend``, ``session_dir``.
        ``result.attrs``: ``torn`` (torn last lines set aside, by file), ``files``
        (SHA-256 of every file read), ``sessions`` (count).
    """
    root = Path(path)
    if not root.exists():
        raise LoadError(f"{root}: no such folder")
    metas = sorted(root.rglob("session.json"))
    frames, torn, files = [], {}, {}
    for mpath in metas:
        folder = mpath.parent
        try:
            meta = json.loads(mpath.read_text(encoding="utf-8"))
        except json.JSONDecodeError as exc:
            raise LoadError(f"{mpath}: not valid JSON ({exc})") from None
        tpath = folder / "trials.tsv"
        if not tpath.exists():
            continue
        files[str(tpath.relative_to(root))] = hashlib.sha256(tpath.read_bytes()).hexdigest()
        files[str(mpath.relative_to(root))] = hashlib.sha256(mpath.read_bytes()).hexdigest()
        df, t = _read_tsv(tpath)
        if t is not None:
            torn[str(tpath)] = t
        if df.empty:
            continue
        rating = meta.get("protocol", {}).get("rating") or {}
        df["protocol"] = meta.get("protocol", {}).get("name", "")
        df["protocol_sha256"] = meta.get("protocol", {}).get("sha256", "")
        df["seed"] = meta.get("seed")
        df["group"] = meta.get("participant", {}).get("group", "") or ""
        df["scale"] = f"{rating['min']}-{rating['max']}" if rating else ""
        df["device_backend"] = meta.get("device", {}).get("backend", "")
        df["responder"] = meta.get("responder", "") if meta.get("ui") == "none" else "person"
        df["session_dir"] = str(folder)
        frames.append(df)
    if not frames:
        raise LoadError(f"{root}: no sessions (sub-*/ses-*/session.json with trials.tsv) found")
    data = pd.concat(frames, ignore_index=True)
    for c in ("trial_index", "attempt", "n_taps", "session"):
        data[c] = pd.to_numeric(data[c], errors="coerce").fillna(0).astype(int)
    for c in ("rating", "response_time", "peak_current", "correct"):
        data[c] = pd.to_numeric(data[c].replace("", np.nan), errors="coerce")
    data["valid"] = data["status"] == "valid"
    rep = data["item"].str.extract(r"#(\d+)$")[0]
    data["repetition"] = pd.to_numeric(rep, errors="coerce").fillna(0).astype(int)
    if "factors" in data:
        parsed = data["factors"].fillna("").map(
            lambda s: dict(kv.split("=", 1) for kv in s.split(";") if "=" in kv))
        for name in sorted({k for d in parsed for k in d}):
            data[name] = parsed.map(lambda d, n=name: d.get(n, ""))
    data.attrs["torn"] = torn
    data.attrs["files"] = files
    data.attrs["sessions"] = len(frames)
    return data


def tap_velocities(data: pd.DataFrame) -> np.ndarray:
    """All incoming speeds [m/s] listed in the rows of ``data``."""
    out = [float(v) for s in data["tap_velocities"].fillna("") for v in s.split(";") if v]
    return np.asarray(out)
