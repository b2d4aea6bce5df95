"""The API's sessions: run, resume and simulate them, and check before one starts
(``hapticlab run``, ``resume``, ``simulate``, ``preflight``)."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from analysis.session_format import SessionStatus

from ..errors import SessionFileError, UsageError
from ._new_session import (
    KIND_OF,
    check_before_opening,
    check_speed,
    checked_request,
    participant_info,
    ready_on,
    record_and_run,
    say_earlier_sessions,
)
from ._say import to_stderr
from ._session import apply_limit, check_rows, drive, keep_markers, session_parts
from .devices import session_device
from .results import SessionResult, StudyResult

__all__ = ["KIND_OF", "DEFAULT_SIM_DATA", "run_session", "resume_session", "session_seed",
           "simulate_study", "preflight", "preflight_line"]

#: where simulated studies go unless told otherwise (never beside people's data)
DEFAULT_SIM_DATA = "sim-data"


def run_session(protocol: str | Path, participant: str, *, device: str,
                data: str | Path = "data", responder: str = "person", seed: int | None = None,
                row: int | None = None, group: str = "", traces: str = "full",
                audio: bool = True, fullscreen: bool = False, quiet: bool = False,
                operator_keys: bool | None = None, clear_fault: bool = False,
                info_fields: dict | None = None, new_session: bool = False,
                say: Callable[[str], None] | None = None, lsl: bool = False,
                lsl_wait: float = 300.0, discrimination: dict | None = None,
                speed: float = 1.0) -> SessionResult:
    """Run one session to the end (or until it is stopped) and record it.

    The request is checked, the participant's earlier sessions said, the data folder and
    the screens checked before the device opens; then the device is made ready, the
    participant's details asked, and the session recorded and run (each step a function of
    :mod:`app.api._new_session`, in that order).

    Parameters
    ----------
    protocol : str or Path
        A built-in protocol's name (one of :data:`protocols.BUILTIN`) or a protocol file.
    participant : str
        Participant id (letters, digits, ``_``, ``-``; at most 32).
    device : str
        Device spec of any registered backend: ``sim``, ``sim:RATE``, ``serial:PORT``,
        ``emulator``, ... (``hapticlab device list``).
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
    discrimination : dict, optional
        ``responder="simulated"``: measured JNDs the simulated participant draws its own
        around (:func:`simulate_study`).
    speed : float
        Device seconds per wall second where the device's clock is paced (an emulator: a
        simulated study run faster than real time), in (0, 20]; 1 for a person. Recorded in
        session.json (``device.speed``): a resume runs at it.

    Returns
    -------
    SessionResult
    """
    from app.console import make_console

    console = make_console(quiet=quiet)
    say = say or console.say
    s = checked_request(protocol, participant, device=device, data=data, responder=responder,
                        seed=seed, row=row, group=group, traces=traces,
                        operator_keys=operator_keys, audio=audio, fullscreen=fullscreen,
                        quiet=quiet, lsl=lsl, lsl_wait=lsl_wait,
                        discrimination=discrimination, speed=speed)
    say_earlier_sessions(s, new_session, say)
    check_before_opening(s)
    with session_device(device, s.seed, s.person, clear_fault, lsl, say, s.speed) as dev:
        limits, libraries = ready_on(s, dev, say)
        info = participant_info(s, info_fields)
        return record_and_run(s, dev, console, say, limits=limits, libraries=libraries,
                              info=info)


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
        It is opened at the speed the session recorded (an emulator's ``--speed``; 1 for a
        file that predates the record).
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
    check_rows(files, meta, rows)
    responder = meta.responder or "scripted"
    if responder not in KIND_OF:
        responder = "person" if meta.ui == "psychopy" else "scripted"
    spec = device or meta.device_spec
    try:  # the pace it was opened at (1 in a file that predates the key)
        speed = check_speed(meta.device.get("speed", 1.0))
    except UsageError as exc:
        raise SessionFileError(f"{files.meta}: device.speed: {exc}") from None
    with session_device(spec, meta.seed, responder == "person", clear_fault, lsl,
                         console.say, speed) as dev:
        limits = apply_limit(proto, dev, (meta.limits or {}).get("current_limit_a"))
        check_recorded(meta.libraries, dev)
        keys = operator_keys if operator_keys is not None else responder == "person"
        with session_parts(dev, proto, responder=responder, seed=meta.seed,
                            group=p.group, fullscreen=fullscreen,
                            audio=meta.audio if audio is None else audio,
                            keys=keys, quiet=quiet, console=console, lsl=lsl,
                            participant=p.id, say=console.say,
                            discrimination=meta.discrimination) as parts:
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
            keep_markers(meta, parts.markers)
            files.write_meta(meta)
            console.say(f"resuming {files.folder} after {len(runner.log)} attempts")
            return drive(runner, files, meta, console, lsl_wait)


def session_seed(study_seed: int, k: int) -> int:
    """Session seed of participant ``k`` (1-based) of a simulated study."""
    return int(np.random.SeedSequence([study_seed, k]).generate_state(1, np.uint32)[0])


def simulate_study(protocol: str | Path, participants: int, *, seed: int = 0,
                   data: str | Path = DEFAULT_SIM_DATA, device: str = "sim", speed: float = 1.0,
                   traces: str = "contacts", prefix: str = "sim", group: str = "",
                   clear_fault: bool = False,
                   progress: Callable[[str], None] | None = to_stderr,
                   discrimination: dict | None = None) -> StudyResult:
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
        Any device spec: ``sim``, ``sim:RATE``, ``emulator``, ``emulator:BUILD`` (each
        session starts its own, seeded with the session's seed), ``serial:PORT``.
    speed : float
        Device seconds per wall second where the device's clock is paced (an emulator),
        ≤ 20; a simulated device in virtual time runs as fast as it can whatever it is.
    traces, prefix, group
        As :func:`run_session` (ids are PREFIX01, PREFIX02, …).
    clear_fault : bool
        Clear a fault the device latched before the first session (the operator's decision).
    progress : callable, optional
        Called with a line after each participant.
    discrimination : dict, optional
        Measured JNDs, Weber fractions at 75 % correct by transient parameter (what
        :func:`app.observer.discrimination_from_report` reads from a report): each
        simulated participant draws its own around them instead of the assumed ones, and
        its session.json records them.

    Returns
    -------
    StudyResult
        The sessions in order; it stops at the first session that does not complete.
    """
    if not isinstance(participants, int) or participants < 1:
        raise UsageError(f"participants must be at least 1, got {participants!r}")
    if not isinstance(seed, int) or seed < 0:
        raise UsageError(f"seed must be an integer >= 0, got {seed!r}")
    check_speed(speed)
    from protocols import SessionEngine, load_protocol

    proto = load_protocol(protocol)
    williams = [p for p in proto.phases if p.block_order == "williams"]
    rows = len(SessionEngine(proto, 0, "x", 0).williams_rows(williams[0])) if williams else 0
    t0 = time.perf_counter()
    out: list[SessionResult] = []
    for k in range(1, participants + 1):
        # a Williams-counterbalanced protocol: participant k takes row (k − 1) mod rows
        r = run_session(protocol, f"{prefix}{k:02d}", device=device, data=data,
                        responder="simulated", seed=session_seed(seed, k), group=group,
                        traces=traces, audio=False, quiet=True, operator_keys=False,
                        row=(k - 1) % rows if rows else None,
                        clear_fault=clear_fault and k == 1, discrimination=discrimination,
                        speed=speed)
        out.append(r)
        if r.status != SessionStatus.COMPLETE:
            break
        if progress is not None:
            progress(f"  {protocol}: participant {k}/{participants} done "
                     f"({time.perf_counter() - t0:.0f} s)")
    return StudyResult(out, time.perf_counter() - t0)


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
        with session_device(device, 0, person=False, clear_fault=clear_fault, lsl=False,
                             say=to_stderr) as dev:
            checks += [check_device(dev, device, again), check_protocol_on(text, source, dev),
                       check_limit(proto, dev),
                       check_libraries(proto, dev, device, protocol)]
    except DeviceError as exc:
        checks.append(Check("device", False, str(exc), "check the cable, the port and the "
                            "power"))
    checks.append(check_audio(audio, play=audio))
    return checks
