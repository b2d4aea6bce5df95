"""``hapticlab run`` and ``hapticlab resume``."""

from __future__ import annotations

import argparse
import signal
from pathlib import Path

__all__ = ["run", "resume"]


class _Stop(Exception):
    pass


def _open(spec: str, seed: int):
    from device import open_device

    if spec == "sim" or spec.startswith("sim:"):
        return open_device(spec, seed=seed)
    return open_device(spec)


def _participant_ui(kind: str, responder: str, protocol, fullscreen: bool = False,
                    seed: int = 0, group: str = ""):
    from app.participants import make_participant

    if kind == "none":
        return make_participant(responder, protocol, seed, group)
    if kind == "psychopy":
        from app.screen import PsychoPyScreen

        return PsychoPyScreen(protocol, fullscreen=fullscreen)
    raise ValueError(f"--ui must be psychopy or none, got {kind!r}")


def _audio(args, device_spec: str, console):
    if args.no_audio:
        return None
    from app.audio import Audio, AudioUnavailable

    try:
        return Audio()
    except AudioUnavailable as exc:
        if device_spec.startswith("serial:"):
            raise ValueError(f"no audio device ({exc}): a real session needs masking noise and "
                             "the tap cue; fix the audio or pass --no-audio") from None
        console.say(f"warning: no audio ({exc}); dry run continues without sound")
        return None


