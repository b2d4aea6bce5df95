"""Command-line actions for acceleration matching and the grasp model: what the functions
of :mod:`app.matching` return, printed and plotted, and the operator's prompt at a fault."""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from device.errors import DeviceFaultError

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


def _say(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def device_sysid(args: argparse.Namespace) -> int:
    from .matching import identify_device

    report = identify_device(args.device, levels=tuple(args.levels), repeats=args.repeats,
                             order=args.order, relative_degree=args.relative_degree,
                             delay_ms=args.delay, restart=args.restart,
                             clear_fault=args.clear_fault, say=_say, on_fault=fault_prompt,
                             on_step=_step_line, again=_sysid_again(args))
    idn = report.pop("_idn")
    m, band = idn.model, report["model"]["band_hz"]
    if args.png:
        _plot_sysid(idn, band, args.device, args.png)
        report["png"] = str(args.png)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(f"identified {args.device}: {m.order}th order, relative degree "
              f"{m.relative_degree}, delay {m.delay * 1e3:.3g} ms; fit over "
              f"{band[0]:g}–{band[1]:g} Hz: {m.err_db_rms:.2f} dB rms ({m.err_db_max:.2f} max), "
              f"{m.err_deg_rms:.1f}° rms ({m.err_deg_max:.1f}° max); resonance "
              f"{report['resonance_hz']:.0f} Hz; coherence ≥ {report['coherence']['min']:.2f}")
    return 0


def _plot_sysid(idn, band, device: str, png: Path) -> None:
    plt = _agg()
    m = idn.model
    e = idn.etfe.in_band(band)
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
    fig.suptitle(f"force → acceleration, {device} (hand holding the stylus)")
    fig.tight_layout()
    fig.savefig(png, dpi=110)


def device_fit_grasp(args: argparse.Namespace) -> int:
    from .matching import fit_grasp

    result = fit_grasp(impacts=args.impacts, seed=args.seed, rig=args.rig,
                       estimate=args.estimate, simulated=args.simulated)
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    for p, unit in (("m", "kg"), ("c", "N·s/m"), ("k", "N/m")):
        r, pub, err = result[p], result["published"][p], result["error_vs_published"][p]
        print(f"{p} = {r['intercept']:.5g} {r['slope']:+.4g}·F_g {unit}   (published "
              f"{pub['intercept']:g} {pub['slope']:+g}·F_g: intercept "
              f"{err['intercept']:+.1%}, slope {err['slope']:+.1%})")
    fp = result["fit_percent"]
    print(f"fit % median {fp['median']:.1f} ({args.estimate}); by estimate: "
          + ", ".join(f"{k} {v:.1f}" for k, v in fp["by_estimate"].items()))
    tissue = result["rig"]["tissue"]
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


def fault_prompt(device, kept: Callable[[], str]) -> Callable | None:
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


def library_build(args: argparse.Namespace) -> int:
    from .matching import build_library_file

    again = "hapticlab " + shlex.join(["library", "build", "--device", args.device,
                                       "--protocol", args.protocol, "--source", args.source,
                                       "--entries", str(args.entries), "--windows",
                                       str(args.windows), "--method", args.method,
                                       *(["--out", str(args.out)] if args.out else []),
                                       "--clear-fault"])

    def written(r: dict) -> None:
        lo, hi = r["speeds_m_s"]
        print(f"wrote {r['path']}: {r['entries']} transients for {r['source']} on "
              f"{r['device']} ({lo:.3f}–{hi:.3f} m/s), {r['method']} inversion, in-window "
              f"error median {r['in_window_error_median']:.2f} (through the identified "
              "model, ‖reply − tap‖ / ‖tap‖ over the window: 0 reproduces each tap's "
              "acceleration exactly, 1 is no better than playing nothing; the verification "
              f"below says how close it comes on the device); sha256 {r['sha256'][:16]}…",
              flush=True)

    r = build_library_file(args.device, protocol=args.protocol, source=args.source,
                           entries=args.entries, windows=args.windows, method=args.method,
                           out=args.out, verify=args.verify, restart=args.restart,
                           clear_fault=args.clear_fault, say=_say, on_fault=fault_prompt,
                           on_step=_step_line, on_written=written, again=again)
    v = r.get("verification")
    if v is not None and "not_verified" in v:
        print(f"not verified ({v['not_verified']}); the library is written")
    elif v is not None:
        print(f"spectral distance to the real {args.source} taps (RMS dB over 10–500 Hz; 0 dB: "
              f"the same spectra, 6 dB: a factor of two): with the library "
              f"{v['matched_db']:.1f} dB — {v['verdict']}; the spring alone, the baseline, "
              f"{v['spring_db']:.1f} dB ({v['matched_taps']} and {v['spring_taps']} taps)")
    return 0


def library_show(args: argparse.Namespace) -> int:
    from .matching import describe_library

    lib = describe_library(args.file, device=args.device, clear_fault=args.clear_fault,
                           say=_say)
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
