"""Command-line actions for acceleration matching and the grasp model (with their plots)."""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from device.errors import DeviceError, DeviceFaultError, HapticlabError

from .errors import UsageError

__all__ = ["device_sysid", "device_fit_grasp", "library_build", "library_show"]


def _agg():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _sysid_again(args: argparse.Namespace) -> str:
    """The command line that runs this identification again, with every option the user
    gave, once a fault is cleared (quoted for the shell)."""
    cmd = ["hapticlab", "device", "sysid", "--device", args.device, "--order", str(args.order),
           "--relative-degree", str(args.relative_degree), "--levels",
           *(str(v) for v in args.levels), "--repeats", str(args.repeats)]
    if args.delay is not None:
        cmd += ["--delay", f"{args.delay:g}"]
    if args.png:
        cmd += ["--png", str(args.png)]
    if args.json:
        cmd.append("--json")
    return shlex.join([*cmd, "--clear-fault"])


def _opened(record, what: str):
    """``record`` after saying whether it resumes an earlier run (``what``: the kept
    measurements' noun, "measurements" or "of 12 sweeps")."""
    if record.set_aside:
        print(f"hapticlab: not resuming from {record.path} ({record.set_aside}): "
              "measuring afresh", file=sys.stderr)
    elif record.resumed:
        print(f"hapticlab: resuming: {record.resumed} {what} kept from an earlier run "
              f"({record.path}; --restart measures everything again)", file=sys.stderr)
    return record


def device_sysid(args: argparse.Namespace, open_spec) -> int:
    from device.matching.library import (
        PIPELINE_VERSION,
        BuildRecord,
        sysid_record_path,
        usable_band,
    )
    from device.matching.measure import MeasurementFault, Pace
    from device.matching.sysid import identify, sweep_seconds

    with open_spec(args.device) as dev:
        band = usable_band(dev.info.servo_rate_hz)
        n = len(args.levels) * args.repeats
        # finished sweeps are kept until the model is fitted, so a fault (cleared at the
        # prompt, or by running the command again) costs one sweep, never the others
        info = dev.info
        key = {"sysid": 1, "pipeline": PIPELINE_VERSION,
               "device": [info.model, info.serial_number, info.servo_rate_hz],
               "levels": [float(v) for v in args.levels], "repeats": args.repeats,
               "band_hz": [float(v) for v in band],
               "sweep_s": sweep_seconds(info.servo_rate_hz, band)}
        record = _opened(BuildRecord.open(sysid_record_path(info), key, restart=args.restart),
                         f"of {n} sweeps")
        pace = Pace([sweep_seconds(info.servo_rate_hz, band)] * n, record.count, _step_line)

        def kept() -> str:
            return f"{record.count} of {n} sweeps are kept in {record.path}"

        try:
            idn = identify(dev, levels=tuple(args.levels), repeats=args.repeats, band=band,
                           order=args.order, relative_degree=args.relative_degree,
                           delay=None if args.delay is None else args.delay * 1e-3,
                           record=record, on_fault=fault_prompt(dev, kept), pace=pace)
        except MeasurementFault as exc:
            raise DeviceError(f"{exc}; {kept()}. Once it is safe, continue with: "
                              f"{_sysid_again(args)}") from None
    m = idn.model
    e = idn.etfe.in_band(band)
    report = {"device": args.device, "rate_hz": idn.rate_hz, "levels_n": list(idn.levels),
              "repeats": idn.repeats, "model": m.to_dict(),
              "coherence": {"min": float(e.coherence.min()), "median": float(np.median(
                  e.coherence))},
              "resonance_hz": float(e.freq[np.argmax(np.abs(e.H))])}
    if args.png:
        plt = _agg()
        fig, ax = plt.subplots(3, 1, figsize=(7, 8), sharex=True)
        for lvl, est in idn.per_level.items():
            b = est.in_band(band)
            ax[0].semilogx(b.freq, 20 * np.log10(np.abs(b.H)), lw=0.7, alpha=0.6,
                           label=f"ETFE {lvl:g} N")
        ax[0].semilogx(e.freq, 20 * np.log10(np.abs(e.H)), "k", lw=1.2, label="ETFE mean")
        ax[0].semilogx(e.freq, 20 * np.log10(np.abs(m.response(e.freq))), "r--",
                       label=f"model {m.order}/{m.relative_degree}, τ={m.delay * 1e3:.3g} ms")
        ax[0].set_ylabel("|a/F| [dB re 1 (m/s²)/N]")
        ax[0].legend(fontsize=7)
        ax[1].semilogx(e.freq, np.degrees(np.unwrap(np.angle(e.H))), "k")
        ax[1].semilogx(e.freq, np.degrees(np.unwrap(np.angle(m.response(e.freq)))), "r--")
        ax[1].set_ylabel("phase [deg]")
        ax[2].semilogx(e.freq, e.coherence, "k")
        ax[2].set_ylabel("coherence")
        ax[2].set_xlabel("frequency [Hz]")
        fig.suptitle(f"force → acceleration, {args.device} (hand holding the stylus)")
        fig.tight_layout()
        fig.savefig(args.png, dpi=110)
        report["png"] = str(args.png)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(f"identified {args.device}: {m.order}th order, relative degree "
              f"{m.relative_degree}, delay {m.delay * 1e3:.3g} ms; fit over "
              f"{band[0]:g}–{band[1]:g} Hz: {m.err_db_rms:.2f} dB rms ({m.err_db_max:.2f} max), "
              f"{m.err_deg_rms:.1f}° rms ({m.err_deg_max:.1f}° max); resonance "
              f"{report['resonance_hz']:.0f} Hz; coherence ≥ {report['coherence']['min']:.2f}")
    record.discard()  # the model is out: the sweeps are no longer needed
    return 0


