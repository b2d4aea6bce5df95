"""The programmatic API: run, resume and simulate sessions, analyse a data folder.

The command line is a thin layer over these functions. Every error they raise on purpose is
a :class:`~device.errors.HapticlabError` (bad input, unusable files, a device that fails);
a session that stops part way is not an error but a :class:`SessionResult` whose status
says so (everything recorded is on disk and :func:`resume_session` continues it).

Examples
--------
>>> from app.api import run_session, simulate_study, analyze        # doctest: +SKIP
>>> r = run_session("realism", "P01", device="sim", responder="simulated", data="sim-data",
...                 audio=False)                                     # doctest: +SKIP
>>> r.status, r.folder                                               # doctest: +SKIP
('complete', PosixPath('sim-data/sub-P01/ses-1'))
"""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from analysis.session_format import SessionRecord, SessionStatus

from .errors import AnalysisError, SessionFileError, UsageError
from .guards import Terminated, close_at_exit

__all__ = ["SessionResult", "StudyResult", "run_session", "resume_session", "simulate_study",
           "analyze", "session_seed", "protocol_plan", "validate_protocol", "power",
           "preflight", "saturation_forecast", "open_device_for", "device_selftest",
           "device_list", "emulate", "EMULATORS", "benchmark", "BENCHMARKS",
           "BENCH_OPTIONS", "KIND_OF",
           "DEFAULT_SIM_DATA", "OVERHEAD_S"]

_GROUP = re.compile(r"^[A-Za-z0-9_.-]{1,32}$")

#: the session kind each responder gives
KIND_OF = {"person": "human", "scripted": "dry-run", "simulated": "simulated"}
#: where simulated studies go unless told otherwise (never beside people's data)
DEFAULT_SIM_DATA = "sim-data"


@dataclass(frozen=True)
class SessionResult:
    """How a session ended.

    Attributes
    ----------
    folder : Path
        The session folder.
    status : SessionStatus
        ``complete``, ``interrupted`` (the device failed or the operator aborted; resume it)
        or ``stopped`` (a signal or Ctrl-C; resume it). A ``str``: it compares and prints
        as its text.
    attempts : int
        Rows recorded in trials.tsv.
    message : str
        What happened, for people (how to resume).
    """

    folder: Path
    status: SessionStatus
    attempts: int
    message: str = ""

    @property
    def exit_code(self) -> int:
        """0 complete, 3 interrupted, 130 stopped (the CLI's exit status)."""
        return {SessionStatus.COMPLETE: 0, SessionStatus.INTERRUPTED: 3}.get(self.status, 130)


@dataclass(frozen=True)
class StudyResult:
    """A simulated study: its sessions (in order) and how long each stage took [s]."""

    sessions: list[SessionResult] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def complete(self) -> bool:
        return all(s.status == SessionStatus.COMPLETE for s in self.sessions)


def _err(*args) -> None:
    print(*args, file=sys.stderr, flush=True)


def _make_responder(responder: str, protocol, seed: int, group: str, fullscreen: bool):
    """What answers a session's trials, for the ``responder`` named (``person``,
    ``simulated`` or ``scripted``)."""
    if responder == "person":
        from app.screen import PsychoPyScreen

        return PsychoPyScreen(protocol, fullscreen=fullscreen)
    if responder == "simulated":
        from app.participant_model import SimulatedParticipant

        return SimulatedParticipant(protocol, seed, group)
    from app.participants import ScriptedResponder

    return ScriptedResponder()


def _audio(enabled: bool, device_backend: str, say: Callable[[str], None]):
    if not enabled:
        return None
    from app.audio import Audio, AudioUnavailable

    try:
        return Audio()
    except AudioUnavailable as exc:
        if device_backend != "sim":
            raise UsageError(f"no audio device ({exc}): a real session needs masking noise "
                             "and the tap cue; fix the audio or pass --no-audio") from None
        say(f"warning: no audio ({exc}); dry run continues without sound")
        return None


def open_device_for(spec: str, *, clear_fault: bool = False,
                    say: Callable[[str], None] | None = None, seed: int = 0,
                    person: bool = False):
    """The device a command opens, with a fault it latched before (an e-stop, the watchdog)
    cleared when the operator said so: every command that opens a device goes through here.

    Parameters
    ----------
    spec : str
        The device spec (``sim``, ``serial:/dev/ttyACM0``, ...).
    clear_fault : bool
        Clear a fault latched before (the operator's decision: ``--clear-fault``); what is
        cleared is said through ``say``.
    say : callable, optional
        Where the operator reads it (default: stderr).
    seed : int
        The simulated device's seed (``sim`` only).
    person : bool
        A person sits at it: the simulated device is paced to the wall clock (unpaced it
        tapped 910 times in 13 s of familiarization).

    Raises
    ------
    DeviceError
        The device cannot be opened, or keeps its fault (its e-stop button still pressed).
    """
    from device import open_device

    dev = (open_device(spec, seed=seed, live=person) if spec == "sim" or spec.startswith("sim:")
           else open_device(spec))
    if clear_fault and dev.fault is not None:
        (say or _err)(f"clearing the latched {dev.fault.code} fault of {spec} (the operator's "
                      "decision: --clear-fault)")
        try:
            dev.clear_fault()
        except BaseException:
            dev.close()
            raise
    return dev


@contextmanager
def _session_device(spec: str, seed: int, person: bool, clear_fault: bool, lsl: bool,
                    say: Callable[[str], None]) -> Iterator:
    """The device a session (run or resume) opens: LSL checked first when asked for (no
    pylsl, or no private network where one is required, is said before anything opens),
    closed at exit whatever ends the process, a fault it latched before cleared when the
    operator said so."""
    if lsl:
        from app.markers import load_pylsl

        load_pylsl()
    with open_device_for(spec, clear_fault=clear_fault, say=say, seed=seed,
                         person=person) as dev:
        close_at_exit(dev)
        yield dev


