"""The steps a session (run or resume) shares: who answers, the sound, the console and the
markers beside the device, the current limit, and driving the runner to its end."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from analysis.session_format import SessionRecord, SessionStatus

from ..errors import SessionFileError, UsageError
from ..guards import Terminated
from .results import SessionResult

__all__ = ["make_responder", "open_audio", "Parts", "session_parts", "apply_limit", "open_markers",
           "keep_markers", "drive", "earlier_sessions", "check_rows"]


def make_responder(responder: str, protocol, seed: int, group: str, fullscreen: bool,
                   discrimination: dict | None = None):
    """What answers a session's trials, for the ``responder`` named (``person``,
    ``simulated`` or ``scripted``); a simulated one draws its JNDs around
    ``discrimination`` when given (measured Weber fractions, app.observer)."""
    if responder == "person":
        from app.screen import PsychoPyScreen

        return PsychoPyScreen(protocol, fullscreen=fullscreen)
    if responder == "simulated":
        from app.participant_model import SimulatedParticipant

        return SimulatedParticipant(protocol, seed, group, discrimination)
    from app.participants import ScriptedResponder

    return ScriptedResponder()


def open_audio(enabled: bool, info, say: Callable[[str], None]):
    """The session's sound (None without): on a device a person touches for real, a session
    without it is refused (the masking noise hides the samples' own sound); on a simulated
    contact there is nothing to hide, and the session goes on without."""
    if not enabled:
        return None
    from app.audio import Audio, AudioUnavailable

    try:
        return Audio()
    except AudioUnavailable as exc:
        if not info.simulated_contact:
            raise UsageError(f"no audio device ({exc}): a real session needs masking noise "
                             "and the tap cue; fix the audio or pass --no-audio") from None
        say(f"warning: no audio ({exc}); on this simulated device the session continues "
            "without sound")
        return None


@dataclass
class Parts:
    """What a session runs with beside its device, closed together."""

    responder: Any
    sound: Any
    console: Any
    markers: Any


@contextmanager
def session_parts(dev, proto, *, responder: str, seed: int, group: str, fullscreen: bool,
                   audio: bool, keys: bool, quiet: bool, console, lsl: bool,
                   participant: str, say: Callable[[str], None],
                   discrimination: dict | None = None) -> Iterator[Parts]:
    """The participant's side, the sound, the operator's console and the markers of a
    session (run or resume) on ``dev``, each closed when it ends."""
    from app.console import make_console

    parts = Parts(make_responder(responder, proto, seed, group, fullscreen, discrimination),
                  None, console, None)
    try:
        parts.sound = open_audio(audio, dev.info, say)
        if keys:
            parts.console = make_console("keys", quiet, dev)
        parts.markers = open_markers(lsl, proto.name, participant, seed, dev, parts.console.say)
        yield parts
    finally:
        for part in (parts.responder, parts.sound, parts.console, parts.markers):
            if part is not None:
                part.close()


def apply_limit(protocol, dev, recorded: float | None = None) -> dict:
    """Clamp the device's current at the protocol's ``[limits] max_current`` (the lower of
    it and the device's rating), for the whole session; what session.json records."""
    from device import CurrentLimitError

    rating = dev.info.current_limit
    wanted = recorded if recorded is not None else protocol.limits.max_current
    try:
        applied = dev.set_current_limit(rating if wanted is None else wanted)
    except CurrentLimitError as exc:  # the device's ceiling (DeviceInfo.ceiling) says no
        raise UsageError(f"the protocol's [limits] max_current: {exc}") from None
    return {"current_limit_a": applied, "device_rating_a": rating,
            "protocol_max_current_a": protocol.limits.max_current}


def open_markers(lsl: bool, protocol: str, participant: str, seed: int, dev, say):
    """The session's marker sink: an LSL outlet with ``lsl`` (made before the session's
    folder, named by what a resume knows: protocol, participant, seed), else one that
    sends nothing."""
    from app.markers import LslMarkers, MarkerSink

    if not lsl:
        return MarkerSink()
    return LslMarkers("hapticlab markers", f"hapticlab:{protocol}:sub-{participant}:seed-{seed}",
                      {"participant": participant, "protocol": protocol, "seed": seed,
                       "device": f"{dev.info.backend} {dev.info.serial_number}"}, say)


def keep_markers(meta: SessionRecord, markers) -> None:
    """This run of the markers' stream in session.json (updated in place as it runs)."""
    if markers.active:
        if meta.lsl is None:
            meta.lsl = {"stream": markers.stream, "runs": []}
        meta.lsl["runs"].append(markers.run)


def drive(runner, files, meta, console, lsl_wait: float = 300.0) -> SessionResult:
    from app.errors import DataFolderError
    from app.runner import SessionInterrupted, utc_now

    markers = runner.markers

    def stopped(why: str, status: SessionStatus, msg: str) -> SessionResult:
        meta.interrupted(why)  # Ctrl-C too: resumed the same way
        markers.trial(None)
        markers.send("session_end", status=status, why=why)
        markers.close()
        try:
            files.write_meta(meta)
        except DataFolderError as exc:  # the disk that stopped the session
            msg += f"\n(session.json still says 'running': {exc})"
        console.say(msg)
        return SessionResult(files.folder, status, len(runner.log), msg)

    started = time.monotonic()
    try:
        if not markers.wait_for_consumer(lsl_wait, console.say):
            return stopped("no LSL recorder", SessionStatus.INTERRUPTED,
                           f"no recorder received the LSL markers within {lsl_wait:g} s; no "
                           "trial ran. Start the recording, then resume with: hapticlab "
                           f"resume {files.folder} --lsl")
        markers.send("session_start", participant=runner.participant, session=runner.session,
                     protocol=runner.protocol.name, attempts_logged=len(runner.log))
        runner.run()
    except SessionInterrupted as exc:
        return stopped(str(exc), SessionStatus.INTERRUPTED, f"session interrupted: {exc}\n"
                       f"resume with: hapticlab resume {files.folder}")
    except (KeyboardInterrupt, Terminated) as exc:
        return stopped(f"stopped ({type(exc).__name__})", SessionStatus.STOPPED,
                       "stopped; everything recorded is saved. resume with: hapticlab resume "
                       f"{files.folder}")
    except BaseException:  # an error no stop caught: the stream goes, its record is kept
        if markers.active:
            markers.close()
            with suppress(Exception):
                files.write_meta(meta)
        raise
    meta.times.finished_utc = utc_now()
    meta.status = SessionStatus.COMPLETE
    summary = runner.summary(time.monotonic() - started)
    meta.summary = summary
    meta.link = runner.device.link_stats()
    if runner.timing:  # live pacing (the simulator in live mode): achieved servo rate
        rates = [t["achieved_rate_hz"] for t in runner.timing]
        meta.timing = {"achieved_rate_hz_median": float(np.median(rates)),
                          "lateness_p99_s_max": max(t["lateness_p99_s"] for t in runner.timing),
                          "slipped_s_total": sum(t.get("slipped_s", 0.0) for t in runner.timing)}
    if runner.warnings:  # what the device could not do as asked, once each
        meta.add_warnings(list(runner.warnings.values()))
    files.write_meta(meta)  # the trials are complete and durable before the debrief
    if runner.console.interactive or runner.responder.name == "person":
        console.say(f"trials complete: {summary} — the participant is answering the "
                    "debrief question")
    meta.participant.debrief = runner.responder.debrief()
    markers.send("session_end", status=SessionStatus.COMPLETE)
    markers.close()
    files.write_meta(meta)
    console.say(f"session complete: {summary}")
    runner.responder.finished(summary)
    return SessionResult(files.folder, SessionStatus.COMPLETE, len(runner.log),
                         f"session complete: {files.folder} ({len(runner.log)} attempts)")


def earlier_sessions(data: Path, participant: str, protocol: str) -> list[str]:
    """``ses-<n> (status, created)`` of each earlier session of ``participant`` with the
    protocol named ``protocol`` in ``data`` (unreadable ones named as such)."""
    from analysis.session_format import META, SessionMetaError, read_meta

    out = []
    sub = data / f"sub-{participant}"
    if not sub.is_dir():
        return out
    for folder in sorted(sub.glob("ses-*"), key=lambda f: (len(f.name), f.name)):
        try:
            meta = read_meta(folder / META)
        except (SessionMetaError, OSError):
            out.append(f"{folder.name} (session.json unreadable)")
            continue
        if meta.protocol.name != protocol:
            continue
        created = (meta.times.created_utc or "")[:10]
        out.append(f"{folder.name} ({meta.status}, {meta.kind}"
                   f"{', ' + created if created else ''})")
    return out


def check_rows(files, meta: SessionRecord, rows: list[dict]) -> None:
    """Every recorded row belongs to this session (participant and session number)."""
    pid, ses = meta.participant.id, str(meta.session)
    for i, r in enumerate(rows, start=2):
        for col, want in (("participant", pid), ("session", ses)):
            if r[col] != want:
                raise SessionFileError(f"{files.trials}:{i}: {col} is {r[col]!r} but "
                                       f"session.json says {want!r}: the files do not belong "
                                       "together (edited, or copied from another session)")
