"""The ``hapticlab`` command line: a thin layer over :mod:`app.api` and the packages.

Every :class:`~device.errors.HapticlabError` prints one line to stderr and exits 2, never a
traceback. Heavy modules are imported inside the command that needs them.

Size: about 700 lines on purpose. The argument parser of every command, with its help, is
one tree read (and generated into the reference) as a whole, and each command's handler is a
few lines over :mod:`app.api`; the library and identification commands have their own module
(:mod:`app.matching_cli`).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable, Sequence

from analysis.session_format import SessionStatus
from device.errors import HapticlabError
from protocols.loader import BUILTIN

from .errors import UsageError

__all__ = ["main", "build_parser"]


def _device_selftest(args: argparse.Namespace) -> int:
    from .api import device_selftest

    if not (math.isfinite(args.tap_wait) and args.tap_wait > 0):
        raise UsageError(f"--tap-wait must be a positive number of seconds, got "
                         f"{args.tap_wait:g}")
    # a bad spec or an absent device: one line, exit 2
    report = device_selftest(args.spec, clear_fault=args.clear_fault,
                             device_alone=args.device_alone, tap_wait_s=args.tap_wait)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        from rich.console import Console
        from rich.table import Table

        table = Table(title=f"device self-test: {args.spec}")
        table.add_column("check")
        table.add_column("result")
        table.add_column("detail")
        mark = {"passed": "[green]ok[/]", "failed": "[red]FAIL[/]",
                "not run": "[yellow]not run[/]"}
        for row in report["checks"]:
            table.add_row(row["name"], mark[row["status"]], row["detail"])
        Console().print(table)
        print(f"{report['passed']} passed, {report['failed']} failed"
              + (f", {report['not_run']} not run (they need someone to tap the stylus: run "
                 "without --device-alone)" if report["not_run"] else ""))
    return 0 if report["failed"] == 0 and report["not_run"] == 0 else 1


def _protocol_validate(args: argparse.Namespace) -> int:
    from .api import validate_protocol

    v = validate_protocol(args.file, device=args.device, clear_fault=args.clear_fault)
    print(f"{v['source']}: valid protocol '{v['protocol']}' — "
          f"{_plural(v['samples'], 'sample')}, {_plural(v['phases'], 'phase')}, "
          f"{'at most ' if v.get('adaptive') else ''}{_plural(v['trials'], 'trial')} "
          "without redraws"
          + (f"; checked against device '{v['device']}'"
             + (f"; {v['libraries']}" if v["libraries"] else "") if v["device"] else ""))
    for warning in v["warnings"]:
        print(f"warning: {warning}")
    for note in v["notes"]:
        print(f"note: {note}")
    return 0


def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def _protocol_show(args: argparse.Namespace) -> int:
    from .api import protocol_plan

    plan = protocol_plan(args.file, seed=args.seed, participant=args.participant, row=args.row)
    phases, estimate = plan["phases"], plan["duration_estimate"]
    n = sum(len(ph["trials"]) + ph.get("adaptive", {}).get("max_trials", 0) for ph in phases)
    windows, tapping = estimate["windows"], estimate["tapping_s"]
    if args.json:
        print(json.dumps(plan, indent=2))
        return 0
    print(f"{plan['title']} ({plan['source']}, sha256 {plan['sha256'][:12]}…), seed {args.seed}")
    most = "at most " if any("adaptive" in ph for ph in phases) else ""
    print(f"{most}{_plural(n, 'trial')}, {_plural(windows, 'tapping window')} of "
          f"{estimate['window_s']:g} s: ≈ {estimate['total_s'] / 60:.0f} min without redraws "
          f"({tapping / 60:.1f} min tapping + {estimate['overhead_per_trial_s']:g} s per trial "
          "to place and answer, "
          "a rule of thumb: time your own; reference taps and redrawn trials add to it)")
    for ph, design in zip(phases, plan["design"]["phases"], strict=False):
        what = {"none": "not analysed"}.get(design["role"], design["role"]) \
            if design["role"] != "analysed" else (
            f"analysed: {design['dv']}" + (f" over {' × '.join(design['within'])}"
                                           if design["within"] else "")
            + (f" per {design['by']}" if design["by"] else ""))
        if ph["no_repeat"]:
            what += "; never the same sample twice in a row"
        if "adaptive" in ph:
            a = ph["adaptive"]
            print(f"\n{ph['name']} (at most {_plural(a['max_trials'], 'trial')}, made from the "
                  f"answers; {what})\n       {a['parameter']} in {a['units']} units, tracks "
                  f"{', '.join(a['tracks'])} interleaved; place: a placeholder block, "
                  "swapped every trial (both renderings are virtual)")
            continue
        print(f"\n{ph['name']} ({_plural(len(ph['trials']), 'trial')}; {what})")
        previous = None
        for i, t in enumerate(ph["trials"], 1):
            s = t["sample"] if isinstance(t["sample"], str) else " / ".join(t["sample"])
            again = "  (the same sample again)" if s == previous else ""
            previous = s
            print(f"  {i:3d}  {s:<28} place: {t['placement'] or 'nothing'}{again}")
    return 0


def _device_list(args: argparse.Namespace) -> int:
    """Every registered backend's devices on this computer, without opening any port
    (opening one can reset a board)."""
    from .api import device_list

    found = device_list()
    if args.json:
        print(json.dumps(found, indent=2))
        return 0
    for d in found["devices"]:
        details = f"  [{d['details']}]" if d["details"] else ""
        print(f"{d['spec']:<32} {d['description']}{details}")
    for name, why in found["broken"].items():
        print(f"backend {name}: cannot be used: {why}")
    for name, hint in found["none_found"].items():
        print(f"backend {name}: {hint}")
    print("check one with: hapticlab device selftest SPEC (it opens the device)")
    return 0


def _add_clear_fault(p: argparse.ArgumentParser) -> None:
    p.add_argument("--clear-fault", action="store_true",
                   help="clear a fault the device latched before (an e-stop, the watchdog), "
                   "once it is safe")


def _matching(args: argparse.Namespace) -> int:
    from app import matching_cli as mc

    if args.action == "sysid":
        return mc.device_sysid(args)
    if args.action == "fit-grasp":
        return mc.device_fit_grasp(args)
    if args.action == "library-build":
        return mc.library_build(args)
    return mc.library_show(args)


def _device_emulate(args: argparse.Namespace) -> int:
    from .api import emulate

    return emulate(args.firmware, rate=args.rate, seed=args.seed, speed=args.speed)


def _device_check(args: argparse.Namespace) -> int:
    from .api import saturation_forecast

    f = saturation_forecast(args.protocol, device=args.device, windows=args.windows,
                            warn=args.warn, clear_fault=args.clear_fault)
    rows, info = f["rows"], f["info"]
    if args.json:
        print(json.dumps({"device": args.device, "rows": rows}, indent=2))
        return 0
    print(f"{f['protocol']} on {args.device} ({info.current_limit:g} A × "
          f"{info.force_constant:g} N/A = {info.max_force:.2f} N), simulated tapper "
          f"0.11 ± 0.033 m/s, {args.windows} windows per sample:")
    for r in rows:
        if "error" in r:
            print(f"  {r['sample']:16s} not checked: {r['error']}")
            continue
        flag = "  WARNING: saturates often" if r["warning"] else ""
        print(f"  {r['sample']:16s} {100 * r['tap_rate']:5.1f} % of taps, "
              f"{100 * r['trial_rate']:5.1f} % of trials saturate{flag}")
    return 0


def _bench(args: argparse.Namespace) -> int:
    from .api import BENCH_OPTIONS, benchmark

    return benchmark(args.what, **{k: getattr(args, k) for k in BENCH_OPTIONS})


def _demo(args: argparse.Namespace) -> int:
    from app.demo import run_demo

    return run_demo(seed=args.seed, out=args.out)


def _measured_jnds(path: str) -> dict:
    """``simulate --jnd``: the 75 % Weber fractions a report.json measured, said aloud."""
    from app.observer import discrimination_from_report

    try:
        report = json.loads(open(path, encoding="utf-8").read())
    except OSError as exc:
        raise UsageError(f"--jnd {path}: cannot read it ({exc.strerror})") from None
    except ValueError as exc:
        raise UsageError(f"--jnd {path}: not a report.json (not JSON: {exc})") from None
    try:
        jnd = discrimination_from_report(report if isinstance(report, dict) else {})
    except ValueError as exc:
        raise UsageError(f"--jnd {path}: {exc}") from None
    print("simulated participants' JNDs drawn around the measured ones: " + ", ".join(
        f"{k} {100 * v:.1f} %" for k, v in sorted(jnd.items())), file=sys.stderr)
    return jnd


def _simulate(args: argparse.Namespace) -> int:
    from app.api import simulate_study

    if args.participants < 1:
        raise UsageError(f"--participants must be at least 1, got {args.participants}")
    if not (math.isfinite(args.speed) and 0 < args.speed <= 20):
        raise UsageError(f"--speed must be in (0, 20] (device seconds per wall second), got "
                         f"{args.speed:g}")
    if args.seed < 0:
        raise UsageError(f"--seed must be >= 0, got {args.seed}")

    discrimination = _measured_jnds(args.jnd) if args.jnd else None
    study = simulate_study(args.protocol, args.participants, seed=args.seed, data=args.data,
                           device=args.device, speed=args.speed, traces=args.traces,
                           prefix=args.prefix, group=args.group, clear_fault=args.clear_fault,
                           discrimination=discrimination)
    if not study.complete:
        last = study.sessions[-1]
        print(last.message, file=sys.stderr)
        return last.exit_code
    print(f"{len(study.sessions)} simulated sessions in {args.data}/ "
          f"({study.seconds:.0f} s)", file=sys.stderr)
    return 0


def _preflight(args: argparse.Namespace) -> int:
    """Every check a session makes before it starts, each on its own line."""
    from .api import preflight

    checks = preflight(args.protocol, device=args.device, data=args.data,
                       responder=args.responder, traces=args.traces, audio=not args.no_audio,
                       clear_fault=args.clear_fault)
    for c in checks:
        print(c.line())
    bad = sum(not c.ok for c in checks)
    print(f"{len(checks) - bad} passed, {bad} failed" + ("" if bad else ": ready to run"))
    return 1 if bad else 0


def _run(args: argparse.Namespace) -> int:
    from app.api import run_session

    responder = "scripted" if args.dry_run else args.responder
    if args.dry_run and args.responder not in ("person", "scripted"):
        raise UsageError("--dry-run is --responder scripted; give one of them")
    device = args.device
    if device is None:
        if responder == "person":
            raise UsageError("a session with a person needs --device: serial:PORT for the "
                             "lab's device (for a rehearsal without a person: --dry-run, or "
                             "--responder simulated)")
        device = "sim"
    r = run_session(args.protocol, args.participant, device=device, data=args.data,
                    responder=responder, seed=args.seed, row=args.row, group=args.group,
                    traces=args.traces, audio=not args.no_audio, fullscreen=args.fullscreen,
                    quiet=args.quiet, clear_fault=args.clear_fault,
                    operator_keys=True if args.operator_keys else None,
                    info_fields={"age": "", "handedness": ["right", "left", "both"]}
                    if args.info_dialog else None, new_session=args.new_session,
                    lsl=args.lsl, lsl_wait=args.lsl_wait)
    _report(r, args.quiet)
    return r.exit_code


def _resume(args: argparse.Namespace) -> int:
    from app.api import resume_session

    r = resume_session(args.session_dir, device=args.device,
                       audio=False if args.no_audio else None, clear_fault=args.clear_fault,
                       fullscreen=args.fullscreen, quiet=args.quiet, lsl=args.lsl,
                       lsl_wait=args.lsl_wait)
    _report(r, args.quiet)
    return r.exit_code


def _add_lsl(p: argparse.ArgumentParser) -> None:
    p.add_argument("--lsl", action="store_true", help="send the session's events as markers "
                   "on Lab Streaming Layer (needs the hapticlab[lsl] extra; "
                   "docs/howto/send-lsl-markers.md)")
    p.add_argument("--lsl-wait", type=float, default=300.0, metavar="SECONDS",
                   help="with --lsl, wait this long for a recorder to receive the markers "
                   "before the first trial (default 300)")


def _report(r, quiet: bool) -> None:
    """A complete session's line on stdout; why it stopped on stderr, even with --quiet
    (the console already said it when not quiet)."""
    if r.status == SessionStatus.COMPLETE:
        print(r.message)
    elif quiet:
        print(f"hapticlab: {r.message}", file=sys.stderr)


def _list(text: str | None) -> list[str] | None:
    return None if text is None else [x.strip() for x in text.split(",") if x.strip()]


def _analyze(args: argparse.Namespace) -> int:
    from app.api import analyze
    from app.api._say import progress_to_stderr

    formats = tuple(f.strip() for f in args.format.split(","))
    bad = set(formats) - {"html", "md", "json"}
    if bad:
        raise UsageError(f"--format takes html, md, json; got {sorted(bad)}")
    rep = analyze(args.data_dir, args.out, formats=formats, protocol=_list(args.protocol),
                  kind=args.kind, status=args.status or "complete",
                  participants=_list(args.participants),
                  since=args.since, until=args.until, drop_invalid=args.drop_invalid,
                  ids=args.ids, sim_device=args.sim_device, progress=progress_to_stderr())
    sel = rep["selection"]
    ids = [a["id"] for a in rep["analyses"]]
    print(f"{len(ids)} analyses ({', '.join(ids) or 'none'}) of {sel['included']} sessions "
          f"({sel['excluded']} excluded, reasons in the report; {sel['filters']['kind']} "
          f"sessions) written to {args.out}/ ({', '.join('report.' + f for f in formats)}, "
          f"{len(rep['figures'])} figure files)")
    if not ids:
        print("hapticlab: nothing was analysed: no analysed phase has data in the selected "
              "sessions (see the selection table in the report)", file=sys.stderr)
        return 1
    return 0


def _selection_args(p: argparse.ArgumentParser) -> None:
    """The session selection shared by analyze and export."""
    p.add_argument("--protocol", help="protocol names to analyse, comma-separated")
    p.add_argument("--kind", choices=("human", "dry-run", "simulated", "all"),
                   help="session kind (default: human when any human session exists)")
    p.add_argument("--status", choices=("complete", "all"), default=None,
                   help="complete sessions only (the default; a BIDS export's default is all: "
                   "a raw dataset keeps interrupted sessions, its sessions.tsv says so), or "
                   "all (interrupted ones too)")
    p.add_argument("--participants", help="participant ids, comma-separated")
    p.add_argument("--since", help="sessions created on or after (YYYY-MM-DD, UTC)")
    p.add_argument("--until", help="sessions created on or before (YYYY-MM-DD, UTC)")
    p.add_argument("--ids", choices=("check", "record", "folder", "rows"), default="check",
                   help="a session whose folder sub-<id>, session.json and trials.tsv rows do "
                   "not name the same participant: leave it out and name it (check), or "
                   "analyse it under session.json's id (record), the folder's (folder) or the "
                   "one the rows name (rows)")
    p.add_argument("--drop-invalid", action="store_true",
                   help="leave out recorded rows that cannot be analysed (a rating off the "
                   "scale, …), listing each, instead of stopping at the first")
    p.add_argument("--sim-device", action="store_true",
                   help="keep people's sessions on the simulated device (--device sim: no "
                   "physical contact); by default they are left out and named")


def _export(args: argparse.Namespace) -> int:
    from app.api import export
    from app.api._say import progress_to_stderr

    files = export(args.data_dir, args.out, args.format, drop_invalid=args.drop_invalid,
                   protocol=_list(args.protocol), kind=args.kind,
                   status=args.status or ("all" if args.format == "bids" else "complete"),
                   participants=_list(args.participants), since=args.since, until=args.until,
                   ids=args.ids, sim_device=args.sim_device, progress=progress_to_stderr())
    if args.format == "bids":  # thousands of files with traces: what to read first
        print(f"a BIDS dataset of {len(files)} files in {args.out}/: participants.tsv maps "
              "each BIDS label to the id as entered; validate it with the BIDS validator")
        return 0
    print(f"{len(files)} files written to {args.out}/: {', '.join(f.name for f in files)}")
    return 0


def _range(text: str, step: int = 1) -> list[int]:
    """'A..B' (every ``step``-th count from A up to B) or a list 'a,b,c' (each count named,
    whatever the step)."""
    if ".." in text:
        a, b = text.split("..", 1)
        return list(range(int(a), int(b) + 1, step))
    return [int(x) for x in text.split(",") if x]


def _power(args: argparse.Namespace) -> int:
    from .api import power

    if args.step < 1:
        raise UsageError(f"--step {args.step}: a step over the subjects range is 1 or more")
    try:
        subjects = _range(args.subjects, args.step)
        reps = _range(args.reps)
    except ValueError:
        raise UsageError("--subjects and --reps take 'A..B' or 'a,b,c'") from None
    pw = power(args.protocol, subjects=subjects, reps=reps, effect=args.effect,
               alpha=args.alpha, experiments=args.experiments, sd_trial=args.sd_trial,
               sd_interaction=args.sd_interaction, sd_subject=args.sd_subject,
               pilot=args.pilot)
    t, sd, comparisons = pw["table"], pw["sd"], pw["comparisons"]
    if args.json:
        print(json.dumps({"protocol": pw["protocol"], "phase": pw["phase"],
                          "effect": args.effect, "comparisons": comparisons, **sd,
                          "rows": t.to_dict(orient="records")}, indent=2, allow_nan=False))
        return 0
    print(f"{pw['protocol']}/{pw['phase']}: power of a {args.effect:g}-point paired difference at "
          f"alpha {args.alpha:g}/{comparisons} (Bonferroni) and the 95 % CI half-width of a "
          f"sample's mean, {args.experiments} simulated experiments per cell "
          f"(sd trial {sd['sd_trial']:.2f}, subject×sample {sd['sd_interaction']:.2f}, "
          f"subject {sd['sd_subject']:.2f})")
    grid = t.pivot(index="subjects", columns="reps", values="power")
    half = t.pivot(index="subjects", columns="reps", values="ci_halfwidth")
    print("power            " + "".join(f"  r={r:<5d}" for r in grid.columns))
    for n in grid.index:
        print(f"  n = {n:3d}        " + "".join(f"  {grid.loc[n, r]:6.2f} " for r in grid.columns))
    print("CI half-width    " + "".join(f"  r={r:<5d}" for r in half.columns))
    for n in half.index:
        print(f"  n = {n:3d}        " + "".join(f"  {half.loc[n, r]:6.2f} " for r in half.columns))
    return 0


#: what a command's protocol argument takes
PROTOCOL_HELP = f"a built-in name ({', '.join(BUILTIN)}) or a file"


def _add_session_parsers(sub) -> None:
    r = sub.add_parser("run", help="run a session: a person at the screen, or a dry run")
    r.add_argument("protocol", help=PROTOCOL_HELP)
    r.add_argument("--participant", required=True, help="participant id, e.g. P01")
    r.add_argument("--device", default=None, help="serial:PORT (the lab's device), sim or "
                   "sim:RATE; required when a person answers")
    r.add_argument("--responder", choices=("person", "scripted", "simulated"),
                   default="person", help="who answers: a person at the PsychoPy screen "
                   "(default), random answers (a dry run), or the simulated participant")
    r.add_argument("--dry-run", action="store_true",
                   help="test the machinery: --responder scripted on --device sim")
    r.add_argument("--seed", type=int, default=None, help="session seed (drawn and recorded "
                   "when not given)")
    r.add_argument("--data", default="data", help="data folder (default ./data)")
    r.add_argument("--no-audio", action="store_true", help="run without sound")
    r.add_argument("--row", type=int, default=None,
                   help="counterbalance row (Williams-ordered protocols)")
    r.add_argument("--traces", choices=("full", "contacts", "none"), default="full",
                   help="raw device streams kept per attempt")
    r.add_argument("--fullscreen", action="store_true", help="the participant's window "
                   "fills the screen")
    r.add_argument("--group", default="", help="participant group label, e.g. expert or novice")
    r.add_argument("--info-dialog", action="store_true", help="ask the participant's details "
                   "(the protocol's [participant] fields, or age and handedness) in a dialog")
    r.add_argument("--clear-fault", action="store_true",
                   help="clear a fault the device latched before the session (when it is safe)")
    r.add_argument("--operator-keys", action="store_true",
                   help="read the operator's keys in a dry run too (to rehearse the operator's "
                   "part; a session with a person always does)")
    r.add_argument("--new-session", action="store_true",
                   help="start another session for a person who already has sessions of this "
                   "protocol (without it the run lists them and stops)")
    r.add_argument("--quiet", action="store_true", help="no console lines (errors still "
                   "print)")
    _add_lsl(r)
    r.set_defaults(func=_run)
    pf = sub.add_parser("preflight", help="every check a session makes before it starts")
    pf.add_argument("protocol", help=PROTOCOL_HELP)
    pf.add_argument("--device", required=True, help="serial:PORT, sim or sim:RATE")
    pf.add_argument("--data", default="data", help="data folder to check (default ./data)")
    pf.add_argument("--responder", choices=("person", "scripted", "simulated"),
                    default="person", help="who will answer (default person: checks the "
                    "display and the operator's terminal too)")
    pf.add_argument("--traces", choices=("full", "contacts", "none"), default="full",
                    help="traces the session will keep (sizes the disk check)")
    pf.add_argument("--no-audio", action="store_true", help="the session will run "
                    "without sound (skips the audio check)")
    _add_clear_fault(pf)
    pf.set_defaults(func=_preflight)
    rs = sub.add_parser("resume", help="continue an interrupted session exactly where it stopped")
    rs.add_argument("session_dir", help="the session folder, e.g. data/sub-P01/ses-1")
    rs.add_argument("--device", default=None, help="override the recorded device spec")
    rs.add_argument("--no-audio", action="store_true", help="continue without sound")
    rs.add_argument("--clear-fault", action="store_true",
                    help="clear a latched e-stop/watchdog fault first (when it is safe)")
    rs.add_argument("--fullscreen", action="store_true", help="the participant's window "
                    "fills the screen")
    rs.add_argument("--quiet", action="store_true", help="no console lines")
    _add_lsl(rs)
    rs.set_defaults(func=_resume)
    s = sub.add_parser("simulate", help="run a whole study with simulated participants")
    s.add_argument("protocol", help=PROTOCOL_HELP)
    s.add_argument("--participants", type=int, default=9, help="simulated participants "
                   "(default 9)")
    s.add_argument("--seed", type=int, default=0, help="study seed (session seeds derive from it)")
    s.add_argument("--data", default="sim-data", help="data folder (default ./sim-data: never "
                   "beside people's data)")
    s.add_argument("--device", default="sim",
                   help="sim, sim:RATE, emulator, emulator:BUILD (each session starts its own, "
                   "paced by --speed) or serial:PORT")
    s.add_argument("--speed", type=float, default=1.0,
                   help="device seconds per wall second where the device's clock is paced (an "
                   "emulator; default 1)")
    s.add_argument("--traces", choices=("full", "contacts", "none"), default="contacts",
                   help="raw device streams kept per attempt (default contacts)")
    s.add_argument("--prefix", default="sim", help="participant ids are PREFIX01, PREFIX02, …")
    s.add_argument("--group", default="", help="group label of these participants")
    s.add_argument("--jnd", default=None, metavar="REPORT", help="a report.json of measured "
                   "thresholds: the simulated participants' JNDs drawn around its 75 %% "
                   "Weber fractions instead of the assumed ones")
    _add_clear_fault(s)
    s.set_defaults(func=_simulate)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="hapticlab",
        description="Psychophysics of haptic contact realism: devices, protocols, analysis.")
    from app import __version__

    p.add_argument("--version", action="version", version=f"hapticlab {__version__}",
                   help="print the version and exit")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    from .api import EMULATORS

    dev = sub.add_parser("device", help="device tools (list, selftest, check, emulate, sysid, "
                         "fit-grasp)")
    dsub = dev.add_subparsers(dest="device_command", required=True, metavar="ACTION")
    st = dsub.add_parser("selftest", help="run the backend-independent checks against a device")
    st.add_argument("spec", help="device spec, e.g. sim or serial:/dev/ttyACM0")
    st.add_argument("--json", action="store_true", help="print a JSON summary")
    st.add_argument("--device-alone", action="store_true",
                    help="on a physical device, run only the checks it does alone; the five "
                    "that need someone to tap the stylus are reported as not run (ignored, "
                    "with a note, on a simulated device: its hand taps by itself)")
    st.add_argument("--tap-wait", type=float, default=30.0, metavar="S",
                    help="on a physical device, how long each check that needs the stylus "
                    "tapped waits for contact after asking (default 30 s)")
    _add_clear_fault(st)
    st.set_defaults(func=_device_selftest)
    dl = dsub.add_parser("list", help="the serial ports and devices found (opens none)")
    dl.add_argument("--json", action="store_true", help="print the list as JSON")
    dl.set_defaults(func=_device_list)
    ck = dsub.add_parser("check", help="predict how often each virtual sample saturates")
    ck.add_argument("protocol", help=PROTOCOL_HELP)
    ck.add_argument("--device", default="sim", help="device spec: sim (default), sim:RATE or "
                    "serial:PORT")
    ck.add_argument("--windows", type=int, default=12, help="5-s windows per sample")
    ck.add_argument("--warn", type=float, default=0.2, help="warn above this share of trials")
    ck.add_argument("--json", action="store_true", help="print the prediction as JSON")
    _add_clear_fault(ck)
    ck.set_defaults(func=_device_check)
    em = dsub.add_parser("emulate", help="serve the wire protocol on a pseudo-terminal "
                         "(simulated plant); prints the port first")
    em.add_argument("--rate", type=float, default=None, help="servo rate of the Python "
                    "emulator [Hz] (default 10,000; the firmware runs at its build's own)")
    em.add_argument("--seed", type=int, default=0, help="seed of the simulated plant and "
                    "tapping (default 0)")
    em.add_argument("--speed", type=float, default=1.0, help="device seconds per wall second")
    em.add_argument("--firmware", choices=tuple(EMULATORS),
                    default="python",
                    help="what serves the port (wire protocol 3): the Python emulator, or the C "
                    "reference firmware built for this machine (host-board: with the "
                    "STM32F405's buffers and 1-Mbaud link; host-san: that under ASan and "
                    "UBSan) or run on an emulated STM32F405 under QEMU, or the bridges to "
                    "commercial devices over stand-ins for their SDKs (dhd-stub: Force "
                    "Dimension, 4 kHz; hd-stub: OpenHaptics, 1 kHz, real time only, and "
                    "hd-stub-tsan, that under ThreadSanitizer; neither has an accelerometer)")
    em.set_defaults(func=_device_emulate)
    from app.matching_cli import add_parsers

    add_parsers(dsub, sub, _matching, _add_clear_fault)

    pw = sub.add_parser("power", help="Monte-Carlo power and precision for session length")
    pw.add_argument("protocol", help=PROTOCOL_HELP)
    pw.add_argument("--subjects", default="5..30", help="participant counts: A..B (with "
                    "--step) or a list 5,10,20 (default 5..30)")
    pw.add_argument("--step", type=int, default=5, help="step over a subjects range A..B; a "
                    "list is taken whole (default 5)")
    pw.add_argument("--reps", default="1..5", help="repetitions per cell: A..B or a list "
                    "(default 1..5)")
    pw.add_argument("--effect", type=float, default=1.0, help="key contrast [scale points]")
    pw.add_argument("--alpha", type=float, default=0.05, help="significance level (default "
                    "0.05)")
    pw.add_argument("--sd-trial", type=float, default=None,
                    help="trial-to-trial SD [scale points] (default 0.9; with --pilot: "
                    "estimated from it, or this value when the pilot rates each cell once)")
    pw.add_argument("--sd-interaction", type=float, default=0.5,
                    help="participant × sample SD [scale points] (default 0.5)")
    pw.add_argument("--sd-subject", type=float, default=0.8,
                    help="between-participant SD of the mean rating [scale points] (default "
                    "0.8)")
    pw.add_argument("--pilot", help="session folder to estimate the SDs from")
    pw.add_argument("--experiments", type=int, default=10_000,
                    help="simulated experiments per cell (default 10,000)")
    pw.add_argument("--json", action="store_true", help="print the table as JSON")
    pw.set_defaults(func=_power)
    an = sub.add_parser("analyze", help="statistics, figures and report from session folders")
    an.add_argument("data_dir", help="folder of session folders (sub-*/ses-*)")
    an.add_argument("--out", required=True, help="folder for report.html/.md/.json and "
                    "the figures (created)")
    an.add_argument("--format", default="html,md,json", help="comma-separated: html, md, json")
    _selection_args(an)
    an.set_defaults(func=_analyze)

    ex = sub.add_parser("export", help="the analysed trials as CSV for JASP, SPSS or R, with "
                        "a codebook")
    ex.add_argument("data_dir", help="folder of session folders (sub-*/ses-*)")
    ex.add_argument("--out", required=True, help="folder to write into")
    ex.add_argument("--format", default="long-csv",
                    choices=("long-csv", "wide-csv", "jasp", "r", "spss", "bids"),
                    help="long-csv: one row per trial; wide-csv: one row per participant and "
                    "one column per cell, per analysed phase; jasp: wide with names JASP and R "
                    "read unchanged; r: long.csv and load.R; spss: the wide and long files "
                    "as .sav with variable and value labels; bids: a BIDS dataset (beh/: "
                    "every attempt, onsets, the device's traces), as the BIDS validator "
                    "accepts it")
    _selection_args(ex)
    ex.set_defaults(func=_export)
    _add_session_parsers(sub)
    pr = sub.add_parser("protocol", help="protocol files (validate, show)")
    psub = pr.add_subparsers(dest="protocol_command", required=True, metavar="ACTION")
    pv = psub.add_parser("validate", help="check a protocol file; exit 0 when valid")
    pv.add_argument("file", help=f"built-in name ({', '.join(BUILTIN)}) or a path")
    pv.add_argument("--device", help="also check forces and currents against this device")
    _add_clear_fault(pv)
    pv.set_defaults(func=_protocol_validate)
    ps = psub.add_parser("show", help="print the resolved trial plan for a seed")
    ps.add_argument("file", help="built-in name or a path")
    ps.add_argument("--seed", type=int, required=True, help="session seed: the plan is "
                    "the one a session with this seed runs")
    ps.add_argument("--participant", default="P00", help="participant id (default P00)")
    ps.add_argument("--row", type=int, default=None,
                    help="counterbalance row for Williams-ordered blocks")
    ps.add_argument("--json", action="store_true", help="print the plan as JSON")
    ps.set_defaults(func=_protocol_show)

    from .api import BENCH_OPTIONS

    b = sub.add_parser("bench", help="speed and speed-vs-accuracy benchmarks")
    b.add_argument("what", help="which benchmark: sim, accuracy (every scene, tap and servo "
                   "rate against 100 kHz), matching, link, crash, analysis, demo, energy, "
                   "orderings, causes (why realism's middle ranks differ from the paper), "
                   "factorial (why the factorial and identification findings differ, and "
                   "what would change them), "
                   "tick (the firmware's servo tick on the Cortex-M4), scale (analyze and "
                   "export against 10³…10⁶ rows: time and peak memory), "
                   "thresholds (bias, CI coverage and trials of the staircase and QUEST+ "
                   "against a simulated observer's known JND)")
    b.add_argument("--json", action="store_true", help="print JSON rows")
    b.add_argument("--repeats", type=int, default=BENCH_OPTIONS["repeats"],
                   help="timing repeats (median reported)")
    b.add_argument("--fuzz", type=int, default=BENCH_OPTIONS["fuzz"],
                   help="link: mutated frames to push through the decoder")
    b.add_argument("--kills", type=int, default=BENCH_OPTIONS["kills"], help="crash: kill -9 count")
    b.add_argument("--sessions", type=int, default=BENCH_OPTIONS["sessions"],
                   help="thresholds: simulated sessions per procedure")
    b.add_argument("--points", default=None, help="crash: kill after every write point "
                   "('all') or the listed ones ('3,17')")
    b.add_argument("--boundaries", default=None, help="crash: cut a simulated participant's "
                   "session after every row ('all') or the listed ones ('1,12'), and resume it")
    b.add_argument("--seeds", default=None, help="orderings: study seeds (default "
                   "1,2,3,4,5); causes, factorial: device seeds (default 1,2); thresholds: "
                   "the study seed (default 1)")
    b.add_argument("--firmware", choices=("host", "qemu"), default=None,
                   help="link: measure the reference firmware (against the Python emulator)")
    b.add_argument("--load", default=None, help="link: competing CPU-bound processes, e.g. "
                   "0,1,2,4: heartbeat gaps the device saw, faults per hour and e-stop "
                   "latency per target under that load")
    b.add_argument("--targets", default=None, help="link --load: python, host, host-board, "
                   "qemu (default all four)")
    b.add_argument("--seconds", type=float, default=BENCH_OPTIONS["seconds"],
                   help="link --load: session traffic per target and load [s]")
    b.add_argument("--baseline", action="store_true", help="link --load: also run each cell "
                   "with reading and heartbeats in Python threads")
    b.add_argument("--rows", default=None, help="scale: study sizes in rows (default "
                   "1e3,1e4,1e5,1e6)")
    b.add_argument("--no-window", action="store_true",
                   help="link --load: no PsychoPy window (drawn otherwise, under Xvfb if needed)")
    b.set_defaults(func=_bench)

    d = sub.add_parser("demo", help="what `make demo` runs: a whole simulated study and its "
                       "report")
    d.add_argument("--seed", type=int, default=1, help="session seed (default 1)")
    d.add_argument("--out", default="out/demo", help="data/ and report/ go here")
    d.set_defaults(func=_demo)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    from device.errors import DeviceFaultError

    from .guards import Terminated, install_signal_guards

    parser = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(argv)
    func: Callable[[argparse.Namespace], int] = args.func
    install_signal_guards()
    try:
        return func(args)
    except DeviceFaultError as exc:  # a fault latched before: say how to go on
        print(f"hapticlab: error: {exc}", file=sys.stderr)
        if hasattr(args, "clear_fault") and not args.clear_fault:
            import shlex

            print("hapticlab: once it is safe, clear the fault and go on: hapticlab "
                  f"{shlex.join([*argv, '--clear-fault'])}", file=sys.stderr)
        return 2
    except HapticlabError as exc:
        print(f"hapticlab: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("hapticlab: interrupted", file=sys.stderr)
        return 130
    except Terminated as exc:
        print(f"hapticlab: stopped ({exc})", file=sys.stderr)
        return 128 + exc.signum
    except BrokenPipeError:  # output piped into `head` and the like
        sys.stderr.close()
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
