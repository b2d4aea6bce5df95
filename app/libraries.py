"""Transient libraries for the device a session uses: found in the store, or built — as an
announced step — when the device is simulated.

Acceleration matching inverts one device's dynamics, so a matched sample plays a library
built on the very device in use. A protocol names the real sample a library reproduces;
:func:`prepare_libraries` finds each library in the store (or the file a sample names),
builds a missing one on a simulated device (saying so first: it is an experiment of its
own), and refuses a real device that has none, naming the command that builds it. The
paths it returns are recorded in session.json, so a library added later never changes a
started session.
"""

from __future__ import annotations

import dataclasses
import shlex
from collections.abc import Callable

from device import LibraryTransient, open_device
from device.matching.library import LibraryError, TransientLibrary, build_into_store, find_library

from .errors import MissingLibraryError

__all__ = ["prepare_libraries", "with_libraries", "check_recorded", "build_line",
           "builds_on_demand", "LIBRARY_SEED", "BUILD_SECONDS"]

#: seed of the fresh simulated device a simulated library is built on (reproducible builds)
LIBRARY_SEED = 20_260_001
#: measured time to build one library on the simulated device (8 windows, identification,
#: 12 inversions), for the announcement
BUILD_SECONDS = 5


def builds_on_demand(info) -> bool:
    """Whether a missing library is built when a session first needs it on the device
    ``info`` describes (:class:`~device.DeviceInfo`): on a simulated contact in virtual
    time, where the build's tapping windows take seconds and nobody taps. On any other
    device it is an experiment of its own, run by the operator (:func:`build_line`)."""
    return bool(info.simulated_contact and info.virtual_time)


def build_line(spec: str, protocol: str, source: str) -> str:
    """The command that builds the library of ``source`` for ``protocol`` on ``spec``."""
    return shlex.join(["hapticlab", "library", "build", "--device", spec, "--protocol",
                       protocol, "--source", source])


def _matched(protocol) -> dict[str, tuple[LibraryTransient, list[str]]]:
    """source sample → (its library transient, the matched samples using it)."""
    out: dict[str, tuple[LibraryTransient, list[str]]] = {}
    for sid, s in protocol.samples.items():
        tr = s.scene.transient
        if isinstance(tr, LibraryTransient):
            key = tr.path or tr.source
            out.setdefault(key, (tr, []))[1].append(sid)
    return out


def prepare_libraries(protocol, device, spec: str, say: Callable[[str], None] = print,
                      build: bool = True, ref: str | None = None,
                      opener: Callable[[], object] | None = None) -> dict[str, dict]:
    """The library file each matched sample of ``protocol`` plays on ``device``.

    Parameters
    ----------
    protocol : Protocol
    device : HapticDevice
        The device in use (its :class:`~device.DeviceInfo` decides which library fits).
    spec : str
        How ``device`` was opened: a missing library of a simulated device is built on a
        fresh device opened from the same spec.
    say : callable
        Where the announcement of a build goes.
    build : bool
        False: never build; report what is missing instead.
    ref : str, optional
        How the user names the protocol (a built-in name or a path), for the command.
    opener : callable, optional
        Opens a fresh device like ``device`` to build on (default: ``open_device(spec)``
        with :data:`LIBRARY_SEED`).

    Returns
    -------
    dict
        sample id → ``{"source", "path", "sha256"}``.

    Raises
    ------
    MissingLibraryError
        A library that is missing on a real device (or ``build=False``), or a file that is
        corrupt or from another device; the message names the samples and the command.
    """
    info = device.info
    out: dict[str, dict] = {}
    missing, broken = [], []
    for tr, samples in _matched(protocol).values():
        try:
            path = find_library(info, tr)
        except LibraryError as exc:
            broken.append(f"{', '.join(samples)}: {exc}")
            continue
        if path is None and build and builds_on_demand(info):
            say(f"building the {tr.source} library on this device, first use: "
                f"~{BUILD_SECONDS} s (identification, 8 tapping windows, inversions)")
            fresh = opener() if opener is not None else open_device(spec, seed=LIBRARY_SEED)
            with fresh as twin:
                path = build_into_store(twin, tr.source_scene)
        if path is None:
            missing.append((tr.source, samples))
            continue
        try:
            lib = TransientLibrary.load(path, info)
        except LibraryError as exc:
            broken.append(f"{', '.join(samples)}: {exc}")
            continue
        for sid in samples:
            out[sid] = {"source": tr.source, "path": str(path), "sha256": lib.sha256}
    if missing and not info.accelerometer:
        problems = [f"{', '.join(samples)} need(s) a library reproducing '{src}', built on the "
                    "device that plays it from its accelerometer's readings; this device "
                    f"({info.model}, serial {info.serial_number}) has no accelerometer on the "
                    "stylus, so no library can be built on it: run these samples on a device "
                    "with one, or leave them out of the protocol"
                    for src, samples in missing] + broken
    else:
        problems = [f"{', '.join(samples)} need(s) a library reproducing '{src}' built on "
                    f"this device ({info.model}, serial {info.serial_number}); build it "
                    "with: " + build_line(spec, str(ref or protocol.source), src)
                    for src, samples in missing] + broken
    if problems:
        raise MissingLibraryError("; ".join(problems))
    return out


def with_libraries(protocol, libraries: dict[str, dict]):
    """``protocol`` with each matched sample's library file set (the protocol's hash, which
    is of its text, is unchanged)."""
    samples = dict(protocol.samples)
    for sid, lib in libraries.items():
        s = samples[sid]
        tr = dataclasses.replace(s.scene.transient, path=lib["path"])
        samples[sid] = dataclasses.replace(s, scene=dataclasses.replace(s.scene, transient=tr))
    return dataclasses.replace(protocol, samples=samples)


def check_recorded(libraries: dict[str, dict], device) -> None:
    """The library files a session recorded are still there, unchanged, and made on this
    device (a resume refuses to start otherwise).

    Raises
    ------
    MissingLibraryError
        Naming the sample, the file and what is wrong.
    """
    for sid, lib in libraries.items():
        try:
            got = TransientLibrary.load(lib["path"], device.info)
        except LibraryError as exc:
            raise MissingLibraryError(f"sample {sid}: the library this session started with "
                                      f"cannot be used: {exc}") from None
        if got.sha256 != lib.get("sha256", got.sha256):
            raise MissingLibraryError(f"sample {sid}: {lib['path']} changed since the session "
                                      "started (its SHA-256 differs); restore it to resume")
