"""The steps of :func:`app.api.run_session`, in the order it takes them.

1. :func:`checked_request` — what was asked, checked: nothing is opened for a bad request;
2. :func:`say_earlier_sessions` — a participant's sessions of this protocol already in the data
   folder (a person's need ``new_session``);
3. :func:`check_before_opening` — the data folder, the answers, the terminal and the display:
   nothing starts that cannot be kept or answered;
4. :func:`ready_on` — on the opened device: its checks, the current limit, the libraries;
5. :func:`participant_info` — the participant's details, when asked for;
6. :func:`record_and_run` — the session folder, its record, and the trials to the end.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import UsageError
from ._session import apply_limit, drive, earlier_sessions, keep_markers, session_parts
from .results import SessionResult

__all__ = ["NewSession", "checked_request", "say_earlier_sessions", "check_before_opening",
           "ready_on", "participant_info", "record_and_run", "KIND_OF"]

#: the session kind each responder gives
KIND_OF = {"person": "human", "scripted": "dry-run", "simulated": "simulated"}
_GROUP = re.compile(r"^[A-Za-z0-9_.-]{1,32}$")


@dataclass
class NewSession:
    """A session :func:`app.api.run_session` was asked for, its request checked.

    Attributes
    ----------
    ref : str
        How the caller named the protocol (a built-in name or a path), for commands shown.
    source, text : str
        Where the protocol's text came from, and the text (copied into the session).
    protocol : Protocol
        The parsed protocol (with its libraries once :func:`ready_on` found them).
    engine : SessionEngine
    participant, group, responder, traces, device : str
    seed : int
    row : int or None
    keys : bool
        The operator's keys are read from the terminal.
    audio, fullscreen, quiet, lsl : bool
    lsl_wait : float [s]
    data : Path
    discrimination : dict or None
        A simulated participant's measured JNDs to draw its own around (recorded).
    speed : float
        Device seconds per wall second where the device's clock is paced (recorded).
    """

    ref: str
    source: str
    text: str
    protocol: Any
    engine: Any
    participant: str
    group: str
    responder: str
    traces: str
    device: str
    seed: int
    row: int | None
    keys: bool
    audio: bool
    fullscreen: bool
    quiet: bool
    lsl: bool
    lsl_wait: float
    data: Path
    discrimination: dict | None = None
    speed: float = 1.0

    @property
    def person(self) -> bool:
        """A person answers (at the PsychoPy screen)."""
        return self.responder == "person"


def check_responder(responder: str) -> str:
    """``responder`` when it is one of :data:`KIND_OF`'s."""
    if responder not in KIND_OF:
        raise UsageError(f"responder must be one of {', '.join(KIND_OF)}, got {responder!r}")
    return responder


def check_speed(speed) -> float:
    """``speed`` (device seconds per wall second) when it is a number in (0, 20]."""
    if not (isinstance(speed, (int, float)) and not isinstance(speed, bool)
            and math.isfinite(speed) and 0 < speed <= 20):
        raise UsageError(f"speed must be in (0, 20] (device seconds per wall second), got "
                         f"{speed!r}")
    return float(speed)


def checked_request(protocol, participant: str, *, device: str, data, responder: str,
                    seed: int | None, row: int | None, group: str, traces: str,
                    operator_keys: bool | None, audio: bool, fullscreen: bool, quiet: bool,
                    lsl: bool, lsl_wait: float, discrimination: dict | None = None,
                    speed: float = 1.0) -> NewSession:
    """Step 1: the request checked, the protocol parsed, the seed drawn when not given.

    Raises
    ------
    UsageError, ProtocolError
        Naming what is wrong with the request, before anything is opened.
    """
    from app.ids import validate_participant
    from protocols import SessionEngine, parse_protocol, protocol_text, seed_from_entropy

    responder = check_responder(responder)
    if traces not in ("full", "contacts", "none"):
        raise UsageError(f"traces must be full, contacts or none, got {traces!r}")
    participant = validate_participant(participant)
    if group and not _GROUP.match(group):
        raise UsageError(f"group {group!r}: use letters, digits, '_', '-' or '.' (at most 32)")
    source, text = protocol_text(protocol)
    proto = parse_protocol(text, source)
    speed = check_speed(speed)
    seed = seed_from_entropy() if seed is None else seed
    if not isinstance(seed, int) or seed < 0:
        raise UsageError(f"seed must be an integer >= 0, got {seed!r}")
    return NewSession(
        ref=str(protocol), source=source, text=text, protocol=proto,
        engine=SessionEngine(proto, seed, participant, row), participant=participant,
        group=group, responder=responder, traces=traces, device=device, seed=seed, row=row,
        keys=operator_keys if operator_keys is not None else responder == "person",
        audio=audio, fullscreen=fullscreen, quiet=quiet, lsl=lsl, lsl_wait=lsl_wait,
        data=Path(data), discrimination=discrimination, speed=speed)