@dataclass
class _Parts:
    """What a session runs with beside its device, closed together."""

    responder: Any
    sound: Any
    console: Any
    markers: Any


@contextmanager
def _session_parts(dev, proto, *, responder: str, seed: int, group: str, fullscreen: bool,
                   audio: bool, keys: bool, quiet: bool, console, lsl: bool,
                   participant: str, say: Callable[[str], None]) -> Iterator[_Parts]:
    """The participant's side, the sound, the operator's console and the markers of a
    session (run or resume) on ``dev``, each closed when it ends."""
    from app.console import make_console

    parts = _Parts(_make_responder(responder, proto, seed, group, fullscreen), None, console,
                   None)
    try:
        parts.sound = _audio(audio, dev.info.backend, say)
        if keys:
            parts.console = make_console("keys", quiet, dev)
        parts.markers = _markers(lsl, proto.name, participant, seed, dev, parts.console.say)
        yield parts
    finally:
        for part in (parts.responder, parts.sound, parts.console, parts.markers):
            if part is not None:
                part.close()


def _apply_limit(protocol, dev, recorded: float | None = None) -> dict:
    """Clamp the device's current at the protocol's ``[limits] max_current`` (the lower of
    it and the device's rating), for the whole session; what session.json records."""
    rating = dev.info.current_limit
    wanted = recorded if recorded is not None else protocol.limits.max_current
    if wanted is not None and wanted > rating * (1 + 1e-12):
        raise UsageError(f"the protocol's [limits] max_current of {wanted:g} A is above this "
                         f"device's rating of {rating:g} A")
    applied = dev.set_current_limit(min(wanted, rating) if wanted is not None else rating)
    return {"current_limit_a": applied, "device_rating_a": rating,
            "protocol_max_current_a": protocol.limits.max_current}


def _markers(lsl: bool, protocol: str, participant: str, seed: int, dev, say):
    """The session's marker sink: an LSL outlet with ``lsl`` (made before the session's
    folder, named by what a resume knows: protocol, participant, seed), else one that
    sends nothing."""
    from app.markers import LslMarkers, MarkerSink

    if not lsl:
        return MarkerSink()
    return LslMarkers("hapticlab markers", f"hapticlab:{protocol}:sub-{participant}:seed-{seed}",
                      {"participant": participant, "protocol": protocol, "seed": seed,
                       "device": f"{dev.info.backend} {dev.info.serial_number}"}, say)


def _keep_markers(meta: SessionRecord, markers) -> None:
    """This run of the markers' stream in session.json (updated in place as it runs)."""
    if markers.active:
        if meta.lsl is None:
            meta.lsl = {"stream": markers.stream, "runs": []}
        meta.lsl["runs"].append(markers.run)


def _drive(runner, files, meta, console, lsl_wait: float = 300.0) -> SessionResult:
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


def _responder(responder: str) -> str:
    if responder not in KIND_OF:
        raise UsageError(f"responder must be one of {', '.join(KIND_OF)}, got {responder!r}")
    return responder


