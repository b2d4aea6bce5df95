"""The acceleration-matching and grasp-model jobs as functions: system identification on a
device, the grasp model's fit, a transient library's build and its description. The CLI
(:mod:`app.matching_cli`) prints what they return; nothing here reads a terminal.

A job on a device keeps every finished measurement in a build record beside its output,
so a fault costs one measurement: ``on_fault(device, kept)`` may return a callback that
asks the operator (:func:`app.matching_cli.fault_prompt`), and without one the job stops
at the first fault, saying what is kept and the command (``again``) that continues.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from device.errors import DeviceError, HapticlabError

from .errors import UsageError

__all__ = ["identify_device", "fit_grasp", "build_library_file", "describe_library"]

Say = Callable[[str], None]
#: ``(device, kept) -> on_fault or None``: how a fault is put to the operator
FaultAsk = Callable[[Any, Callable[[], str]], Callable | None]


def _open(device: str, clear_fault: bool, say: Say | None):
    """The device, a fault it latched cleared when asked, and said (``say``, else stderr:
    a cleared fault is never silent)."""
    from .api import open_device_for

    return open_device_for(device, clear_fault=clear_fault, say=say)


def _opened(record, what: str, say: Say) -> Any:
    """``record`` after saying whether it resumes an earlier run (``what``: the kept
    measurements' noun, "measurements" or "of 12 sweeps")."""
    if record.set_aside:
        say(f"hapticlab: not resuming from {record.path} ({record.set_aside}): measuring "
            "afresh")
    elif record.resumed:
        say(f"hapticlab: resuming: {record.resumed} {what} kept from an earlier run "
            f"({record.path}; --restart measures everything again)")
    return record


def _quiet(_: str) -> None:
    pass


def identify_device(device: str = "sim", *, levels: tuple[float, ...] = (0.5, 1.0, 1.5),
                    repeats: int = 4, order: int = 7, relative_degree: int = 4,
                    delay_ms: float | None = None, restart: bool = False,
                    clear_fault: bool = False, say: Say | None = None,
                    on_fault: FaultAsk | None = None, on_step: Callable | None = None,
                    again: str = "the same job with clear_fault") -> dict:
    """Identify force → acceleration on ``device`` with the hand holding the stylus: swept
    sines at each force level [N], ``repeats`` times, then a model of ``order`` poles and
    ``relative_degree`` poles minus zeros (delay fitted unless ``delay_ms`` [ms]).

    Returns
    -------
    dict
        ``device``, ``rate_hz``, ``levels_n``, ``repeats``, ``model`` (numerator,
        denominator, delay [s], its band [Hz] and fit errors [dB, °]), ``coherence``
        (``min``, ``median``), ``resonance_hz``; and, for plotting, ``_idn`` (the
        identification object, not JSON).

    Raises
    ------
    DeviceError
        A fault the operator did not clear: the message says what is kept and ``again``.
    """
    import numpy as np

    from device.matching.library import (
        PIPELINE_VERSION,
        BuildRecord,
        sysid_record_path,
        usable_band,
    )
    from device.matching.measure import MeasurementFault, Pace
    from device.matching.sysid import identify_system, sweep_seconds

    tell = say or _quiet  # progress; a cleared fault is said even without ``say``
    with _open(device, clear_fault, say) as dev:
        band = usable_band(dev.info.servo_rate_hz)
        n = len(levels) * repeats
        # finished sweeps are kept until the model is fitted, so a fault (cleared at the
        # prompt, or by running the command again) costs one sweep, never the others
        info = dev.info
        key = {"sysid": 1, "pipeline": PIPELINE_VERSION,
               "device": [info.model, info.serial_number, info.servo_rate_hz],
               "levels": [float(v) for v in levels], "repeats": repeats,
               "band_hz": [float(v) for v in band],
               "sweep_s": sweep_seconds(info.servo_rate_hz, band)}
        record = _opened(BuildRecord.open(sysid_record_path(info), key, restart=restart),
                         f"of {n} sweeps", tell)
        pace = Pace([sweep_seconds(info.servo_rate_hz, band)] * n, record.count, on_step)

        def kept() -> str:
            return f"{record.count} of {n} sweeps are kept in {record.path}"

        try:
            idn = identify_system(dev, levels=tuple(levels), repeats=repeats, band=band,
                           order=order, relative_degree=relative_degree,
                           delay=None if delay_ms is None else delay_ms * 1e-3,
                           record=record, on_fault=on_fault and on_fault(dev, kept),
                           pace=pace)
        except MeasurementFault as exc:
            raise DeviceError(f"{exc}; {kept()}. Once it is safe, continue with: "
                              f"{again}") from None
    e = idn.etfe.in_band(band)
    record.discard()  # the model is out: the sweeps are no longer needed
    return {"device": device, "rate_hz": idn.rate_hz, "levels_n": list(idn.levels),
            "repeats": idn.repeats, "model": idn.model.to_dict(),
            "coherence": {"min": float(e.coherence.min()),
                          "median": float(np.median(e.coherence))},
            "resonance_hz": float(e.freq[np.argmax(np.abs(e.H))]), "_idn": idn}


def fit_grasp(*, impacts: int = 100, seed: int = 1, rig: str = "tissue",
              estimate: str = "ls", simulated: bool = True) -> dict:
    """Fit the grasp-force model (SPEC §3: m, c and k each a line in grasp force) to
    ``impacts`` impacts of the simulated grasping rig (``tissue``: the published handle
    with a mode the model lacks; ``published``: the published model alone, a round trip),
    by ``estimate`` (``ls``, ``manual`` or ``rls``).

    Returns
    -------
    dict
        ``m``, ``c``, ``k`` (``intercept``, ``slope`` per N of grasp force), ``fit_percent``,
        ``rig``, ``published``, ``error_vs_published`` (relative, per part) and ``seed``.

    Raises
    ------
    UsageError
        Real impacts (no recording driver), fewer than 3 impacts, a negative seed.
    """
    from device.matching.grasp import PUBLISHED, TISSUE, GraspRig, identify_grasp

    if not simulated:
        raise UsageError("only --simulated grasp impacts are available; a real grasping "
                         "interface needs its own recording driver")
    if impacts < 3:
        raise UsageError(f"--impacts {impacts}: a line through m, c and k against grasp "
                         "force fitted to fewer than 3 impacts has no residual to judge it by")
    if seed < 0:
        raise UsageError(f"--seed must be >= 0, got {seed}")
    tissue = TISSUE if rig == "tissue" else None
    result = identify_grasp(GraspRig(tissue=tissue).impacts(impacts, seed), estimate=estimate)
    result["rig"] = {"kind": rig, "tissue": list(tissue) if tissue else None}
    result["published"] = {p: dict(zip(("intercept", "slope"), getattr(PUBLISHED, p),
                                       strict=True)) for p in ("m", "c", "k")}
    # the published rig draws its impacts from the published lines: how far a fit lands
    # from them is the estimator's error on this seed (a round trip); the tissue rig adds a
    # mode the fitted model lacks: what a second-order fit makes of such impacts
    result["error_vs_published"] = {
        p: {part: result[p][part] / result["published"][p][part] - 1.0
            for part in ("intercept", "slope")} for p in ("m", "c", "k")}
    result["seed"] = seed
    return result


def build_library_file(device: str = "sim", *, protocol: str = "realism",
                       source: str = "wood_on_foam", entries: int = 12, windows: int = 8,
                       method: str = "regularized", out: Path | None = None, verify: int = 2,
                       restart: bool = False, clear_fault: bool = False,
                       say: Say | None = None, on_fault: FaultAsk | None = None,
                       on_step: Callable | None = None,
                       on_written: Callable[[dict], None] | None = None,
                       again: str = "the same job with clear_fault") -> dict:
    """Record, identify, invert: build the transient library of real sample ``source`` of
    ``protocol`` on ``device`` (``entries`` transients over the speeds tapped in ``windows``
    windows of 5 s; ``method`` ``regularized`` or ``stable``), written to ``out`` or the
    library store; then, with ``verify`` > 0, tap the matched sample and its spring alone
    ``verify`` windows each and compare both with the real taps.

    ``on_written(result)`` hears of the file before the verification starts.

    Returns
    -------
    dict
        ``path``, ``sha256``, ``source``, ``device``, ``method``, ``entries``,
        ``speeds_m_s`` (lowest, highest), ``in_window_error_median`` (0: each tap's
        acceleration reproduced exactly through the model, 1: no better than nothing), and
        ``verification``: ``matched_db``, ``spring_db``, ``verdict``, the taps of each, or
        ``not_verified`` with the reason.

    Raises
    ------
    UsageError
        A source that is not a real sample of the protocol, too few entries or windows.
    DeviceError
        A fault the operator did not clear, or another device error after measurements
        were kept: the message says what is kept and ``again``.
    """
    import numpy as np

    from device.matching.library import (
        BuildRecord,
        MeasurementFault,
        build_key,
        build_library,
        library_path,
        record_path,
    )
    from protocols import load_protocol

    tell = say or _quiet  # progress; a cleared fault is said even without ``say``
    proto = load_protocol(protocol)
    if source not in proto.samples or not proto.samples[source].is_real:
        real = [k for k, s in proto.samples.items() if s.is_real]
        raise UsageError(f"--source must be a real sample of {proto.source}: "
                         f"{', '.join(real)}; got {source!r}")
    if entries < 2 or windows < 1:
        raise UsageError("--entries must be >= 2 and --windows >= 1")
    scene = proto.samples[source].scene
    with _open(device, clear_fault, say) as dev:
        target = out or library_path(dev.info, scene)
        key = build_key(dev.info, scene, entries=entries, windows=windows)
        record = _opened(BuildRecord.open(record_path(target), key, restart=restart),
                         "measurements", tell)

        def kept() -> str:
            return f"{record.count} finished measurements are kept in {record.path}"

        tell(f"building the {source} library on {device}: 12 sweeps (~40 s), {windows} "
            "tapping windows of 5 s; hold the stylus during the sweeps, tap the real sample "
            "during the windows")
        try:
            lib = build_library(dev, scene, entries=entries, method=method, windows=windows,
                                record=record, on_fault=on_fault and on_fault(dev, kept),
                                on_step=on_step)
        except MeasurementFault as exc:
            raise DeviceError(f"{exc}. {kept()}; once it is safe, continue with: {again}"
                              ) from None
        except HapticlabError as exc:
            if record.count:
                raise type(exc)(f"{exc}. {kept()}; continue with: {again}") from None
            raise
        path = lib.save(target)
        result: dict[str, Any] = {
            "path": str(path), "sha256": lib.sha256, "source": source, "device": device,
            "method": method, "entries": len(lib.velocities),
            "speeds_m_s": [float(lib.velocities.min()), float(lib.velocities.max())],
            "in_window_error_median": float(np.median(
                lib.provenance["inversion"]["in_window_error"]))}
        if on_written is not None:
            on_written(result)
        if verify:
            result["verification"] = _verify(dev, proto, source, verify, path,
                                             record.windows, tell, on_fault, on_step)
    record.discard()
    return result


def _verify(dev, protocol, source: str, n: int, path: Path, real, say: Say,
            on_fault: FaultAsk | None, on_step) -> dict:
    """Tap the protocol's matched sample with the new library and its spring alone, and
    say how close each comes to the real taps the build recorded."""
    import dataclasses

    from device.matching.compare import verify_library
    from device.matching.measure import MeasurementFault, Pace

    matched = next((s.scene for s in protocol.samples.values()
                    if s.scene.transient is not None and s.scene.transient.kind == "library"
                    and s.scene.transient.source == source), None)
    if matched is None:
        return {"not_verified": f"no sample of {protocol.source} plays the {source} library"}
    play = dataclasses.replace(matched, transient=dataclasses.replace(matched.transient,
                                                                      path=str(path)))
    spring = dataclasses.replace(matched, transient=None)
    say(f"verifying: {n} tapping windows on '{matched.name}' (its spring and the library × "
        f"{matched.transient.attenuation:g}) and {n} on its spring alone; tap as on the real "
        "sample")
    try:
        v = verify_library(dev, real, play, spring, n,
                           on_fault=on_fault and on_fault(dev, lambda: "the library is written"),
                           pace=Pace([5.0] * (2 * n), 0, on_step))
    except (MeasurementFault, ValueError) as exc:
        return {"not_verified": str(exc)}
    return {"matched_db": v.matched_db, "spring_db": v.spring_db, "verdict": v.verdict(),
            "matched_taps": v.matched_taps, "spring_taps": v.spring_taps}


def describe_library(file: str | Path, *, device: str | None = None,
                     clear_fault: bool = False, say: Say | None = None):
    """A library file read and verified (its content hash; with ``device``, that it was
    made on that device).

    Returns
    -------
    TransientLibrary
        Its speeds [m/s], transients [N] and ``provenance`` (how it was made).

    Raises
    ------
    LibraryError
        A corrupt or edited file, another format, or another device's library.
    """
    from device.matching.library import TransientLibrary

    info = None
    if device:
        with _open(device, clear_fault, say) as dev:
            info = dev.info
    return TransientLibrary.load(file, info)