def _finish(files, meta, runner, outcome: str, console) -> int:
    from app.runner import utc_now

    meta["times"]["finished_utc"] = utc_now() if outcome == "complete" else None
    meta["status"] = outcome
    dev = runner.device
    if hasattr(dev, "link_stats"):
        meta["link"] = dev.link_stats()
    if runner.timing:  # live pacing (the simulator in live mode): achieved servo rate
        rates = [t["achieved_rate_hz"] for t in runner.timing]
        meta["timing"] = {"achieved_rate_hz_median": float(sorted(rates)[len(rates) // 2]),
                          "lateness_p99_s_max": max(t["lateness_p99_s"] for t in runner.timing)}
    meta["participant"]["debrief"] = getattr(runner.participant_ui, "debrief", lambda: "")()
    files.write_meta(meta)
    return 0


def _drive(runner, files, meta, console) -> int:
    from app.runner import SessionInterrupted

    def on_term(signum, frame):
        raise _Stop(f"signal {signum}")

    prev = signal.signal(signal.SIGTERM, on_term)
    try:
        outcome = runner.run()
    except SessionInterrupted as exc:
        meta["status"] = "interrupted"
        meta.setdefault("interruptions", []).append(str(exc))
        files.write_meta(meta)
        console.say(f"session interrupted: {exc}\nresume with: hapticlab resume {files.folder}")
        return 3
    except (KeyboardInterrupt, _Stop) as exc:
        meta["status"] = "interrupted"
        meta.setdefault("interruptions", []).append(f"stopped ({type(exc).__name__})")
        files.write_meta(meta)
        console.say(f"stopped; everything recorded is saved. resume with: hapticlab resume "
                    f"{files.folder}")
        return 130
    finally:
        signal.signal(signal.SIGTERM, prev)
    _finish(files, meta, runner, outcome, console)
    n = len(runner.log)
    print(f"session complete: {files.folder} ({n} attempts)")
    return 0


def run(args: argparse.Namespace) -> int:
    from app.console import make_console
    from app.ids import validate_participant
    from app.recorder import SessionFiles, new_session_dir
    from app.runner import SessionRunner, session_meta
    from protocols import SessionEngine, load_protocol, seed_from_entropy

    participant = validate_participant(args.participant)
    protocol = load_protocol(args.protocol)
    seed = args.seed if args.seed is not None else seed_from_entropy()
    if seed < 0:
        raise ValueError(f"--seed must be >= 0, got {seed}")
    console = make_console(quiet=args.quiet)
    engine = SessionEngine(protocol, seed, participant, args.row)
    ui = _participant_ui(args.ui, args.responder, protocol, args.fullscreen, seed, args.group)
    audio = _audio(args, args.device, console)
    with _open(args.device, seed) as dev:
        if args.ui == "psychopy":  # an operator is at the terminal: ready, pause, e-stop keys
            console = make_console("keys", args.quiet, dev)
        folder, n = new_session_dir(Path(args.data), participant)
        files = SessionFiles(folder)
        meta = session_meta(protocol, args.protocol, participant, n, seed, args.row, dev,
                            args.device, args.ui, args.responder, audio is not None, args.group)
        meta["traces_mode"] = args.traces
        files.write_meta(meta)
        console.say(f"session {folder} (seed {seed})")
        runner = SessionRunner(protocol, engine, dev, files, ui, participant, n, seed, console,
                               audio, args.traces)
        try:
            return _drive(runner, files, meta, console)
        finally:
            for part in (ui, audio, console):
                if part is not None and hasattr(part, "close"):
                    part.close()


def resume(args: argparse.Namespace) -> int:
    from app.console import make_console
    from app.recorder import SessionFiles
    from app.runner import SessionRunner, utc_now
    from protocols import LogMismatch, ResumeMismatch, SessionEngine, load_protocol

    files = SessionFiles(Path(args.session_dir))
    meta = files.read_meta()
    console = make_console(quiet=args.quiet)
    if meta.get("status") == "complete":
        print(f"{files.folder}: the session is already complete")
        return 0
    protocol = load_protocol(meta["protocol"]["ref"])
    if protocol.sha256 != meta["protocol"]["sha256"]:
        raise ResumeMismatch(f"cannot resume: {meta['protocol']['ref']} changed since the session "
                             f"started (sha256 {meta['protocol']['sha256'][:12]}… then, "
                             f"{protocol.sha256[:12]}… now)")
    p = meta["participant"]
    engine = SessionEngine(protocol, meta["seed"], p["id"], p.get("counterbalance_row"))
    engine.check_resume({"protocol_sha256": meta["protocol"]["sha256"], "seed": meta["seed"],
                         "participant": p["id"],
                         "counterbalance_row": p.get("counterbalance_row")})
    torn = files.set_aside_torn()
    if torn is not None:
        console.say(f"set aside a torn last line of trials.tsv (line {torn.line}, kept in "
                    "trials.torn.tsv): the attempt it belonged to will run again")
    spec = args.device or meta["device"]["spec"]
    ui_kind = args.ui or meta["ui"]
    ui = _participant_ui(ui_kind, meta["responder"], protocol, False, meta["seed"],
                         meta.get("participant", {}).get("group", ""))
    audio = _audio(args, spec, console) if meta.get("audio") else None
    with _open(spec, meta["seed"]) as dev:
        if args.clear_fault and dev.fault is not None:
            console.say(f"clearing the latched {dev.fault.code} fault (operator's decision)")
            dev.clear_fault()
        if ui_kind == "psychopy":
            console = make_console("keys", args.quiet, dev)
        runner = SessionRunner(protocol, engine, dev, files, ui, p["id"], meta["session"],
                               meta["seed"], console, audio, meta.get("traces_mode", "full"))
        runner.load_log()
        try:
            engine.next_trial(runner.log)
        except LogMismatch as exc:
            raise ValueError(f"{files.trials}: {exc}") from None
        meta["resumes"].append({"at_utc": utc_now(), "attempts_logged": len(runner.log),
                                "torn_line": None if torn is None else torn.line,
                                "device": spec})
        meta["status"] = "running"
        files.write_meta(meta)
        console.say(f"resuming {files.folder} after {len(runner.log)} attempts")
        try:
            return _drive(runner, files, meta, console)
        finally:
            for part in (ui, audio, console):
                if part is not None and hasattr(part, "close"):
                    part.close()


def add_parsers(sub, func_run, func_resume) -> None:
    r = sub.add_parser("run", help="run a session with a participant (or a scripted one)")
    r.add_argument("protocol", help="realism, factorial, identification, or a protocol file")
    r.add_argument("--participant", required=True, help="participant id, e.g. P01")
    r.add_argument("--device", default="sim", help="sim, sim:RATE or serial:PORT")
    r.add_argument("--seed", type=int, default=None, help="session seed (drawn and recorded "
                   "when not given)")
    r.add_argument("--data", default="data", help="data folder (default ./data)")
    r.add_argument("--ui", choices=("psychopy", "none"), default="psychopy")
    r.add_argument("--responder", default="scripted", help="participant for --ui none")
    r.add_argument("--no-audio", action="store_true", help="run without sound")
    r.add_argument("--row", type=int, default=None,
                   help="counterbalance row (Williams-ordered protocols)")
    r.add_argument("--traces", choices=("full", "contacts", "none"), default="full",
                   help="raw device streams kept per attempt")
    r.add_argument("--fullscreen", action="store_true")
    r.add_argument("--group", default="", help="participant group label, e.g. expert or novice")
    r.add_argument("--quiet", action="store_true")
    r.set_defaults(func=func_run)
    rs = sub.add_parser("resume", help="continue an interrupted session exactly where it stopped")
    rs.add_argument("session_dir")
    rs.add_argument("--device", default=None, help="override the recorded device spec")
    rs.add_argument("--ui", choices=("psychopy", "none"), default=None)
    rs.add_argument("--no-audio", action="store_true")
    rs.add_argument("--clear-fault", action="store_true",
                    help="clear a latched e-stop/watchdog fault first (when it is safe)")
    rs.add_argument("--quiet", action="store_true")
    rs.set_defaults(func=func_resume)