def run_session(protocol: str | Path, participant: str, *, device: str,
                data: str | Path = "data", responder: str = "person", seed: int | None = None,
                row: int | None = None, group: str = "", traces: str = "full",
                audio: bool = True, fullscreen: bool = False, quiet: bool = False,
                operator_keys: bool | None = None, clear_fault: bool = False,
                info_fields: dict | None = None, new_session: bool = False,
                say: Callable[[str], None] | None = None, lsl: bool = False,
                lsl_wait: float = 300.0) -> SessionResult:
    """Run one session to the end (or until it is stopped) and record it.

    Parameters
    ----------
    protocol : str or Path
        A built-in protocol name (``realism``, ``factorial``, ``identification``) or a file.
    participant : str
        Participant id (letters, digits, ``_``, ``-``; at most 32).
    device : str
        Device spec: ``sim``, ``sim:RATE``, ``serial:PORT``.
    data : path
        Data folder; the session goes to ``data/sub-<participant>/ses-<n>/``.
    responder : {'person', 'scripted', 'simulated'}
        Who answers: a person at the PsychoPy screen (a ``human`` session), random answers
        (a ``dry-run``), or the simulated participant model (``simulated``).
    seed : int, optional
        Session seed (drawn and recorded when None).
    row : int, optional
        Counterbalance row for Williams-ordered block orders.
    group : str
        Participant group label (e.g. ``expert``).
    traces : {'full', 'contacts', 'none'}
        Raw device streams kept per attempt.
    audio : bool
        Masking noise, tap cue and saturation tone.
    fullscreen : bool
        The participant's window fills the screen.
    quiet : bool
        No console lines.
    operator_keys : bool, optional
        Read operator keys from the terminal (default: when a person answers; refused
        without a terminal).
    clear_fault : bool
        Clear a fault the device latched before the session (the operator's decision).
    info_fields : dict, optional
        Ask the participant's details in a dialog first (the protocol's ``[participant]
        fields`` when it declares them, else these); stored in session.json.
    new_session : bool
        A person who already has sessions of this protocol in ``data`` gets another only
        with this (the error lists what exists, and how to resume an unfinished one); for
        a dry run or a simulated participant what exists is said, and the session runs.
    say : callable, optional
        Where messages for the operator go (default: stderr).
    lsl : bool
        Send the session's events as markers on Lab Streaming Layer (:mod:`app.markers`).
    lsl_wait : float [s]
        With ``lsl``, how long to wait for a recorder to receive the markers before the
        first trial; without one the session stops there (resumable, nothing lost).

    Returns
    -------
    SessionResult
    """
    from app.console import make_console
    from app.ids import validate_participant
    from app.libraries import prepare_libraries, with_libraries
    from app.preflight import (
        PreflightError,
        check_answers,
        check_device,
        check_display,
        check_protocol_on,
        check_terminal,
        data_folder_ready,
        expected_session_bytes,
        failed,
    )
    from app.recorder import SessionFiles, new_session_dir
    from app.runner import SessionRunner, session_meta
    from protocols import SessionEngine, parse_protocol, protocol_text, seed_from_entropy
    from protocols.texts import english_note

    responder = _responder(responder)
    if traces not in ("full", "contacts", "none"):
        raise UsageError(f"traces must be full, contacts or none, got {traces!r}")
    participant = validate_participant(participant)
    if group and not _GROUP.match(group):
        raise UsageError(f"group {group!r}: use letters, digits, '_', '-' or '.' (at most 32)")
    source, text = protocol_text(protocol)
    proto = parse_protocol(text, source)
    seed = seed_from_entropy() if seed is None else seed
    if not isinstance(seed, int) or seed < 0:
        raise UsageError(f"seed must be an integer >= 0, got {seed!r}")
    engine = SessionEngine(proto, seed, participant, row)
    console = make_console(quiet=quiet)
    say = say or console.say
    earlier = _earlier_sessions(Path(data), participant, proto.name)
    if earlier:
        listed = "; ".join(earlier)
        if responder == "person" and not new_session:
            raise UsageError(f"participant {participant} already has {proto.name} session(s) "
                             f"in {data}: {listed}. Check the participant id; start another "
                             "session with --new-session, or continue an unfinished one with: "
                             "hapticlab resume FOLDER")
        say(f"participant {participant} already has {proto.name} session(s): {listed}; "
            "this one is the next")
    if responder == "person" and (note := english_note(proto)):
        say(f"note: {note}")
    keys = operator_keys if operator_keys is not None else responder == "person"
    # before any device or window opens: nothing starts that cannot be kept or answered
    data_folder_ready(data, expected_session_bytes(proto, traces))
    early = [check_answers(proto)]
    if keys:
        early.append(check_terminal())
    if responder == "person":
        early.append(check_display())
    if failed(early):
        raise PreflightError(failed(early))
    with _session_device(device, seed, responder == "person", clear_fault, lsl, say) as dev:
        again = (f"hapticlab run {protocol} --participant {participant} --device {device} "
                 "--clear-fault (with the session's other options)")
        checks = [check_device(dev, device, again), check_protocol_on(text, source, dev)]
        if failed(checks):
            raise PreflightError(failed(checks))
        limits = _apply_limit(proto, dev)
        libraries = prepare_libraries(proto, dev, device, say, ref=str(protocol))
        proto = with_libraries(proto, libraries)
        info = None
        if info_fields:  # the participant's details, asked before the window opens
            from app.screen import info_dialog

            info = info_dialog(dict(proto.participant_fields or info_fields))
            if info is None:
                raise UsageError("the participant information dialog was cancelled; nothing "
                                 "was recorded")
        files = None
        try:
            with _session_parts(dev, proto, responder=responder, seed=seed, group=group,
                                fullscreen=fullscreen, audio=audio, keys=keys, quiet=quiet,
                                console=console, lsl=lsl, participant=participant,
                                say=say) as parts:
                folder, n = new_session_dir(Path(data), participant)
                files = SessionFiles(folder)
                files.lock()
                files.start(text)
                meta = session_meta(proto, str(protocol), participant, n, seed, row, dev,
                                    device, "psychopy" if responder == "person" else "none",
                                    responder, parts.sound is not None, group,
                                    KIND_OF[responder], libraries)
                meta.traces_mode = traces
                meta.limits = limits
                meta.participant.info = info
                _keep_markers(meta, parts.markers)
                files.write_meta(meta)
                parts.console.say(f"session {folder} (seed {seed})")
                runner = SessionRunner(protocol=proto, engine=engine, device=dev, files=files,
                                       responder=parts.responder, participant=participant,
                                       session=n, seed=seed, console=parts.console,
                                       audio=parts.sound, traces=traces, meta=meta,
                                       markers=parts.markers)
                return _drive(runner, files, meta, parts.console, lsl_wait)
        finally:
            if files is not None:
                files.release()


def _earlier_sessions(data: Path, participant: str, protocol: str) -> list[str]:
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


def _check_rows(files, meta: SessionRecord, rows: list[dict]) -> None:
    """Every recorded row belongs to this session (participant and session number)."""
    pid, ses = meta.participant.id, str(meta.session)
    for i, r in enumerate(rows, start=2):
        for col, want in (("participant", pid), ("session", ses)):
            if r[col] != want:
                raise SessionFileError(f"{files.trials}:{i}: {col} is {r[col]!r} but "
                                       f"session.json says {want!r}: the files do not belong "
                                       "together (edited, or copied from another session)")