def device_fit_grasp(args: argparse.Namespace) -> int:
    from device.matching.grasp import PUBLISHED, TISSUE, GraspRig, identify_grasp

    if not args.simulated:
        raise UsageError("only --simulated grasp impacts are available; a real grasping "
                         "interface needs its own recording driver")
    if args.impacts < 3:
        raise UsageError(f"--impacts {args.impacts}: a line through m, c and k against grasp "
                         "force fitted to fewer than 3 impacts has no residual to judge it by")
    if args.seed < 0:
        raise UsageError(f"--seed must be >= 0, got {args.seed}")
    tissue = TISSUE if args.rig == "tissue" else None
    rig = GraspRig(tissue=tissue)
    result = identify_grasp(rig.impacts(args.impacts, args.seed), estimate=args.estimate)
    result["rig"] = {"kind": args.rig, "tissue": list(tissue) if tissue else None}
    result["published"] = {"m": dict(zip(("intercept", "slope"), PUBLISHED.m, strict=True)),
                           "c": dict(zip(("intercept", "slope"), PUBLISHED.c, strict=True)),
                           "k": dict(zip(("intercept", "slope"), PUBLISHED.k, strict=True))}
    # the published rig draws its impacts from the published lines: how far a fit lands
    # from them is the estimator's error on this seed (a round trip); the tissue rig adds a
    # mode the fitted model lacks: what a second-order fit makes of such impacts
    result["error_vs_published"] = {
        p: {part: result[p][part] / result["published"][p][part] - 1.0
            for part in ("intercept", "slope")} for p in ("m", "c", "k")}
    result["seed"] = args.seed
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        for p, unit in (("m", "kg"), ("c", "N·s/m"), ("k", "N/m")):
            r, pub, err = result[p], result["published"][p], result["error_vs_published"][p]
            print(f"{p} = {r['intercept']:.5g} {r['slope']:+.4g}·F_g {unit}   (published "
                  f"{pub['intercept']:g} {pub['slope']:+g}·F_g: intercept "
                  f"{err['intercept']:+.1%}, slope {err['slope']:+.1%})")
        fp = result["fit_percent"]
        print(f"fit % median {fp['median']:.1f} ({args.estimate}); by estimate: "
              + ", ".join(f"{k} {v:.1f}" for k, v in fp["by_estimate"].items()))
        if tissue is None:
            print("the published rig draws its impacts from the published lines, so these "
                  "differences are the estimator's error on this seed (a round trip)")
        else:
            print(f"the tissue rig's handle is the published model with a mode it does not "
                  f"have ({tissue[0]:g} of its mass at {tissue[1]:g}× its frequency, damping "
                  f"ratio {tissue[2]:g}; sized so the manual fit % is in the paper's range): "
                  "these differences are what a second-order fit makes of such impacts")
    return 0


