"""Transient libraries: record taps on a real sample, invert them, play them back.

Pipeline (:func:`build_library`): identify the device as a system
(:func:`~device.matching.sysid.identify_system`) → record tapping windows on the real
sample → segment contacts at the encoder's position threshold (the device's contact
events) → 100-ms acceleration windows with their incoming speeds, keeping taps not
followed by another contact inside the window → an even spread of speeds → invert each
(:func:`~device.matching.inversion.invert`) → :class:`TransientLibrary`.

File format (``.npz``, version 1): arrays ``velocities`` (n) [m/s], ``forces`` (n, L) [N],
``meta_json`` (UTF-8 JSON: format version, device identity and servo rate, the
identified model, inversion method and parameters, source sample and recordings) and
``sha256`` (hex digest over the canonical JSON and the arrays' little-endian bytes).
Loading checks the version and the hash (a corrupt file is refused) and, given a
device, that the library was made on that very device (model, serial number, rate).

Building is an explicit step (``hapticlab library build``, or the application's
preflight on a simulated device, which announces it); built libraries live in the
library store (:func:`library_dir`), one folder per device, where
:func:`find_library` finds them for the device in use.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DeviceError
from ..events import WindowResult
from ..fileio import atomic_write, file_kind
from ..info import DeviceInfo
from ..scene import LibraryTransient, Scene, TransientTable
from .inversion import METHODS, discretize, invert
from .measure import MeasurementFault, OnFault, OnStep, Pace, measured
from .record import BuildRecord
from .sysid import TFModel, accel_at_every_tick, identify_system, sweep_seconds

__all__ = ["TransientLibrary", "LibraryError", "build_library", "usable_band", "record_taps",
           "segment_taps", "even_spread", "library_dir", "library_path", "find_library",
           "build_into_store", "build_key", "BuildRecord", "MeasurementFault", "record_path",
           "sysid_record_path",
           "FORMAT_VERSION", "Tap", "SWEEP_LEVELS", "SWEEP_REPEATS"]

FORMAT_VERSION = 1
PIPELINE_VERSION = "matching-1"


class LibraryError(DeviceError):
    """A library file is corrupt, of an unknown version, or from another device."""


@dataclass(frozen=True)
class Tap:
    """One segmented contact: incoming speed [m/s] and the acceleration window [m/s²]."""

    velocity: float
    accel: np.ndarray
    t: float


@dataclass
class TransientLibrary:
    """Velocity-indexed force transients for one device.

    Attributes
    ----------
    velocities : ndarray (n,) [m/s]
        Ascending incoming speeds.
    forces : ndarray (n, L) [N]
        Transient per speed at the servo rate.
    provenance : dict
        How it was made (the file's ``meta_json``): ``device`` (DeviceInfo dict),
        ``servo_rate_hz``, ``model`` (identified TF), ``inversion`` (method, λ, band,
        tapers, in-window errors), ``source`` (sample scene and recordings), ``pipeline``.
    """

    velocities: np.ndarray
    forces: np.ndarray
    provenance: dict = field(default_factory=dict)

    @property
    def rate_hz(self) -> float:
        return float(self.provenance["servo_rate_hz"])

    @property
    def sha256(self) -> str:
        return _digest(self.velocities, self.forces, self.provenance)

    @property
    def nbytes(self) -> int:
        """What the device must hold: the force table as float32 plus the speeds."""
        return int(self.forces.size * 4 + self.velocities.size * 4)

    def table(self, attenuation: float = 0.8, blend: str = "linear") -> TransientTable:
        return TransientTable(self.velocities, self.forces, blend, attenuation)

    # ---------------------------------------------------------------- file
    def save(self, path: str | Path) -> Path:
        """Write atomically (:func:`device.fileio.atomic_write`)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        buf = io.BytesIO()
        np.savez(buf, velocities=self.velocities.astype("<f8"), forces=self.forces.astype("<f8"),
                 meta_json=np.array(_canonical(self.provenance)), sha256=np.array(self.sha256))
        atomic_write(path, buf.getvalue())
        return path

    @classmethod
    def load(cls, path: str | Path, device: DeviceInfo | None = None) -> TransientLibrary:
        """Read and verify a library; with ``device``, refuse one made on another device."""
        path = Path(path)
        kind = file_kind(path)
        if kind not in ("a regular file", "missing"):  # a named pipe would block np.load
            raise LibraryError(f"{path}: not a regular file ({kind}); a transient library is "
                               "a .npz file that `hapticlab library build` writes")
        if kind == "a regular file" and not zipfile.is_zipfile(path):
            raise LibraryError(f"{path}: corrupt, or not a transient library file (not a "
                               "NumPy .npz archive)")
        try:
            with np.load(path, allow_pickle=False) as z:
                v, f = z["velocities"], z["forces"]
                provenance = json.loads(str(z["meta_json"]))
                stored = str(z["sha256"])
        except FileNotFoundError:
            raise LibraryError(f"{path}: no such library file") from None
        except (OSError, ValueError, KeyError, zipfile.BadZipFile) as exc:
            raise LibraryError(f"{path}: corrupt, or not a transient library file ({exc})"
                               ) from None
        version = provenance.get("format_version")
        if version != FORMAT_VERSION:
            raise LibraryError(f"{path}: library format version {version!r}; this hapticlab "
                               f"reads version {FORMAT_VERSION}")
        lib = cls(np.asarray(v, float), np.asarray(f, float), provenance)
        if lib.sha256 != stored:
            raise LibraryError(f"{path}: content hash mismatch (stored {stored[:12]}…, computed "
                               f"{lib.sha256[:12]}…): the file is corrupt or was edited")
        if device is not None:
            lib.check_device(device, str(path))
        return lib

    def check_device(self, device: DeviceInfo, where: str = "library") -> None:
        made = self.provenance.get("device", {})
        mine = (device.model, device.serial_number, float(device.servo_rate_hz))
        theirs = (made.get("model"), made.get("serial_number"),
                  float(made.get("servo_rate_hz", -1)))
        if mine != theirs:
            raise LibraryError(
                f"{where}: made on '{theirs[0]}' serial {theirs[1]} at {theirs[2]:g} Hz, but this "
                f"is '{mine[0]}' serial {mine[1]} at {mine[2]:g} Hz; acceleration matching "
                "inverts one device's dynamics, so build a library on this device "
                "(hapticlab library build)")


def _canonical(meta: dict) -> str:
    return json.dumps(meta, sort_keys=True, separators=(",", ":"), default=float)


def _digest(v: np.ndarray, f: np.ndarray, meta: dict) -> str:
    h = hashlib.sha256()
    h.update(_canonical(meta).encode())
    h.update(np.ascontiguousarray(v, "<f8").tobytes())
    h.update(np.ascontiguousarray(f, "<f8").tobytes())
    return h.hexdigest()


# --------------------------------------------------------------------- pipeline
def usable_band(rate_hz: float, band: tuple[float, float] = (10.0, 500.0)) -> tuple[float, float]:
    """The matching band at a servo rate: 10–500 Hz, the top clipped to 0.4 of the rate."""
    return (band[0], min(band[1], 0.4 * rate_hz))


def record_taps(device, scene: Scene, windows: int = 8, duration: float = 5.0, *,
                record: BuildRecord | None = None, on_fault: OnFault | None = None,
                pace: Pace | None = None) -> list:
    """Tap windows on ``scene``: list of WindowResult (contact events, and the
    accelerometer at every servo tick).

    Each window is one measurement (:func:`~device.matching.measure.measured`: a fault
    during it goes to ``on_fault``, and the window is tapped again once it is cleared);
    ``record`` keeps every finished window and gives back those of an earlier run.
    """
    out = [] if record is None else record.windows[:windows]
    if len(out) >= windows:
        return out
    device.load_scene(scene)
    with accel_at_every_tick(device):
        for i in range(len(out), windows):
            what = f"tapping window {i + 1} of {windows}"

            def tap() -> WindowResult:
                device.home()
                res = device.run_window(duration)
                device.zero()  # off while this host computes: the link's lease may lapse
                return res

            t0 = time.perf_counter()
            res = measured(device, tap, what, on_fault)
            if record is not None:
                record.add_window(res)
            out.append(res)
            if pace is not None:
                pace.did(f"{what}: {len(res.contacts)} contacts", time.perf_counter() - t0)
    return out


#: the acceleration recorded after each contact, and so one library entry's length [s]
TAP_WINDOW_S = 0.100


def segment_taps(results, window: float = TAP_WINDOW_S, baseline: float = 0.005) -> list[Tap]:
    """Acceleration windows from each contact, keeping taps with no other contact inside.

    The contact instant is the device's position-threshold crossing (its contact event);
    the acceleration's mean over ``baseline`` seconds before it is removed. A tap whose
    window or baseline holds a record lost on the link (NaN) is left out.
    """
    taps = []
    for res in results:
        tr = res.traces
        rate = res.rate_hz
        n = int(round(window * rate))
        nb = max(1, int(round(baseline * rate)))
        times = [c.t for c in res.contacts]
        for k, c in enumerate(res.contacts):
            if k + 1 < len(times) and times[k + 1] - c.t < window:
                continue  # a bounce or the next tap inside the window
            i = int(round((c.t - tr["t"][0]) * rate))
            if i - nb < 0 or i + n > len(tr["t"]):
                continue
            a = tr["accel"][i: i + n] - np.mean(tr["accel"][i - nb: i])
            if not np.all(np.isfinite(a)):
                continue  # records lost on the link (NaN): a tap with a gap is no tap
            taps.append(Tap(float(c.velocity), a.astype(float), float(c.t)))
    return taps


def even_spread(velocities: np.ndarray, n: int) -> np.ndarray:
    """Indices of ``n`` taps whose speeds are closest to an even grid over their range."""
    v = np.asarray(velocities, float)
    if n >= v.size:
        return np.argsort(v)
    grid = np.linspace(v.min(), v.max(), n)
    chosen: list[int] = []
    for g in grid:
        order = np.argsort(np.abs(v - g))
        for i in order:
            if int(i) not in chosen and not np.any(np.isclose(v[chosen], v[i])):
                chosen.append(int(i))
                break
    return np.array(sorted(chosen, key=lambda i: v[i]))


#: the system identification a library build runs: sweep force levels [N] and repeats per level
SWEEP_LEVELS = (0.5, 1.0, 1.5)
SWEEP_REPEATS = 4
#: a tapping window's length [s]
TAP_SECONDS = 5.0


#: the matching band of the paper [Hz], the one the library store holds
PAPER_BAND = (10.0, 500.0)


def build_key(info: DeviceInfo, source: Scene, *, entries: int = 12, windows: int = 8,
              levels: tuple[float, ...] = SWEEP_LEVELS, repeats: int = SWEEP_REPEATS,
              band: tuple[float, float] = PAPER_BAND) -> dict:
    """What a build's measurements depend on (a :class:`BuildRecord` is kept per key)."""
    return {"pipeline": PIPELINE_VERSION, "device": [info.model, info.serial_number,
                                                      float(info.servo_rate_hz)],
            "source": source.to_dict(), "windows": windows, "levels": list(levels),
            "repeats": repeats, "tap_window_s": TAP_WINDOW_S, "entries": entries,
            "band": list(band)}


def build_library(device, source: Scene, entries: int = 12, method: str = "regularized",
                  lam: float = 1e-4, windows: int = 8, order: int = 7, relative_degree: int = 4,
                  model: TFModel | None = None, *, band: tuple[float, float] = PAPER_BAND,
                  under: Scene | None = None, record: BuildRecord | None = None,
                  on_fault: OnFault | None = None, on_step: OnStep | None = None
                  ) -> TransientLibrary:
    """Run the whole pipeline on ``device`` for the real sample ``source``.

    Parameters
    ----------
    device : HapticDevice
        Needs ``play_force`` for system identification (unless ``model`` is given).
    source : Scene
        The real sample whose taps the library reproduces.
    entries : int
        Library size (an even spread of the recorded speeds).
    method : {'regularized', 'stable'}
    lam : float
        Regularization of the ``regularized`` inversion.
    windows : int
        5-s tapping windows recorded on the source.
    band : (float, float) [Hz]
        Where the sweep identifies the device and the taps are matched: the paper's
        10–500 Hz by default (the top clipped to 0.4 of the servo rate,
        :func:`usable_band`); ``hapticlab bench causes`` widens it to see what it costs.
    under : Scene, optional
        The virtual scene the library will be played over (its spring). By default each
        transient reproduces the whole tap, as the paper's, so over a spring the part of
        the tap the spring renders anyway comes twice (the paper's users found the surface
        slightly active; it attenuated the library by 0.8 and left superposition to future
        work). Given, ``windows`` windows are also tapped on ``under`` (a spring alone), and
        each target has the acceleration ``under`` gives at its speed taken out first: its
        least-squares response per unit of incoming speed over those taps (a linear spring
        on a linear hand responds in proportion to the speed). Not for the store:
        ``hapticlab bench causes`` measures what it changes (on the simulated wood on foam,
        nothing measurable).
    record : BuildRecord, optional
        Keeps each finished measurement (a sweep, a tapping window) and gives back those
        of an earlier run of the same build, which are not measured again.
    on_fault : callable, optional
        ``on_fault(fault, what) -> bool``: a fault during a measurement; True when it was
        cleared (the measurement runs again), False to stop (:class:`MeasurementFault`).
    on_step : callable, optional
        Called with a :class:`~device.matching.measure.Step` after each measurement.

    Raises
    ------
    MeasurementFault
        A fault during a measurement that was not cleared; every measurement finished
        before it is in ``record``.
    """
    if not source.is_real:
        raise ValueError(f"a library reproduces a real sample; '{source.name}' is virtual")
    if under is not None and (under.is_real or under.transient is not None):
        raise ValueError(f"a library is played over a spring alone; '{under.name}' is "
                         + ("real" if under.is_real else "a spring with a transient"))
    if method not in METHODS:
        raise ValueError(f"inversion method must be one of {', '.join(METHODS)}")
    info = device.info
    ticks = int(round(TAP_WINDOW_S * info.servo_rate_hz))  # one entry's row
    cap = device.table_capacity
    if cap is not None and entries * ticks > cap:  # refused before any tapping
        raise LibraryError(f"a library of {entries} entries of {ticks} ticks is "
                           f"{entries * ticks} table items; this device's transient table "
                           f"holds {cap}: at most {cap // ticks} entries")
    band = usable_band(info.servo_rate_hz, band)
    sweeps = 0 if model is not None else len(SWEEP_LEVELS) * SWEEP_REPEATS
    nominal = ([sweep_seconds(info.servo_rate_hz, band)] * sweeps
               + [TAP_SECONDS] * windows * (1 if under is None else 2))
    pace = Pace(nominal, 0 if record is None else record.count, on_step)
    if model is None:
        model = identify_system(device, SWEEP_LEVELS, SWEEP_REPEATS, order=order,
                         relative_degree=relative_degree, band=band, record=record,
                         on_fault=on_fault, pace=pace).model
    dm = discretize(model, info.servo_rate_hz)
    taps = segment_taps(record_taps(device, source, windows, TAP_SECONDS, record=record,
                                    on_fault=on_fault, pace=pace))
    if len(taps) < 2:
        raise LibraryError(f"only {len(taps)} clean taps recorded on '{source.name}'")
    pick = even_spread(np.array([t.velocity for t in taps]), entries)
    targets = [taps[i].accel for i in pick]
    superposed = None
    if under is not None:
        own = segment_taps(record_taps(device, under, windows, TAP_SECONDS,
                                       on_fault=on_fault, pace=pace))
        if len(own) < 2:
            raise LibraryError(f"only {len(own)} clean taps recorded on '{under.name}'")
        # its response per unit speed [m/s² per m/s]: the least-squares gain over the taps,
        # so a slow tap's noise does not weigh more than a fast one's
        v = np.array([t.velocity for t in own])
        per_speed = (v[:, None] * np.stack([t.accel for t in own])).sum(0) / np.sum(v ** 2)
        targets = [taps[i].accel - taps[i].velocity * per_speed for i in pick]
        superposed = {"scene": under.to_dict(), "taps": len(own)}
    invs = [invert(dm, a, method, lam=lam, band=band) for a in targets]
    provenance: dict[str, Any] = {
        "format_version": FORMAT_VERSION,
        "pipeline": PIPELINE_VERSION,
        "device": {**info.to_dict(), "servo_rate_hz": float(info.servo_rate_hz)},
        "servo_rate_hz": float(info.servo_rate_hz),
        "model": model.to_dict(),
        "inversion": {"method": method, "lambda": lam, "band_hz": list(band),
                      "taper_s": [0.001, 0.01], "window_s": TAP_WINDOW_S,
                      "in_window_error": [v.in_window_error for v in invs],
                      "energy_outside": [v.energy_outside for v in invs]},
        "source": {"sample": source.name, "scene": source.to_dict(), "windows": windows,
                   "taps_recorded": len(taps), "tap_times_s": [taps[i].t for i in pick]},
    }
    if superposed is not None:
        provenance["superposed_on"] = superposed
    return TransientLibrary(np.array([taps[i].velocity for i in pick]),
                            np.stack([v.force for v in invs]), provenance)


# --------------------------------------------------------------------- the library store
def library_dir() -> Path:
    """The library store: ``$HAPTICLAB_LIBRARIES``, or ``~/.local/share/hapticlab/libraries``.

    Built libraries are kept here, one folder per device (model, serial number, servo
    rate), so that a protocol names the real sample a library reproduces and the device in
    use finds its own library without the protocol file changing.
    """
    env = os.environ.get("HAPTICLAB_LIBRARIES")
    return Path(env) if env else Path.home() / ".local" / "share" / "hapticlab" / "libraries"


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in text).strip("_") or "device"