def resume_session(folder: str | Path, *, device: str | None = None, audio: bool | None = None,
                   clear_fault: bool = False, fullscreen: bool = False, quiet: bool = False,
                   operator_keys: bool | None = None, lsl: bool = False,
                   lsl_wait: float = 300.0) -> SessionResult:
    """Continue an interrupted session exactly where it stopped.

    The session keeps its kind and responder; the protocol is the copy in the session
    folder (so resuming works from any working directory, and editing the original file
    changes nothing), with the library files recorded at the start.

    Parameters
    ----------
    folder : path
        The session folder (``.../sub-P01/ses-1``).
    device : str, optional
        Another device spec than the recorded one (e.g. the same device on another port).
    audio : bool, optional
        Default: as recorded.
    clear_fault : bool
        Clear a latched e-stop or watchdog fault first (the operator's decision).
    fullscreen, quiet, operator_keys, lsl, lsl_wait
        As :func:`run_session` (a resume with ``lsl`` is a new run of the markers' stream,
        recorded beside the earlier ones in session.json).
    """
    from app.console import make_console
    from app.recorder import SessionFiles

    files = SessionFiles(Path(folder))
    files.read_meta()  # a session folder (a named error otherwise), before anything is written
    files.lock()  # one writer: a second resume of this session stops here
    try:
        meta = files.read_meta()  # as the last writer left it
        console = make_console(quiet=quiet)
        if meta.status == SessionStatus.COMPLETE:
            return SessionResult(files.folder, SessionStatus.COMPLETE, len(files.read_rows()[0]),
                                 f"{files.folder}: the session is already complete")
        return _resume(files, meta, console, device, audio, clear_fault, fullscreen, quiet,
                       operator_keys, lsl, lsl_wait)
    finally:
        files.release()


def _resume(files, meta, console, device, audio, clear_fault, fullscreen, quiet,
            operator_keys, lsl, lsl_wait) -> SessionResult:
    from app.ids import validate_participant
    from app.libraries import check_recorded, with_libraries
    from app.preflight import data_folder_ready
    from app.runner import SessionRunner, utc_now
    from protocols import LogMismatch, ResumeMismatch, SessionEngine, parse_protocol

    ref = meta.protocol.ref or ""
    if files.protocol.exists():
        text, source = files.protocol.read_text(encoding="utf-8"), str(files.protocol)
    else:  # written before sessions kept their protocol copy
        from protocols import protocol_text

        source, text = protocol_text(ref)
    proto = parse_protocol(text, source)
    if proto.sha256 != meta.protocol.sha256:
        raise ResumeMismatch(f"cannot resume: {source} changed since the session started "
                             f"(sha256 {meta.protocol.sha256[:12]}… then, "
                             f"{proto.sha256[:12]}… now)")
    proto = with_libraries(proto, meta.libraries)
    p = meta.participant
    validate_participant(p.id, new=False)
    engine = SessionEngine(proto, meta.seed, p.id, p.counterbalance_row)
    engine.check_resume({"protocol_sha256": meta.protocol.sha256, "seed": meta.seed,
                         "participant": p.id, "counterbalance_row": p.counterbalance_row})
    data_folder_ready(files.folder)
    torn = files.set_aside_torn()
    if torn is not None:
        console.say(f"set aside a torn last line of trials.tsv (line {torn.line}, kept in "
                    "trials.torn.tsv): the attempt it belonged to will run again")
    for done in files.repair():
        console.say(done)
    rows, _ = files.read_rows()
    _check_rows(files, meta, rows)
    responder = meta.responder or "scripted"
    if responder not in KIND_OF:
        responder = "person" if meta.ui == "psychopy" else "scripted"
    spec = device or meta.device_spec
    with _session_device(spec, meta.seed, responder == "person", clear_fault, lsl,
                         console.say) as dev:
        limits = _apply_limit(proto, dev, (meta.limits or {}).get("current_limit_a"))
        check_recorded(meta.libraries, dev)
        keys = operator_keys if operator_keys is not None else responder == "person"
        with _session_parts(dev, proto, responder=responder, seed=meta.seed,
                            group=p.group, fullscreen=fullscreen,
                            audio=meta.audio if audio is None else audio,
                            keys=keys, quiet=quiet, console=console, lsl=lsl,
                            participant=p.id, say=console.say) as parts:
            console = parts.console
            runner = SessionRunner(protocol=proto, engine=engine, device=dev, files=files,
                                   responder=parts.responder, participant=p.id,
                                   session=meta.session, seed=meta.seed, console=console,
                                   audio=parts.sound, traces=meta.traces_mode or "full",
                                   meta=meta, markers=parts.markers)
            runner.load_log()
            try:
                engine.next_trial(runner.log)
            except LogMismatch as exc:
                raise SessionFileError(f"{files.trials}: {exc}") from None
            if parts.responder.stateful:  # its answers depend on what it felt: bring it back
                console.say(f"replaying {len(rows)} recorded attempts for the simulated "
                            "participant's memory")
                runner.replay(rows)
            meta.resumes.append({"at_utc": utc_now(), "attempts_logged": len(runner.log),
                                    "torn_line": None if torn is None else torn.line,
                                    "device": spec, "limits": limits})
            meta.status = SessionStatus.RUNNING
            _keep_markers(meta, parts.markers)
            files.write_meta(meta)
            console.say(f"resuming {files.folder} after {len(runner.log)} attempts")
            return _drive(runner, files, meta, console, lsl_wait)


def session_seed(study_seed: int, k: int) -> int:
    """Session seed of participant ``k`` (1-based) of a simulated study."""
    return int(np.random.SeedSequence([study_seed, k]).generate_state(1, np.uint32)[0])