def _clock(seconds: float | None) -> str:
    if seconds is None:
        return "time left: after the first measurement"
    m, sec = divmod(int(round(seconds)), 60)
    return f"~{m}:{sec:02d} left"


def _step_line(step) -> None:
    """Progress of a long device job, one line per measurement (stderr)."""
    print(f"  [{step.done:2d}/{step.total}] {step.what}; {_clock(step.seconds_left)}",
          file=sys.stderr, flush=True)


def fault_prompt(device, kept: Callable[[], str]) -> Callable:
    """``on_fault`` for a person at the terminal: one line on what happened and what to do,
    then ``c`` clears the fault and measures again, ``q`` stops (what was measured is kept).
    Without a terminal there is nobody to confirm: the job stops at once."""
    if not sys.stdin.isatty():
        return None

    def on_fault(fault, what: str) -> bool:
        code = fault.code if fault is not None else "latched"
        cause = {"watchdog": "the device heard nothing from this computer for its watchdog "
                             "period and zeroed its output (the computer was too busy, or "
                             "the cable is loose)",
                 "estop": "an e-stop zeroed the output"}.get(code, "the device zeroed its "
                                                             "output")
        print(f"hapticlab: {code.upper()} during {what}: {cause}. {kept()}. Make it safe, "
              "then c + ENTER clears the fault and measures it again; q + ENTER stops "
              "(the same command continues later)", file=sys.stderr, flush=True)
        while True:
            try:
                answer = input("c / q: ").strip().lower()
            except EOFError:
                return False
            if answer == "q":
                return False
            if answer == "c":
                try:
                    device.clear_fault()
                except DeviceFaultError as exc:
                    print(f"hapticlab: not cleared: {exc}", file=sys.stderr, flush=True)
                    continue
                print("hapticlab: fault cleared; measuring again", file=sys.stderr, flush=True)
                return True

    return on_fault


def library_build(args: argparse.Namespace, open_spec, load_protocol) -> int:
    from device.matching.library import (
        BuildRecord,
        MeasurementFault,
        build_key,
        build_library,
        library_path,
        record_path,
    )

    protocol = load_protocol(args.protocol)
    if args.source not in protocol.samples or not protocol.samples[args.source].is_real:
        real = [k for k, s in protocol.samples.items() if s.is_real]
        raise UsageError(f"--source must be a real sample of {protocol.source}: "
                         f"{', '.join(real)}; got {args.source!r}")
    if args.entries < 2 or args.windows < 1:
        raise UsageError("--entries must be >= 2 and --windows >= 1")
    source = protocol.samples[args.source].scene
    again = "hapticlab " + shlex.join(["library", "build", "--device", args.device,
                                       "--protocol", args.protocol, "--source", args.source,
                                       "--entries", str(args.entries), "--windows",
                                       str(args.windows), "--method", args.method,
                                       *(["--out", str(args.out)] if args.out else []),
                                       "--clear-fault"])
    with open_spec(args.device) as dev:
        out = args.out or library_path(dev.info, source)
        key = build_key(dev.info, source, entries=args.entries, windows=args.windows)
        record = _opened(BuildRecord.open(record_path(out), key, restart=args.restart),
                         "measurements")

        def kept() -> str:
            return f"{record.count} finished measurements are kept in {record.path}"

        print(f"building the {args.source} library on {args.device}: 12 sweeps (~40 s), "
              f"{args.windows} tapping windows of 5 s; hold the stylus during the sweeps, "
              "tap the real sample during the windows", file=sys.stderr, flush=True)
        try:
            lib = build_library(dev, source, entries=args.entries, method=args.method,
                                windows=args.windows, record=record,
                                on_fault=fault_prompt(dev, kept), on_step=_step_line)
        except MeasurementFault as exc:
            raise DeviceError(f"{exc}. {kept()}; once it is safe, continue with: {again}"
                              ) from None
        except HapticlabError as exc:
            if record.count:
                raise type(exc)(f"{exc}. {kept()}; continue with: {again}") from None
            raise
        path = lib.save(out)
        errs = lib.provenance["inversion"]["in_window_error"]
        print(f"wrote {path}: {len(lib.velocities)} transients for {args.source} on "
              f"{args.device} ({lib.velocities.min():.3f}–{lib.velocities.max():.3f} m/s), "
              f"{args.method} inversion, in-window error median {np.median(errs):.2f} (through "
              "the identified model, ‖reply − tap‖ / ‖tap‖ over the window: 0 reproduces each "
              "tap's acceleration exactly, 1 is no better than playing nothing; the "
              f"verification below says how close it comes on the device); sha256 "
              f"{lib.sha256[:16]}…")
        if args.verify:
            _verify(dev, protocol, args, path, record.windows)
    record.discard()
    return 0