def say_earlier_sessions(s: NewSession, new_session: bool, say: Callable[[str], None]) -> None:
    """Step 2: the participant's earlier sessions of this protocol, said; a person's stop
    the run unless ``new_session`` (a mistyped id must not start a second session).

    Raises
    ------
    UsageError
        A person with sessions of this protocol, without ``new_session``.
    """
    from protocols.texts import english_note

    earlier = earlier_sessions(s.data, s.participant, s.protocol.name)
    if earlier:
        listed = "; ".join(earlier)
        if s.person and not new_session:
            raise UsageError(f"participant {s.participant} already has {s.protocol.name} "
                             f"session(s) in {s.data}: {listed}. Check the participant id; "
                             "start another session with --new-session, or continue an "
                             "unfinished one with: hapticlab resume FOLDER")
        say(f"participant {s.participant} already has {s.protocol.name} session(s): "
            f"{listed}; this one is the next")
    if s.person and (note := english_note(s.protocol)):
        say(f"note: {note}")


def check_before_opening(s: NewSession) -> None:
    """Step 3: before any device or window opens, nothing starts that cannot be kept or
    answered: room in the data folder, answers the protocol can take, the operator's
    terminal and the participant's display where they are needed.

    Raises
    ------
    DataFolderError, PreflightError
    """
    from app.preflight import (
        PreflightError,
        check_answers,
        check_display,
        check_terminal,
        data_folder_ready,
        expected_session_bytes,
        failed,
    )

    data_folder_ready(s.data, expected_session_bytes(s.protocol, s.traces))
    early = [check_answers(s.protocol)]
    if s.keys:
        early.append(check_terminal())
    if s.person:
        early.append(check_display())
    if failed(early):
        raise PreflightError(failed(early))


def ready_on(s: NewSession, dev, say: Callable[[str], None]) -> tuple[dict, dict]:
    """Step 4: on the opened device — said when a person sits at a simulated one — its own
    checks and the protocol's against it, the current limit, and the transient libraries
    (``s.protocol`` takes them). Returns (limits, libraries) as session.json records them.

    Raises
    ------
    PreflightError, UsageError, MissingLibraryError
    """
    from app.libraries import prepare_libraries, with_libraries
    from app.preflight import PreflightError, check_device, check_protocol_on, failed

    if s.person and dev.info.simulated_contact:
        say(f"warning: a person on a SIMULATED device ({s.device}) — nothing they feel comes "
            "from a physical surface; the session is recorded as human, with the device's "
            "capabilities (an analysis leaves it out unless asked)")
    again = (f"hapticlab run {s.ref} --participant {s.participant} --device {s.device} "
             "--clear-fault (with the session's other options)")
    checks = [check_device(dev, s.device, again), check_protocol_on(s.text, s.source, dev)]
    if failed(checks):
        raise PreflightError(failed(checks))
    limits = apply_limit(s.protocol, dev)
    libraries = prepare_libraries(s.protocol, dev, s.device, say, ref=s.ref)
    s.protocol = with_libraries(s.protocol, libraries)
    return limits, libraries


def participant_info(s: NewSession, info_fields: dict | None) -> dict | None:
    """Step 5: the participant's details from a dialog (the protocol's ``[participant]
    fields`` when it declares them, else ``info_fields``), before the window opens; None
    when not asked.

    Raises
    ------
    UsageError
        The dialog was cancelled (nothing recorded).
    """
    if not info_fields:
        return None
    from app.screen import info_dialog

    info = info_dialog(dict(s.protocol.participant_fields or info_fields))
    if info is None:
        raise UsageError("the participant information dialog was cancelled; nothing was "
                         "recorded")
    return info


def record_and_run(s: NewSession, dev, console, say: Callable[[str], None], *, limits: dict,
                   libraries: dict, info: dict | None) -> SessionResult:
    """Step 6: with the participant's side, the sound, the console and the markers open, a
    new session folder (locked, the protocol copied, session.json written), then the trials
    to the end (:func:`app.api._session.drive`)."""
    from app.recorder import SessionFiles, new_session_dir
    from app.runner import SessionRunner
    from app.session_record import session_meta

    files = None
    try:
        with session_parts(dev, s.protocol, responder=s.responder, seed=s.seed, group=s.group,
                           fullscreen=s.fullscreen, audio=s.audio, keys=s.keys, quiet=s.quiet,
                           console=console, lsl=s.lsl, participant=s.participant,
                           say=say, discrimination=s.discrimination) as parts:
            folder, n = new_session_dir(s.data, s.participant)
            files = SessionFiles(folder)
            files.lock()
            files.start(s.text)
            meta = session_meta(s.protocol, s.ref, s.participant, n, s.seed, s.row, dev,
                                s.device, "psychopy" if s.person else "none", s.responder,
                                parts.sound is not None, s.group, KIND_OF[s.responder],
                                libraries, speed=s.speed)
            meta.traces_mode = s.traces
            meta.limits = limits
            if s.responder == "simulated" and s.discrimination:
                meta.discrimination = dict(s.discrimination)  # a resume draws the same
            meta.participant.info = info
            keep_markers(meta, parts.markers)
            files.write_meta(meta)
            parts.console.say(f"session {folder} (seed {s.seed})")
            runner = SessionRunner(protocol=s.protocol, engine=s.engine, device=dev,
                                   files=files, responder=parts.responder,
                                   participant=s.participant, session=n, seed=s.seed,
                                   console=parts.console, audio=parts.sound, traces=s.traces,
                                   meta=meta, markers=parts.markers)
            return drive(runner, files, meta, parts.console, s.lsl_wait)
    finally:
        if files is not None:
            files.release()