@contextmanager
def _device_spec(spec: str, speed: float = 1.0, log: Path | None = None) -> Iterator[str]:
    """``serial:emulator`` starts a device emulator on a pty for the run, paced at ``speed``
    × real time; what it says (faults, the watchdog's timing) goes to ``log``."""
    if spec != "serial:emulator":
        yield spec
        return
    if log is not None:
        log.parent.mkdir(parents=True, exist_ok=True)
    with open(log if log is not None else os.devnull, "w") as err:
        proc = subprocess.Popen([sys.executable, "-m", "app", "device", "emulate", "--speed",
                                 repr(float(speed))],
                                stdout=subprocess.PIPE, stderr=err, text=True)
    try:
        port = proc.stdout.readline().strip()
        if not port:
            raise UsageError("the device emulator did not start"
                             + (f" (its log: {log})" if log is not None else ""))
        yield f"serial:{port}"
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def simulate_study(protocol: str | Path, participants: int, *, seed: int = 0,
                   data: str | Path = DEFAULT_SIM_DATA, device: str = "sim", speed: float = 1.0,
                   traces: str = "contacts", prefix: str = "sim", group: str = "",
                   clear_fault: bool = False,
                   progress: Callable[[str], None] | None = _err) -> StudyResult:
    """Simulated participants' sessions, headless, through the same path as a real session.

    Participant k (1-based) of a study with seed S gets the id ``PREFIXkk`` and the session
    seed ``SeedSequence([S, k])``, so a study is reproduced from S alone; in a protocol whose
    blocks are Williams-counterbalanced, participant k takes row (k − 1) mod the number of
    rows, so every order is used equally often.

    Parameters
    ----------
    protocol : str or Path
    participants : int
    seed : int
        Study seed.
    data : path
        Default ``sim-data``: simulated sessions never land beside people's.
    device : str
        ``sim``, ``sim:RATE``, ``serial:PORT`` or ``serial:emulator`` (paced by ``speed``).
    speed : float
        ``serial:emulator`` only: device seconds per wall second (≤ 20).
    traces, prefix, group
        As :func:`run_session` (ids are PREFIX01, PREFIX02, …).
    clear_fault : bool
        Clear a fault the device latched before the first session (the operator's decision).
    progress : callable, optional
        Called with a line after each participant.

    Returns
    -------
    StudyResult
        The sessions in order; it stops at the first session that does not complete.
    """
    if not isinstance(participants, int) or participants < 1:
        raise UsageError(f"participants must be at least 1, got {participants!r}")
    if not isinstance(seed, int) or seed < 0:
        raise UsageError(f"seed must be an integer >= 0, got {seed!r}")
    if not (isinstance(speed, (int, float)) and math.isfinite(speed) and 0 < speed <= 20):
        raise UsageError(f"speed must be in (0, 20] (device seconds per wall second), got "
                         f"{speed!r}")
    from protocols import SessionEngine, load_protocol

    proto = load_protocol(protocol)
    williams = [p for p in proto.phases if p.block_order == "williams"]
    rows = len(SessionEngine(proto, 0, "x", 0).williams_rows(williams[0])) if williams else 0
    t0 = time.perf_counter()
    out: list[SessionResult] = []
    with _device_spec(device, speed, Path(data) / "emulator.log") as spec:
        for k in range(1, participants + 1):
            # a Williams-counterbalanced protocol: participant k takes row (k − 1) mod rows
            r = run_session(protocol, f"{prefix}{k:02d}", device=spec, data=data,
                            responder="simulated", seed=session_seed(seed, k), group=group,
                            traces=traces, audio=False, quiet=True, operator_keys=False,
                            row=(k - 1) % rows if rows else None,
                            clear_fault=clear_fault and k == 1)
            out.append(r)
            if r.status != SessionStatus.COMPLETE:
                break
            if progress is not None:
                progress(f"  {protocol}: participant {k}/{participants} done "
                         f"({time.perf_counter() - t0:.0f} s)")
    return StudyResult(out, time.perf_counter() - t0)


def validate_protocol(protocol: str | Path, *, device: str | None = None,
                      clear_fault: bool = False) -> dict:
    """Check a protocol file, and with ``device`` its forces, currents and rendering against
    that device (``hapticlab protocol validate``).

    Parameters
    ----------
    protocol : str or path
        A built-in name or a protocol file.
    device : str, optional
        A device spec (``sim``, ``serial:PORT``): opened once, to read what it can render
        and which transient libraries it has.
    clear_fault : bool
        Clear a fault the device latched before (the operator's decision).

    Returns
    -------
    dict
        ``protocol``, ``source``, ``samples``, ``phases``, ``trials`` (the engine's plan,
        without redraws), ``device`` (the spec or None), ``libraries`` (what was found or
        will be built, in words, or ""), ``warnings`` (what the device renders otherwise
        than asked) and ``notes`` (texts left in English).

    Raises
    ------
    ProtocolError
        Naming the file, line and key of the first problem.
    """
    from protocols import SessionEngine, load_protocol
    from protocols.texts import english_note

    info, found, warnings, libraries = None, {}, [], ""
    if device:
        from app.libraries import prepare_libraries
        from app.preflight import rendering_notes

        with _session_device(device, 0, person=False, clear_fault=clear_fault, lsl=False,
                             say=_err) as dev:
            info = dev.info
            p = load_protocol(protocol, device=info)
            sim = info.backend == "sim"
            found = prepare_libraries(p, dev, device, build=False, ref=str(protocol)) \
                if not sim else {}
        if sim and any(s.scene.kind == "library" for s in p.samples.values()):
            libraries = "matched samples: a missing library is built on first use (simulated)"
        elif found:
            libraries = f"libraries found for {', '.join(sorted(found))}"
        warnings = list(rendering_notes(p, info))
    else:
        p = load_protocol(protocol)
    # the engine's own plan (any seed and counterbalance row plan as many trials)
    williams = any(ph.block_order == "williams" for ph in p.phases)
    trials = len(SessionEngine(p, 0, "validate", 0 if williams else None).plan())
    note = english_note(p)
    return {"protocol": p.name, "source": p.source, "samples": len(p.samples),
            "phases": len(p.phases), "trials": trials, "device": device,
            "libraries": libraries, "warnings": warnings, "notes": [note] if note else []}


