"""Checks that run before any device or window opens, so a session cannot start wrong.

Each check returns a :class:`Check` (``ok``, what it saw, and how to fix it); the session
refuses to start on the first failure, and ``hapticlab preflight`` prints them all.
"""

from __future__ import annotations

import errno
import os
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path

from .errors import DataFolderError, DiskFullError, HapticlabError, NotAFolderError, io_error

__all__ = ["Check", "check_data_folder", "expected_session_bytes", "data_folder_ready",
           "PER_WINDOW_BYTES", "PreflightError", "check_terminal", "check_display",
           "check_device", "check_protocol_on", "check_limit", "check_libraries",
           "check_answers", "check_audio", "failed", "rendering_notes"]

#: bytes one tapping window's traces take on disk (compressed NumPy), by ``--traces`` mode;
#: measured on realism sessions (15 MB full, 5 MB contacts over 49 windows)
PER_WINDOW_BYTES = {"full": 320_000, "contacts": 110_000, "none": 0}
ROW_BYTES = 600  # one trials.tsv row, generously


@dataclass(frozen=True)
class Check:
    """One preflight check: its name, whether it passed, what was seen, and the fix."""

    name: str
    ok: bool
    detail: str
    fix: str = ""

    def line(self) -> str:
        mark = "ok  " if self.ok else "FAIL"
        return f"{mark} {self.name}: {self.detail}" + ("" if self.ok or not self.fix
                                                      else f" — {self.fix}")


def expected_session_bytes(protocol, traces: str = "full", redraw_margin: float = 1.5) -> int:
    """A generous estimate of what one session of ``protocol`` writes [bytes]."""
    windows = sum(len(p.samples) * p.repetitions for p in protocol.phases)
    return int(windows * redraw_margin * (PER_WINDOW_BYTES.get(traces, 0) + ROW_BYTES)) \
        + 200_000  # session.json, protocol copy, headroom


def _existing_ancestor(folder: Path) -> Path:
    p = folder.absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def data_folder_ready(folder: str | Path, need_bytes: int = 0) -> Path:
    """Make sure ``folder`` can take a session: a folder (or one that can be created there)
    that this user may write, on a writable file system, with ``need_bytes`` free. Nothing
    is created: a session that does not start leaves no trace.

    Raises
    ------
    DataFolderError
        A subclass naming the folder and the fix: not a folder, read-only, permission
        denied, disk full.
    """
    folder = Path(folder)
    base = _existing_ancestor(folder)
    if not base.is_dir():
        raise NotAFolderError(20, f"data folder {folder}: {base} is not a folder (it is a "
                                  "file or a device); give a folder for the sessions")
    try:
        if os.statvfs(base).f_flag & os.ST_RDONLY:
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(base))
        if not os.access(base, os.W_OK | os.X_OK):
            raise OSError(errno.EACCES, os.strerror(errno.EACCES), str(base))
        if base == folder.absolute():  # an existing folder: prove it with a real write
            fd, probe = tempfile.mkstemp(dir=folder, prefix=".hapticlab-probe-")
            try:
                os.write(fd, b"x")
                os.fsync(fd)
            finally:
                os.close(fd)
                os.unlink(probe)
    except OSError as exc:
        raise io_error(exc, f"data folder {folder} is not writable") from None
    free = shutil.disk_usage(base).free
    if free < need_bytes:
        raise DiskFullError(28, f"data folder {folder}: {free / 1e6:.1f} MB free, a session "
                                f"needs about {need_bytes / 1e6:.1f} MB; free some space or "
                                "record fewer traces (--traces contacts or none)")
    return folder


def check_data_folder(folder: str | Path, need_bytes: int = 0) -> Check:
    """:func:`data_folder_ready` as a preflight :class:`Check`."""
    try:
        data_folder_ready(folder, need_bytes)
    except DataFolderError as exc:
        return Check("data folder", False, str(exc))
    free = shutil.disk_usage(_existing_ancestor(Path(folder))).free
    return Check("data folder", True, f"{folder} writable, {free / 1e9:.1f} GB free "
                                      f"(a session needs about {need_bytes / 1e6:.1f} MB)")


class PreflightError(HapticlabError):
    """A check before the session failed; nothing was recorded."""

    def __init__(self, failed: list[Check]):
        self.failed = failed
        super().__init__("preflight: " + "; ".join(
            f"{c.name}: {c.detail}" + (f" — {c.fix}" if c.fix else "") for c in failed))


def check_terminal() -> Check:
    """A person's session needs the operator at a terminal (r ready, e E-STOP)."""
    if sys.stdin is not None and sys.stdin.isatty():
        return Check("operator keys", True, "a terminal is attached")
    return Check("operator keys", False, "no terminal is attached (started from a launcher or "
                 "an IDE?)", "run hapticlab from a terminal: the operator's keys (r ready, "
                 "e E-STOP) need one")


def check_display() -> Check:
    """A person's session needs a screen for the participant's window."""
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                 or os.environ.get("WAYLAND_DISPLAY")):
        return Check("participant screen", False, "no display (DISPLAY is not set)",
                     "run on the computer whose screen the participant sees")
    return Check("participant screen", True, os.environ.get("DISPLAY", "the system's display"))


def check_device(dev, spec: str, again: str = "") -> Check:
    """The device answers and has no latched fault; ``again`` is the command line that
    repeats this one with ``--clear-fault`` (named in the failure)."""
    i = dev.info
    if dev.fault is not None:
        return Check("device", False, f"{i.model} ({spec}) has a latched {dev.fault.code} "
                     "fault", "make it safe (the stylus held or at rest, the button released), "
                     f"then: {again or 'the same command with --clear-fault'}")
    return Check("device", True, f"{i.model}, serial {i.serial_number}, firmware {i.firmware}, "
                 f"{i.servo_rate_hz:g} Hz, {i.current_limit:g} A × {i.force_constant:g} N/A")