def library_path(info: DeviceInfo, source: Scene) -> Path:
    """Where the store keeps the library of real sample ``source`` built on device ``info``.

    The file name carries a hash of the source sample's scene and of the pipeline version, so
    a changed sample (or pipeline) never picks up a library made for the old one.
    """
    key = hashlib.sha256(json.dumps({"pipeline": PIPELINE_VERSION, "source": source.to_dict()},
                                    sort_keys=True).encode()).hexdigest()[:12]
    return _device_dir(info) / f"{_slug(source.name)}-{key}.npz"


def _device_dir(info: DeviceInfo) -> Path:
    """The store's folder for device ``info`` (model, serial number, servo rate)."""
    name = f"{_slug(info.model)}-{_slug(info.serial_number)}-{info.servo_rate_hz:g}Hz"
    return library_dir() / name


def record_path(library: Path) -> Path:
    """Where a build keeps its finished measurements until ``library`` is written."""
    library = Path(library)
    return library.with_name(library.stem + ".partial.npz")


def sysid_record_path(info: DeviceInfo) -> Path:
    """Where ``device sysid`` keeps its finished sweeps on device ``info`` until the model
    is fitted (one per device, in the library store)."""
    return _device_dir(info) / "sysid.partial.npz"


def build_into_store(device, source: Scene, **options: Any) -> Path:
    """Build the library of real sample ``source`` on ``device`` (:func:`build_library`,
    ``options`` passed on) and keep it in the store; returns its path. The store holds
    libraries matched over the paper's band: another band is saved under a path of its own
    (:meth:`TransientLibrary.save`), never in the protocol's place."""
    if tuple(options.get("band", PAPER_BAND)) != PAPER_BAND:
        raise ValueError(f"the library store holds libraries matched over {PAPER_BAND} Hz; "
                         f"save one matched over {tuple(options['band'])} Hz under its own path")
    if options.get("under") is not None:
        raise ValueError("the library store holds libraries of whole taps, as the paper's; "
                         "save one with the spring's response taken out under its own path")
    lib = build_library(device, source, **options)
    return lib.save(library_path(device.info, source))


def find_library(info: DeviceInfo, transient: LibraryTransient) -> Path | None:
    """The library file a device plays for ``transient``: the transient's own ``path`` when
    it names one, else the store's library of its source sample on this device, or None.

    Raises
    ------
    LibraryError
        The transient names a file that does not exist.
    """
    if transient.path is not None:
        p = Path(transient.path)
        if not p.is_file():
            raise LibraryError(f"{p}: no such library file")
        return p
    if transient.source_scene is None:
        return None
    p = library_path(info, transient.source_scene)
    return p if p.is_file() else None