def power(protocol: str | Path, *, subjects, reps, effect: float = 1.0, alpha: float = 0.05,
          experiments: int = 10_000, sd_trial: float | None = None,
          sd_interaction: float = 0.5, sd_subject: float = 0.8,
          pilot: str | Path | None = None) -> dict:
    """Power of a paired difference and precision of a sample's mean against participants
    and repetitions, for the last analysed rating phase of ``protocol``, by Monte-Carlo
    (``hapticlab power``; :func:`analysis.power.power_table`).

    Parameters
    ----------
    protocol : str or path
        A built-in name or a protocol file.
    subjects, reps : sequence of int
        Participant counts (at least 2) and repetitions per cell (at least 1).
    effect : float
        The key contrast [scale points].
    alpha : float
        Significance level, Bonferroni-divided over every pair of the phase's samples.
    experiments : int
        Simulated experiments per cell.
    sd_trial, sd_interaction, sd_subject : float
        The SDs [scale points] of trial noise (default 0.9), participant × sample and
        participant; with ``pilot`` estimated from its ratings instead.
    pilot : path, optional
        A folder of pilot sessions of this protocol.

    Returns
    -------
    dict
        ``protocol``, ``phase``, ``comparisons``, ``sd`` (the three SDs used) and
        ``table`` (DataFrame: ``subjects``, ``reps``, ``power``, ``ci_halfwidth``).

    Raises
    ------
    UsageError
        Too few subjects or repetitions, a protocol without an analysed rating phase, or
        pilot data without its ratings (each named).
    """
    from analysis.power import power_table, variance_components
    from protocols import load_protocol

    subjects, reps = list(subjects), list(reps)
    if not subjects or min(subjects) < 2 or not reps or min(reps) < 1:
        raise UsageError("need at least 2 subjects and 1 repetition")
    p = load_protocol(protocol)
    rated = [ph for ph in p.phases if ph.design.analysed and ph.design.dv == "rating"]
    if not rated:
        raise UsageError(f"power: protocol {p.name!r} has no analysed rating phase; "
                         "power and precision are computed for rating studies")
    phase = rated[-1]
    comparisons = math.comb(len(phase.samples), 2)
    sd = {"sd_trial": 0.9 if sd_trial is None else sd_trial,
          "sd_interaction": sd_interaction, "sd_subject": sd_subject}
    if pilot:
        from analysis import LoadError, load_sessions

        try:
            d = load_sessions(pilot)
        except LoadError as exc:
            raise UsageError(str(exc)) from None
        # the phase the protocol's design analyses (a practice phase is a first look)
        d = d[d["valid"] & d["rating"].notna() & (d["protocol"] == p.name)
              & (d["phase"] == phase.name)]
        if d.empty:
            raise UsageError(f"--pilot {pilot}: no valid ratings of {p.name!r} "
                             f"in phase {phase.name!r}")
        try:
            sd = variance_components(d, sd_trial=sd_trial)
        except ValueError as exc:
            raise UsageError(f"--pilot {pilot}: {exc}") from None
    table = power_table(subjects, reps, effect, alpha=alpha, comparisons=comparisons,
                        experiments=experiments, **sd)
    return {"protocol": p.name, "phase": phase.name, "comparisons": comparisons, "sd": sd,
            "table": table}


def preflight_line(protocol: str | Path, *, device: str, data: str | Path, responder: str,
                   traces: str, audio: bool) -> str:
    """The preflight's command line again, clearing the device's latched fault (quoted for
    a shell: a folder may hold a space)."""
    import shlex

    return shlex.join(["hapticlab", "preflight", str(protocol), "--device", device,
                       "--data", str(data), "--responder", responder, "--traces", traces,
                       *([] if audio else ["--no-audio"]), "--clear-fault"])


def preflight(protocol: str | Path, *, device: str, data: str | Path = "data",
              responder: str = "person", traces: str = "full", audio: bool = True,
              clear_fault: bool = False) -> list:
    """Every check a session makes before it starts (``hapticlab preflight``), each a
    :class:`app.preflight.Check` with its line and, when it fails, what to do.

    Parameters
    ----------
    protocol : str or path
        A built-in name or a protocol file.
    device : str
        The device spec the session will open.
    data : path
        The data folder (room for a session, writable).
    responder : str
        ``person`` also checks the terminal and the display.
    traces : str
        The traces the session will record (its size estimate).
    audio : bool
        Check (and play) the sound.
    clear_fault : bool
        Clear a fault the device latched before (the operator's decision); a failed
        device check suggests the command again with it.
    """
    from app.preflight import (
        Check,
        check_answers,
        check_audio,
        check_data_folder,
        check_device,
        check_display,
        check_libraries,
        check_limit,
        check_protocol_on,
        check_terminal,
        expected_session_bytes,
    )
    from device import DeviceError
    from protocols import parse_protocol, protocol_text
    from protocols.texts import english_note

    source, text = protocol_text(protocol)
    proto = parse_protocol(text, source)
    checks = [Check("protocol", True, f"{source}: '{proto.name}' ({proto.sha256[:12]}…)"),
              check_data_folder(data, expected_session_bytes(proto, traces)),
              check_answers(proto)]
    if note := english_note(proto):
        checks.append(Check("texts", True, note))
    if responder == "person":
        checks += [check_terminal(), check_display()]
    again = preflight_line(protocol, device=device, data=data, responder=responder,
                           traces=traces, audio=audio)
    try:
        with _session_device(device, 0, person=False, clear_fault=clear_fault, lsl=False,
                             say=_err) as dev:
            checks += [check_device(dev, device, again), check_protocol_on(text, source, dev),
                       check_limit(proto, dev),
                       check_libraries(proto, dev, device, protocol)]
    except DeviceError as exc:
        checks.append(Check("device", False, str(exc), "check the cable, the port and the "
                            "power"))
    checks.append(check_audio(audio, play=audio))
    return checks