def check_protocol_on(text: str, source: str, dev) -> Check:
    from device import LibraryTransient, SceneError
    from protocols import ProtocolError, parse_protocol

    try:
        proto = parse_protocol(text, source, dev.info)
    except ProtocolError as exc:
        return Check("protocol on this device", False, str(exc))
    for sample in proto.samples.values():  # what only the device itself knows
        scene = sample.scene
        if isinstance(scene.transient, LibraryTransient):  # its file: check_libraries
            scene = replace(scene, transient=None)
        try:
            dev.check_scene(scene)
        except SceneError as exc:
            return Check("protocol on this device", False, f"sample '{sample.id}': {exc}")
    notes = rendering_notes(proto, dev.info)
    return Check("protocol on this device", True, "every transient can be played and the "
                 "limits are within the device's rating"
                 + "".join(f"; warning: {n}" for n in notes))


def rendering_notes(protocol, info) -> list[str]:
    """What a device described by ``info`` plays less faithfully than a protocol asks, one
    sentence per sample (a transient whose peaks fall between its samples); empty: none."""
    out = []
    for sample in protocol.samples.values():
        tr = sample.scene.transient
        if tr is not None and (note := tr.rendering_note(info.servo_rate_hz)):
            out.append(f"sample '{sample.id}': {note}")
    return out


def check_limit(protocol, dev) -> Check:
    from device import CurrentLimitError, DeviceError

    want = protocol.limits.max_current
    if want is None:
        return Check("current limit", True, f"the device's rating, {dev.info.current_limit:g} A")
    try:
        got = dev.set_current_limit(want)
    except CurrentLimitError as exc:
        return Check("current limit", False, f"the protocol's [limits] max_current: {exc}",
                     "lower max_current, or use the device the protocol was written for")
    except DeviceError as exc:
        return Check("current limit", False, str(exc), "use a device that can lower its "
                     "limit, or remove [limits] max_current")
    return Check("current limit", True, f"{got:g} A applied on the device (protocol "
                 f"{want:g} A, rating {dev.info.current_limit:g} A)")


def check_libraries(protocol, dev, spec: str, ref: str, say=None) -> Check:
    from device import SceneError

    from .errors import MissingLibraryError
    from .libraries import builds_on_demand, prepare_libraries, with_libraries

    on_demand = builds_on_demand(dev.info)
    try:
        found = prepare_libraries(protocol, dev, spec, say=say or (lambda _m: None),
                                  build=on_demand and say is not None, ref=ref)
    except MissingLibraryError as exc:
        if on_demand:
            return Check("libraries", True, "missing on this simulated device: built, "
                         "announced, when the session starts")
        return Check("libraries", False, str(exc))
    if not found:
        return Check("libraries", True, "no matched sample")
    bound = with_libraries(protocol, found)
    for sid in sorted(found):  # the tables as this device would take them (its LIMITS)
        try:
            dev.check_scene(bound.samples[sid].scene)
        except SceneError as exc:
            return Check("libraries", False, f"sample '{sid}': {exc}", "build the library "
                         "again with fewer --entries")
    return Check("libraries", True, "built on this device: " + ", ".join(
        f"{sid} ({Path(v['path']).name})" for sid, v in sorted(found.items())))


def check_answers(protocol) -> Check:
    """Every scale point and every answer can be given with the keys the screen offers (the
    screen's own key maps), however the protocol object was made."""
    parts, unreachable = [], []
    if protocol.rating is not None:
        r = protocol.rating
        mode = r.entry_mode
        if mode == "keys":
            missing = sorted(set(r.values) - set(r.key_map().values()))
            if missing:
                unreachable.append(f"ratings {missing} have no key (one-key entry answers "
                                   "0–9 only)")
        how = {"keys": "one number key", "typed": "digits typed, then ENTER",
               "slider": "a slider (arrow keys or the mouse, then ENTER)"}[mode]
        parts.append(f"ratings {r.min}–{r.max}: {how}")
    if protocol.answer is not None:
        keys = protocol.answer.key_map()
        missing = [c for c in protocol.answer.choices if c not in keys.values()]
        if missing:
            unreachable.append(f"answers {missing} have no number key (at most 9 choices)")
        parts.append("names: " + ", ".join(f"{k} = {c}" for k, c in keys.items()
                                            if not k.startswith("num_")))
    from protocols.kinds import phase_kind

    # answers that need no table (a choice between the samples felt): said by what they are
    kinds = [phase_kind(ph.kind) for ph in protocol.phases]
    parts += [f"{r.name}: {r.summary}" for r in {
        k.asks.name: k.asks for k in kinds if k.asks is not None and k.needs is None}.values()]
    if unreachable:
        return Check("answers", False, "; ".join(unreachable), "set [rating] entry = \"typed\" "
                     "or \"slider\", or name fewer choices")
    return Check("answers", True, "; ".join(parts) or "nothing to answer")


def check_audio(enabled: bool, play: bool = False) -> Check:
    if not enabled:
        return Check("audio", True, "off (--no-audio)")
    from .audio import Audio, AudioUnavailable

    try:
        a = Audio()
    except AudioUnavailable as exc:
        return Check("audio", False, str(exc), "connect headphones, or pass --no-audio for a "
                     "session without masking noise and cues")
    try:
        if play:
            a.tap_cue()
            time.sleep(0.8)
            a.low_tone()
            time.sleep(0.6)
    finally:
        a.close()
    return Check("audio", True, "masking noise, the tap cue and the low tone play"
                 + (" (played now: listen for them)" if play else ""))


def failed(checks: list[Check]) -> list[Check]:
    return [c for c in checks if not c.ok]