def _verify(dev, protocol, args, path: Path, real) -> None:
    """Tap the protocol's matched sample with the new library and its spring alone, and
    say how close each comes to the real taps the build recorded."""
    import dataclasses

    from device.matching.compare import verify_library
    from device.matching.measure import MeasurementFault, Pace

    matched = next((s.scene for s in protocol.samples.values()
                    if s.scene.transient is not None and s.scene.transient.kind == "library"
                    and s.scene.transient.source == args.source), None)
    if matched is None:
        print(f"not verified: no sample of {protocol.source} plays the {args.source} library")
        return
    play = dataclasses.replace(matched, transient=dataclasses.replace(matched.transient,
                                                                      path=str(path)))
    spring = dataclasses.replace(matched, transient=None)
    print(f"verifying: {args.verify} tapping windows on '{matched.name}' (its spring and the "
          f"library × {matched.transient.attenuation:g}) and {args.verify} on its spring "
          "alone; tap as on the real sample", file=sys.stderr, flush=True)
    pace = Pace([5.0] * (2 * args.verify), 0, _step_line)
    try:
        v = verify_library(dev, real, play, spring, args.verify,
                           on_fault=fault_prompt(dev, lambda: "the library is written"),
                           pace=pace)
    except (MeasurementFault, ValueError) as exc:
        print(f"not verified ({exc}); the library is written")
        return
    print(f"spectral distance to the real {args.source} taps (RMS dB over 10–500 Hz; 0 dB: the "
          f"same spectra, 6 dB: a factor of two): with the library {v.matched_db:.1f} dB — "
          f"{v.verdict()}; the spring alone, the baseline, {v.spring_db:.1f} dB "
          f"({v.matched_taps} and {v.spring_taps} taps)")


def library_show(args: argparse.Namespace, open_spec) -> int:
    from device.matching.library import TransientLibrary

    info = None
    if args.device:
        with open_spec(args.device) as dev:
            info = dev.info
    lib = TransientLibrary.load(args.file, info)
    made = lib.provenance
    print(f"{args.file}: format {made['format_version']}, sha256 {lib.sha256[:16]}…")
    print(f"  device  {made['device']['model']} serial {made['device']['serial_number']} at "
          f"{lib.rate_hz:g} Hz")
    print(f"  source  {made['source']['sample']} ({made['source']['taps_recorded']} clean taps "
          f"from {made['source']['windows']} windows)")
    inv = made["inversion"]
    print(f"  inverse {inv['method']}, λ = {inv['lambda']:g}, band {inv['band_hz']} Hz; "
          f"in-window error median {np.median(inv['in_window_error']):.2f}")
    print(f"  entries {len(lib.velocities)}: " + ", ".join(f"{v:.3f}" for v in lib.velocities)
          + f" m/s; {lib.nbytes} bytes on the device")
    if args.png:
        plt = _agg()
        t = np.arange(lib.forces.shape[1]) / lib.rate_hz * 1e3
        fig, ax = plt.subplots(1, 2, figsize=(10, 4))
        cmap = plt.get_cmap("viridis")
        for i, (v, f) in enumerate(zip(lib.velocities, lib.forces, strict=True)):
            ax[0].plot(t, f, color=cmap(i / max(1, len(lib.velocities) - 1)), lw=0.8,
                       label=f"{v:.3f} m/s" if i in (0, len(lib.velocities) - 1) else None)
        ax[0].set_xlabel("time after contact [ms]")
        ax[0].set_ylabel("force [N]")
        ax[0].legend()
        ax[0].set_title(f"transients for {made['source']['sample']}")
        ax[1].plot(lib.velocities, np.abs(lib.forces).max(axis=1), "o-")
        ax[1].set_xlabel("incoming speed [m/s]")
        ax[1].set_ylabel("peak force [N]")
        ax[1].set_title("peak force against speed")
        fig.tight_layout()
        fig.savefig(args.png, dpi=110)
        print(f"  plot    {args.png}")
    return 0