def saturation_forecast(protocol: str | Path, *, device: str, windows: int = 12,
                        warn: float = 0.2, clear_fault: bool = False) -> dict:
    """How often each sample of ``protocol`` will saturate ``device``'s drive, from a
    simulated tapper (0.11 ± 0.033 m/s) over ``windows`` windows per sample (``hapticlab
    device check``; :func:`app.saturation_forecast.saturation_check`).

    Returns
    -------
    dict
        ``protocol`` (its name), ``device`` (the spec), ``info`` (the device's
        :class:`~device.DeviceInfo`) and ``rows`` (per sample: ``tap_rate``,
        ``trial_rate``, ``warning`` — above ``warn`` of trials —, or ``error``).
    """
    from app.saturation_forecast import saturation_check
    from protocols import load_protocol

    p = load_protocol(protocol)
    with _session_device(device, 0, person=False, clear_fault=clear_fault, lsl=False,
                         say=_err) as dev:
        info = dev.info
    rows = saturation_check(p, info, windows=windows, warn=warn, say=_err)
    return {"protocol": p.name, "device": device, "info": info, "rows": rows}


#: seconds per trial besides tapping (the operator swaps the block, the participant answers):
#: a rule of thumb for the estimate :func:`protocol_plan` gives; a lab measures its own
OVERHEAD_S = 20.0


def device_selftest(spec: str, *, clear_fault: bool = False,
                    say: Callable[[str], None] | None = None) -> dict:
    """The backend-independent checks (:mod:`device.suite`) against the device at ``spec``.

    The device is opened once first, so a bad spec or an absent device is one named error
    before any check runs (and a fault latched before is cleared there, with
    ``clear_fault``); each check then opens it afresh.

    Returns
    -------
    dict
        ``spec``, ``checks`` (each ``name``, ``ok``, ``detail``), ``passed``, ``failed``.
    """
    from device.suite import run_selftest

    open_device_for(spec, clear_fault=clear_fault, say=say).close()
    return run_selftest(spec, lambda: open_device_for(spec))


def device_list() -> dict:
    """The registered backends, the serial ports this computer has and the simulated
    device, without opening any port (opening one can reset a board).

    Returns
    -------
    dict
        ``backends`` (names), ``ports`` (each ``spec``, ``description``, ``hwid``, sorted by
        port) and ``simulated`` (each ``spec``, ``description``).
    """
    from serial.tools import list_ports

    from device import backends

    ports = [{"spec": f"serial:{p.device}", "description": p.description or "",
              "hwid": p.hwid or ""} for p in sorted(list_ports.comports(), key=lambda p: p.device)]
    return {"backends": list(backends()), "ports": ports,
            "simulated": [{"spec": "sim", "description": "the simulated device (no hardware)"}]}


#: what ``emulate`` can serve the wire protocol with, and the servo rate each runs at [Hz]
#: (None: the Python emulator's ``rate``)
EMULATORS = {"python": None, "host": 10_000.0, "host-board": 10_000.0, "host-san": 10_000.0,
             "qemu": 10_000.0, "dhd-stub": 4_000.0, "hd-stub": 1_000.0,
             "hd-stub-tsan": 1_000.0}


def emulate(firmware: str = "python", *, rate: float | None = None, seed: int = 0,
            speed: float = 1.0) -> int:
    """Serve protocol 2 on a new pseudo-terminal until SIGINT or SIGTERM, printing the
    port's path first; the exit status.

    Parameters
    ----------
    firmware : str
        One of :data:`EMULATORS`: the Python emulator, the C firmware built for this
        machine (``host``, ``host-board``, ``host-san``), under QEMU (``qemu``), or a bridge
        over a commercial SDK's stand-in (``dhd-stub``, ``hd-stub``, ``hd-stub-tsan``).
    rate : float, optional
        The Python emulator's servo rate [Hz], 1,000–20,000 (default 10,000); a build runs
        at its own (:data:`EMULATORS`), and refuses one given.
    seed : int
        Seed of the simulated plant and tapping.
    speed : float
        Device seconds per wall second, in (0, 20]; 1 for QEMU and the OpenHaptics bridge.

    Raises
    ------
    UsageError
        An option this emulator cannot honour, named.
    """
    if firmware not in EMULATORS:
        raise UsageError(f"no emulator named {firmware!r}; one of {', '.join(EMULATORS)}")
    if not 0 < speed <= 20:
        raise UsageError(f"--speed must be in (0, 20] (device seconds per wall second), "
                         f"got {speed:g}")
    if firmware != "python":
        from device.serial.firmware import REAL_TIME_ONLY, serve

        if rate is not None:
            raise UsageError(f"the firmware's servo runs at its build's own rate "
                             f"({EMULATORS[firmware]:,.0f} Hz for {firmware}): --rate applies "
                             "to --firmware python only")
        if firmware == "qemu" and speed != 1.0:
            raise UsageError("the firmware under QEMU runs at the pace of its counted "
                             "instructions and its sleeps: --speed applies to "
                             "--firmware python, host, host-board, host-san and dhd-stub")
        if firmware in REAL_TIME_ONLY and speed != 1.0:
            raise UsageError(f"--firmware {firmware} runs in real time, in the HD "
                             "scheduler's clock: --speed must be 1")
        return serve(firmware, seed, speed)
    from device.serial.emulator import main as serve_python

    rate = 10_000.0 if rate is None else rate
    if not 1_000 <= rate <= 20_000:
        raise UsageError(f"--rate must be 1,000–20,000 Hz, got {rate:g}")
    return serve_python(rate, seed, speed)


#: the benchmarks (``hapticlab bench WHAT``), each a module of ``benchmarks/``
BENCHMARKS = ("sim", "accuracy", "matching", "link", "crash", "analysis", "demo", "energy",
              "orderings", "causes", "factorial", "tick")
