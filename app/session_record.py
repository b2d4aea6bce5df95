"""The record a session starts with (session.json at its first write): what ran, on what,
for whom, with which versions (:func:`session_meta`), and the times it records
(:func:`utc_now`)."""

from __future__ import annotations

import datetime as _dt
import platform
import subprocess
import sys
from importlib import metadata
from pathlib import Path

from analysis.session_format import (
    FORMAT_VERSION,
    PROTOCOL_COPY,
    ParticipantRecord,
    ProtocolRecord,
    SessionRecord,
    SessionStatus,
    TimesRecord,
)
from device import HapticDevice
from protocols import RNG_ALGORITHM, Protocol

from . import __version__

__all__ = ["session_meta", "utc_now", "APP_VERSION"]

APP_VERSION = __version__


def utc_now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds")


def _git_sha() -> str:
    here = Path(__file__).resolve().parents[1]
    try:
        out = subprocess.run(["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True,
                             text=True, timeout=5)
        return out.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def _versions() -> dict[str, str]:
    out = {}
    for pkg in ("numpy", "scipy", "pandas", "statsmodels", "numba", "pyserial", "matplotlib",
                "psychopy"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return out


def session_meta(protocol: Protocol, protocol_ref: str, participant: str, session: int, seed: int,
                 counterbalance_row: int | None, device: HapticDevice, device_spec: str,
                 ui: str, responder: str, audio: bool, group: str = "",
                 session_kind: str = "dry-run", libraries: dict | None = None,
                 speed: float = 1.0) -> SessionRecord:
    """The record DESIGN.md asks for, at session start; ``speed`` is how the device was
    opened beside its spec (device seconds per wall second where its clock is paced), so a
    resume opens it the same way."""
    return SessionRecord(
        format_version=FORMAT_VERSION,
        app={"name": "hapticlab", "version": APP_VERSION, "git_sha": _git_sha()},
        protocol=ProtocolRecord(name=protocol.name, ref=protocol_ref, source=protocol.source,
                                sha256=protocol.sha256, copy=PROTOCOL_COPY,
                                design=protocol.design()),  # the one place of scale, choices
        kind=session_kind,
        libraries=libraries or {},
        seed=seed,
        rng=RNG_ALGORITHM + "; per attempt: SeedSequence([seed, trial_index, attempt])",
        participant=ParticipantRecord(id=participant, counterbalance_row=counterbalance_row,
                                      group=group),
        session=session,
        device={"spec": device_spec, "speed": float(speed), **device.info.to_dict()},
        ui=ui, responder=responder, audio=audio,
        packages=_versions(),
        python=sys.version.split()[0],
        os=platform.platform(),
        times=TimesRecord(created_utc=utc_now(), finished_utc=None),
        status=SessionStatus.RUNNING,
    )
