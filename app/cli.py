"""The ``hapticlab`` command line.

User errors (bad specs, files, values) print one clear line to stderr and exit 2,
never a traceback. Heavy modules are imported inside the command that needs them.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable, Sequence

__all__ = ["main"]


class UserError(Exception):
    """An error in what the user asked for; printed without a traceback."""


def _device_selftest(args: argparse.Namespace) -> int:
    from device import DeviceError, open_device
    from device.suite import run_selftest

    try:
        open_device(args.spec).close()
    except (DeviceError, ValueError) as exc:
        raise UserError(str(exc)) from None
    report = run_selftest(args.spec, lambda: open_device(args.spec))
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        from rich.console import Console
        from rich.table import Table

        table = Table(title=f"device self-test: {args.spec}")
        table.add_column("check")
        table.add_column("result")
        table.add_column("detail")
        for row in report["checks"]:
            table.add_row(row["name"], "[green]ok[/]" if row["ok"] else "[red]FAIL[/]",
                          row["detail"])
        Console().print(table)
        print(f"{report['passed']} passed, {report['failed']} failed")
    return 0 if report["failed"] == 0 else 1


def _load_protocol(path: str, device_spec: str | None = None):
    from device import DeviceError, open_device
    from protocols import ProtocolError, load_protocol

    info = None
    if device_spec:
        try:
            with open_device(device_spec) as dev:
                info = dev.info
        except (DeviceError, ValueError) as exc:
            raise UserError(str(exc)) from None
    try:
        return load_protocol(path, device=info)
    except ProtocolError as exc:
        raise UserError(str(exc)) from None


def _protocol_validate(args: argparse.Namespace) -> int:
    p = _load_protocol(args.file, args.device)
    n_items = sum(len(ph.samples) * ph.repetitions if ph.kind != "identification"
                  else ph.repetitions for ph in p.phases)
    print(f"{p.source}: valid protocol '{p.name}' — {len(p.samples)} samples, "
          f"{len(p.phases)} phases, {n_items} trials without redraws"
          + (f"; checked against device '{args.device}'" if args.device else ""))
    return 0


def _protocol_show(args: argparse.Namespace) -> int:
    from protocols import SessionEngine

    p = _load_protocol(args.file)
    try:
        engine = SessionEngine(p, args.seed, args.participant, args.row)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    phases: list[dict] = []
    for item in engine.plan():
        if not phases or phases[-1]["name"] != item.phase:
            phases.append({"name": item.phase, "trials": []})
        trial = {"sample": item.samples[0] if len(item.samples) == 1 else list(item.samples),
                 "item": item.key}
        if item.block is not None:
            trial["block"] = item.block
        phases[-1]["trials"].append(trial)
    plan = {"protocol": p.name, "source": p.source, "sha256": p.sha256, "seed": args.seed,
            "participant": args.participant, "phases": phases}
    if args.json:
        print(json.dumps(plan, indent=2))
        return 0
    print(f"{p.title} ({p.source}, sha256 {p.sha256[:12]}…), seed {args.seed}")
    for ph in phases:
        print(f"\n{ph['name']} ({len(ph['trials'])} trials)")
        for i, t in enumerate(ph["trials"], 1):
            s = t["sample"] if isinstance(t["sample"], str) else " / ".join(t["sample"])
            print(f"  {i:3d}  {s}")
    return 0


def _open_spec(spec: str):
    from device import DeviceError, open_device

    try:
        return open_device(spec)
    except (DeviceError, ValueError) as exc:
        raise UserError(str(exc)) from None


def _matching(args: argparse.Namespace) -> int:
    from app import matching_cli as mc
    from device import DeviceError

    try:
        if args.action == "identify":
            return mc.device_identify(args, _open_spec)
        if args.action == "identify-grasp":
            return mc.device_identify_grasp(args)
        if args.action == "library-build":
            return mc.library_build(args, _open_spec, lambda p: _load_protocol(p))
        return mc.library_show(args, _open_spec)
    except (DeviceError, ValueError) as exc:
        raise UserError(str(exc)) from None


def _device_emulate(args: argparse.Namespace) -> int:
    from device.serial.emulator import main as emulate

    if not 1_000 <= args.rate <= 20_000:
        raise UserError(f"--rate must be 1,000–20,000 Hz, got {args.rate:g}")
    if not 0 < args.speed <= 20:
        raise UserError(f"--speed must be in (0, 20] (device seconds per wall second), "
                        f"got {args.speed:g}")
    return emulate(args.rate, args.seed, args.speed)


def _device_check(args: argparse.Namespace) -> int:
    from app.check import saturation_check

    protocol = _load_protocol(args.protocol)
    with _open_spec(args.device) as dev:
        info = dev.info
    rows = saturation_check(protocol, info, windows=args.windows, warn=args.warn)
    if args.json:
        print(json.dumps({"device": args.device, "rows": rows}, indent=2))
        return 0
    print(f"{protocol.name} on {args.device} ({info.current_limit:g} A × "
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
    import importlib

    try:
        module = importlib.import_module(f"benchmarks.{args.what}")
    except ModuleNotFoundError:
        raise UserError(f"no benchmark named {args.what!r}; "
                        "available: sim, matching, link, crash, analysis, demo") from None
    return module.main(args)


def _demo(args: argparse.Namespace) -> int:
    from app.demo import run_demo

    return run_demo(seed=args.seed, out=args.out)


def _simulate(args: argparse.Namespace) -> int:
    from app.ids import ParticipantIdError
    from app.simulate_cli import simulate
    from device import DeviceError
    from protocols import ProtocolError

    try:
        return simulate(args)
    except (ParticipantIdError, ProtocolError, DeviceError, ValueError) as exc:
        raise UserError(str(exc)) from None


def _run(args: argparse.Namespace) -> int:
    from app.ids import ParticipantIdError
    from app.session_cli import run
    from device import DeviceError
    from protocols import ProtocolError

    try:
        return run(args)
    except (ParticipantIdError, ProtocolError, DeviceError, ValueError) as exc:
        raise UserError(str(exc)) from None


def _resume(args: argparse.Namespace) -> int:
    from app.recorder import TrialsFileError
    from app.session_cli import resume
    from device import DeviceError
    from protocols import ProtocolError, ResumeMismatch

    try:
        return resume(args)
    except (ProtocolError, DeviceError, ValueError, ResumeMismatch, TrialsFileError,
            FileNotFoundError) as exc:
        raise UserError(str(exc)) from None


def _analyze(args: argparse.Namespace) -> int:
    from analysis import LoadError, StatsError
    from analysis.report import analyze

    formats = tuple(f.strip() for f in args.format.split(","))
    bad = set(formats) - {"html", "md", "json"}
    if bad:
        raise UserError(f"--format takes html, md, json; got {sorted(bad)}")
    try:
        rep = analyze(args.data_dir, args.out, formats)
    except (LoadError, StatsError) as exc:
        raise UserError(str(exc)) from None
    studies = [k for k in ("realism", "factorial", "identification") if k in rep]
    print(f"report for {', '.join(studies) or 'no study'} ({rep['provenance']['sessions']} "
          f"sessions) written to {args.out}/ ({', '.join('report.' + f for f in formats)}, "
          f"{len(rep['figures'])} figure files)")
    return 0


def _range(text: str) -> list[int]:
    """'5..30' (step 5 for subjects, 1 otherwise is given by --step) or '5,10,20'."""
    if ".." in text:
        a, b = text.split("..", 1)
        return list(range(int(a), int(b) + 1))
    return [int(x) for x in text.split(",") if x]


def _power(args: argparse.Namespace) -> int:
    from analysis.power import power_table, variance_components

    try:
        subjects = _range(args.subjects)[:: args.step]
        reps = _range(args.reps)
    except ValueError:
        raise UserError("--subjects and --reps take 'A..B' or 'a,b,c'") from None
    if not subjects or min(subjects) < 2 or not reps or min(reps) < 1:
        raise UserError("need at least 2 subjects and 1 repetition")
    protocol = _load_protocol(args.protocol)
    rated = [p.name for p in protocol.phases if p.kind == "rated"]
    if not rated:
        raise UserError(f"power: protocol {protocol.name!r} has no rated phase; power and "
                        "precision are computed for rating studies")
    comparisons = math.comb(len([s for s in protocol.samples.values() if s.rated]), 2)
    sd = {"sd_trial": args.sd_trial, "sd_interaction": args.sd_interaction,
          "sd_subject": args.sd_subject}
    if args.pilot:
        from analysis import load_sessions

        # the phase the study is analysed on: the last rated one (realism: testing; a
        # demonstration phase is a first look, rated before the scale settles)
        phase = rated[-1]
        d = load_sessions(args.pilot)
        d = d[d["valid"] & d["rating"].notna() & (d["protocol"] == protocol.name)
              & (d["phase"] == phase)]
        if d.empty:
            raise UserError(f"--pilot {args.pilot}: no valid ratings of {protocol.name!r} "
                            f"in phase {phase!r}")
        sd = variance_components(d)
    t = power_table(subjects, reps, args.effect, alpha=args.alpha, comparisons=comparisons,
                    experiments=args.experiments, **sd)
    if args.json:
        print(json.dumps({"protocol": protocol.name, "effect": args.effect,
                          "comparisons": comparisons, **sd,
                          "rows": t.to_dict(orient="records")}, indent=2))
        return 0
    print(f"{protocol.name}: power of a {args.effect:g}-point paired difference at alpha "
          f"{args.alpha:g}/{comparisons} (Bonferroni) and the 95 % CI half-width of a "
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


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="hapticlab",
        description="Psychophysics of haptic contact realism: devices, protocols, analysis.")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    dev = sub.add_parser("device",
                         help="device tools (selftest, emulate, identify, identify-grasp)")
    dsub = dev.add_subparsers(dest="device_command", required=True, metavar="ACTION")
    st = dsub.add_parser("selftest", help="run the backend-independent checks against a device")
    st.add_argument("spec", help="device spec, e.g. sim or serial:/dev/ttyACM0")
    st.add_argument("--json", action="store_true", help="print a JSON summary")
    st.set_defaults(func=_device_selftest)
    ck = dsub.add_parser("check", help="predict how often each virtual sample saturates")
    ck.add_argument("protocol")
    ck.add_argument("--device", default="sim")
    ck.add_argument("--windows", type=int, default=12, help="5-s windows per sample")
    ck.add_argument("--warn", type=float, default=0.2, help="warn above this share of trials")
    ck.add_argument("--json", action="store_true")
    ck.set_defaults(func=_device_check)
    em = dsub.add_parser("emulate", help="serve the wire protocol on a pseudo-terminal "
                         "(simulated plant); prints the port first")
    em.add_argument("--rate", type=float, default=10_000.0, help="servo rate [Hz]")
    em.add_argument("--seed", type=int, default=0)
    em.add_argument("--speed", type=float, default=1.0, help="device seconds per wall second")
    em.set_defaults(func=_device_emulate)
    from app.matching_cli import add_parsers

    add_parsers(dsub, sub, _matching)

    pw = sub.add_parser("power", help="Monte-Carlo power and precision for session length")
    pw.add_argument("protocol")
    pw.add_argument("--subjects", default="5..30")
    pw.add_argument("--step", type=int, default=5, help="step over the subjects range")
    pw.add_argument("--reps", default="1..5")
    pw.add_argument("--effect", type=float, default=1.0, help="key contrast [scale points]")
    pw.add_argument("--alpha", type=float, default=0.05)
    pw.add_argument("--sd-trial", type=float, default=0.9)
    pw.add_argument("--sd-interaction", type=float, default=0.5)
    pw.add_argument("--sd-subject", type=float, default=0.8)
    pw.add_argument("--pilot", help="session folder to estimate the SDs from")
    pw.add_argument("--experiments", type=int, default=10_000)
    pw.add_argument("--json", action="store_true")
    pw.set_defaults(func=_power)
    an = sub.add_parser("analyze", help="statistics, figures and report from session folders")
    an.add_argument("data_dir")
    an.add_argument("--out", required=True)
    an.add_argument("--format", default="html,md,json", help="comma-separated: html, md, json")
    an.set_defaults(func=_analyze)
    from app.session_cli import add_parsers as add_session

    add_session(sub, _run, _resume)
    from app.simulate_cli import add_parser as add_simulate

    add_simulate(sub, _simulate)
    pr = sub.add_parser("protocol", help="protocol files (validate, show)")
    psub = pr.add_subparsers(dest="protocol_command", required=True, metavar="ACTION")
    pv = psub.add_parser("validate", help="check a protocol file; exit 0 when valid")
    pv.add_argument("file", help="built-in name (realism, factorial, identification) or a path")
    pv.add_argument("--device", help="also check forces and currents against this device")
    pv.set_defaults(func=_protocol_validate)
    ps = psub.add_parser("show", help="print the resolved trial plan for a seed")
    ps.add_argument("file", help="built-in name or a path")
    ps.add_argument("--seed", type=int, required=True)
    ps.add_argument("--participant", default="P00", help="participant id (default P00)")
    ps.add_argument("--row", type=int, default=None,
                    help="counterbalance row for Williams-ordered blocks")
    ps.add_argument("--json", action="store_true")
    ps.set_defaults(func=_protocol_show)

    b = sub.add_parser("bench", help="speed and speed-vs-accuracy benchmarks")
    b.add_argument("what", help="which benchmark: sim, matching, link, crash, analysis, demo")
    b.add_argument("--json", action="store_true", help="print JSON rows")
    b.add_argument("--repeats", type=int, default=5, help="timing repeats (median reported)")
    b.add_argument("--fuzz", type=int, default=100_000,
                   help="link: mutated frames to push through the decoder")
    b.add_argument("--kills", type=int, default=1000, help="crash: kill -9 count")
    b.set_defaults(func=_bench)

    d = sub.add_parser("demo", help="what `make demo` runs: a whole simulated study and its "
                       "report")
    d.add_argument("--seed", type=int, default=1)
    d.add_argument("--out", default="out/demo", help="data/ and report/ go here")
    d.set_defaults(func=_demo)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    func: Callable[[argparse.Namespace], int] = args.func
    try:
        return func(args)
    except UserError as exc:
        print(f"hapticlab: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("hapticlab: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into `head` and the like
        sys.stderr.close()
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