#: the benchmarks' options and their defaults (each benchmark reads those it uses; the
#: CLI's ``bench --help`` says which)
BENCH_OPTIONS = {"json": False, "repeats": 5, "fuzz": 100_000, "kills": 1000, "points": None,
                 "seeds": None, "firmware": None, "load": None, "targets": None,
                 "seconds": 60.0, "baseline": False, "no_window": False}


def benchmark(what: str, **options) -> int:
    """Run benchmark ``what`` (one of :data:`BENCHMARKS`), which prints its table (JSON
    rows with ``json=True``) with ratios against a baseline run in the same process; its
    exit status.

    Raises
    ------
    UsageError
        No such benchmark, an option not in :data:`BENCH_OPTIONS`, a bad value of one, or
        one the benchmark does not read (:func:`benchmarks._options.check_options`).
    """
    import argparse
    import importlib

    if what not in BENCHMARKS:
        raise UsageError(f"no benchmark named {what!r}; available: {', '.join(BENCHMARKS)}")
    from benchmarks._options import check_options

    options = check_options(what, options, BENCH_OPTIONS)  # every value, before anything runs
    module = importlib.import_module(f"benchmarks.{what}")
    return module.main(argparse.Namespace(what=what, **options))


def protocol_plan(protocol: str | Path, *, seed: int, participant: str = "P00",
                  row: int | None = None) -> dict:
    """The trials a session of ``protocol`` with this seed runs, in order, without redraws
    (``hapticlab protocol show``; plain data, as its ``--json`` prints it).

    Parameters
    ----------
    protocol : str or path
        A built-in name or a protocol file.
    seed : int
        The session seed.
    participant : str
        Participant id.
    row : int, optional
        Counterbalance row, for Williams-ordered blocks.

    Returns
    -------
    dict
        ``protocol``, ``title``, ``source``, ``sha256``, ``seed``, ``participant``,
        ``phases`` (each its ``name``, ``no_repeat`` and ``trials``: sample or surfaces,
        item key, placement, block), ``design`` and ``duration_estimate`` (``windows``,
        ``window_s``, ``tapping_s`` [s], ``overhead_per_trial_s`` [s] and ``total_s`` [s]).
    """
    from protocols import SessionEngine, load_protocol

    p = load_protocol(protocol)
    engine = SessionEngine(p, seed, participant, row)
    phases: list[dict] = []
    no_repeat = {ph.name: ph.no_repeat for ph in p.phases}
    for item, place in zip(engine.plan(), engine.placements(), strict=True):
        if not phases or phases[-1]["name"] != item.phase:
            phases.append({"name": item.phase, "no_repeat": no_repeat[item.phase],
                           "trials": []})
        trial = {"sample": item.samples[0] if len(item.samples) == 1 else list(item.samples),
                 "item": item.key, "placement": place}
        if item.block is not None:
            trial["block"] = item.block
        phases[-1]["trials"].append(trial)
    n = sum(len(ph["trials"]) for ph in phases)
    windows = sum(len(t["sample"]) if isinstance(t["sample"], list) else 1
                  for ph in phases for t in ph["trials"])
    tapping = windows * p.window.duration
    return {"protocol": p.name, "title": p.title, "source": p.source, "sha256": p.sha256,
            "seed": seed, "participant": participant, "phases": phases, "design": p.design(),
            "duration_estimate": {"windows": windows, "window_s": p.window.duration,
                                  "tapping_s": tapping, "overhead_per_trial_s": OVERHEAD_S,
                                  "total_s": tapping + n * OVERHEAD_S}}


def export(data: str | Path, out: str | Path, fmt: str = "long-csv", **selection) -> list[Path]:
    """The analysed trials as files for JASP, SPSS or R (:func:`analysis.export.export`);
    its errors come back as :class:`~app.errors.AnalysisError`.

    Returns
    -------
    list of Path
        The files written, ``codebook.csv`` last.
    """
    from analysis import LoadError, StatsError
    from analysis.export import FORMATS
    from analysis.export import export as _export

    if fmt not in FORMATS:
        raise UsageError(f"formats are {', '.join(FORMATS)}; got {fmt!r}")
    try:
        return _export(data, out, fmt, **selection)
    except (LoadError, StatsError) as exc:
        raise AnalysisError(str(exc)) from None
    except OSError as exc:
        from app.errors import io_error

        raise io_error(exc, "cannot write the export") from None


def analyze(data: str | Path, out: str | Path, *, formats=("html", "md", "json"),
            protocol: str | list[str] | None = None, kind: str | None = None,
            status: str = "complete", participants: list[str] | None = None,
            since: str | None = None, until: str | None = None,
            drop_invalid: bool = False, ids: str = "check", sim_device: bool = False) -> dict:
    """Select sessions, run the analyses their designs call for, write the report.

    Parameters are those of :func:`analysis.report.analyze`; its errors come back as
    :class:`~app.errors.AnalysisError`.

    Returns
    -------
    dict
        The report's content (report.json).
    """
    from analysis import LoadError, StatsError
    from analysis.report import analyze as _analyze

    bad = set(formats) - {"html", "md", "json"}
    if bad:
        raise UsageError(f"formats are html, md, json; got {sorted(bad)}")
    try:
        return _analyze(data, out, tuple(formats), protocol=protocol, kind=kind, status=status,
                        participants=participants, since=since, until=until,
                        drop_invalid=drop_invalid, ids=ids, sim_device=sim_device)
    except (LoadError, StatsError) as exc:
        raise AnalysisError(str(exc)) from None
    except OSError as exc:
        from app.errors import io_error

        raise io_error(exc, "cannot write the report") from None