def add_parsers(device_sub, sub, func, clear_fault) -> None:
    """Register the matching commands on the ``device`` sub-parser and a ``library`` command.

    ``func(args)`` runs them (it dispatches on ``args.action``); ``clear_fault(parser)``
    adds ``--clear-fault`` to those that open a device.
    """
    di = device_sub.add_parser("sysid", help="system identification: force → acceleration "
                               "on a device, with the hand holding the stylus")
    di.add_argument("--device", default="sim", help="device spec: sim (default) or "
                    "serial:PORT")
    di.add_argument("--order", type=int, default=7, help="model order (poles, default 7)")
    di.add_argument("--relative-degree", type=int, default=4,
                    help="poles minus zeros of the model (default 4)")
    di.add_argument("--delay", type=float, default=None, help="fixed delay [ms]; default: fit it")
    di.add_argument("--levels", type=float, nargs="+", default=[0.5, 1.0, 1.5],
                    help="sweep force amplitudes [N]")
    di.add_argument("--repeats", type=int, default=4, help="sweeps per force level "
                    "(default 4)")
    di.add_argument("--png", type=Path, help="plot the fit to this PNG file")
    di.add_argument("--json", action="store_true", help="print the model as JSON")
    di.add_argument("--restart", action="store_true", help="measure every sweep again "
                    "(default: keep those an interrupted run finished)")
    clear_fault(di)
    di.set_defaults(action="sysid", func=func)

    dg = device_sub.add_parser("fit-grasp", help="fit the grasp-force model to impacts (SPEC §3)")
    dg.add_argument("--simulated", action="store_true", help="use the simulated grasping rig")
    dg.add_argument("--impacts", type=int, default=100, help="impacts to fit (default 100)")
    dg.add_argument("--rig", choices=("tissue", "published"), default="tissue",
                    help="tissue (default): the published handle with a mode the fitted "
                    "model lacks, sized to the paper's manual fit %%; published: the published "
                    "model alone (a round trip that checks the estimators)")
    dg.add_argument("--seed", type=int, default=1, help="seed of the simulated rig "
                    "(default 1)")
    dg.add_argument("--estimate", choices=("ls", "manual", "rls"), default="ls",
                    help="least squares (default), the paper's manual fit from frequency, "
                    "settling time and peak gain, or recursive least squares")
    dg.add_argument("--json", action="store_true", help="print the fit as JSON")
    dg.set_defaults(action="fit-grasp", func=func)

    lib = sub.add_parser("library", help="acceleration-matched transient libraries")
    lsub = lib.add_subparsers(dest="library_command", required=True, metavar="ACTION")
    lb = lsub.add_parser("build", help="record, identify, invert: build a library on a device "
                         "(into the library store, where sessions on that device find it)")
    lb.add_argument("--device", default="sim", help="device spec: sim (default) or "
                    "serial:PORT — the device the library will play on")
    lb.add_argument("--protocol", default="realism", help="protocol holding the source sample")
    lb.add_argument("--source", default="wood_on_foam", help="real sample to reproduce")
    lb.add_argument("--entries", type=int, default=12, help="transients in the library, "
                    "spread over the tapped speeds (default 12)")
    lb.add_argument("--windows", type=int, default=8, help="5-s tap windows to record")
    lb.add_argument("--method", choices=("regularized", "stable"), default="regularized",
                    help="inversion: regularized in the frequency domain (default) or "
                    "exact stable inversion (zeros outside the circle anti-causally)")
    lb.add_argument("--out", type=Path, default=None,
                    help="write here instead of the library store (a protocol's sample then "
                    "names it in 'path')")
    lb.add_argument("--verify", type=int, default=2, metavar="N",
                    help="then tap the matched sample and its spring alone N windows each and "
                    "compare both with the real taps (0: do not)")
    lb.add_argument("--restart", action="store_true",
                    help="measure everything again (a build that stopped resumes by default "
                    "from the measurements it kept)")
    clear_fault(lb)
    lb.set_defaults(action="library-build", func=func)
    ls = lsub.add_parser("show", help="describe a library file and plot it")
    ls.add_argument("file", type=Path, help="a library file (.npz)")
    ls.add_argument("--png", type=Path, help="plot the library to this PNG file")
    ls.add_argument("--device", help="also check the library belongs to this device")
    clear_fault(ls)
    ls.set_defaults(action="library-show", func=func)
