"""The :class:`HapticDevice` interface every backend implements.

Backends are found through the ``hapticlab.backends`` entry-point group and opened by
:func:`device.registry.open_device`; what a backend offers beside a device (its opener, the
devices it finds, its way into the conformance suite) are class methods here with safe
defaults, in the manner of python-can's ``BusABC``.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import (
    DeviceError,
    DeviceFaultError,
    DeviceSpecError,
    SceneError,
)
from .events import TRACE_CHANNELS, FaultEvent, HostClock, WindowResult
from .info import DeviceInfo
from .scene import Scene, Transient, TransientTable

__all__ = ["DeviceInfo", "HapticDevice", "SimulatedHand", "max_spring", "MAX_WINDOW_TICKS"]

#: most servo ticks one window or playback may span (its wait for a first contact
#: included): every tick is recorded, and the simulator's buffers and traces peak at 176
#: bytes of host memory a tick (measured over 120-s windows, spring and block alike), so 2²³
#: ticks stay near 1.5 GB: 839 s at 10 kHz, 419 s at 20 kHz. A window of 10⁷ s ran for hours
#: and filled the memory before this bound
MAX_WINDOW_TICKS = 2**23


@dataclass(frozen=True)
class SimulatedHand:
    """How a simulated person holds and taps the stylus of a simulated device.

    Only a simulated device has a simulated hand (:meth:`HapticDevice.set_simulated_hand`);
    on hardware a person holds the stylus and this is ignored.

    Attributes
    ----------
    grasp : float [1]
        Factor on the hand's stiffness and damping (a firmer grip is stiffer and more damped).
    tap_speed, tap_speed_sd : float [m/s]
        Mean and SD of the person's intended tap speeds.
    rhythm : float [1]
        Factor on the dwell and pause between taps.
    """

    grasp: float = 1.0
    tap_speed: float = 0.11
    tap_speed_sd: float = 0.033
    rhythm: float = 1.0

    def __post_init__(self) -> None:
        for name in ("grasp", "tap_speed", "rhythm"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"simulated hand: {name} must be finite and > 0, got {v!r}")
        if not (math.isfinite(self.tap_speed_sd) and self.tap_speed_sd >= 0):
            raise ValueError(f"simulated hand: tap_speed_sd must be finite and >= 0, got "
                             f"{self.tap_speed_sd!r}")


class HapticDevice(ABC):
    """A force-feedback device that renders scenes and reports contacts.

    Use as a context manager: output is zero on every exit path.

    The life of a trial: :meth:`load_scene` → :meth:`home` → :meth:`run_window`
    (events and traces in a :class:`~device.events.WindowResult`). A latched fault
    (:meth:`estop`, watchdog) keeps output at zero until :meth:`clear_fault`.

    The public methods are templates (in the manner of python-can's ``BusABC``): they do
    the checks every backend shares once — device open, no latched fault, a scene loaded
    and homed, arguments finite and in range — turn a scene's transient into the table
    this device plays (:func:`device.tables.transient_table`), and call the backend's
    ``_load_scene``, ``_home``, ``_run_window`` and ``_play_force``. A backend renders
    tables; it never builds them.
    """

    def __init__(self) -> None:
        self._closed = False
        self._loaded: Scene | None = None
        self._homed = False
        self._tables: dict[Transient, TransientTable] = {}
        self._current_limit: float | None = None

    # ------------------------------------------------------------- the backend
    @classmethod
    def from_spec(cls, arg: str | None = None, **options: Any) -> HapticDevice:
        """Open the device of the spec ``NAME:arg`` (``arg`` None for ``NAME`` alone).

        Every backend takes the options ``seed``, ``live`` and ``speed``
        (:mod:`device.registry`) and uses those that apply. The default opens ``cls()``
        when there is no ``arg`` and no other option.

        Raises
        ------
        DeviceSpecError
            An argument or option this backend does not take.
        """
        for common in ("seed", "live", "speed"):
            options.pop(common, None)
        if arg or options:
            raise DeviceSpecError(f"{cls.__name__} takes no spec argument or option "
                                  f"({arg or ''}{', '.join(options)})")
        return cls()

    @classmethod
    def available(cls) -> list:
        """The devices of this backend this computer offers, found without opening any
        (:class:`~device.registry.AvailableDevice` each). The default: none found."""
        return []

    @classmethod
    def none_found(cls) -> str:
        """What to check when :meth:`available` finds no device of this backend, in words
        (``hapticlab device list`` says it); "" for nothing to say (the default)."""
        return ""

    @classmethod
    def conformance_opener(cls) -> AbstractContextManager[Callable[[], HapticDevice]]:
        """A context manager giving a zero-argument opener of a device of this backend
        that the conformance suite (:mod:`device.suite`) runs against on a computer
        without the hardware (a simulation, an emulator, the vendor's own simulator).

        Raises
        ------
        NotImplementedError
            The default: a backend that gives none fails the suite, never skips it.
        """
        raise NotImplementedError(f"{cls.__name__} gives no device for the conformance "
                                  "suite: implement conformance_opener()")

    # ---------------------------------------------------------------- identity
    @property
    @abstractmethod
    def info(self) -> DeviceInfo:
        """What the device is and can do (:class:`~device.info.DeviceInfo`): ask it, never
        its backend's name."""

    @property
    def closed(self) -> bool:
        """True once :meth:`close` has run."""
        return self._closed

    @property
    def scene(self) -> Scene | None:
        """The scene loaded last (None before any)."""
        return self._loaded

    # ----------------------------------------------------------------- control
    def load_scene(self, scene: Scene) -> None:
        """Prepare the device to render ``scene`` (uploads only what the scene needs).

        Raises
        ------
        TypeError
            ``scene`` is not a :class:`~device.scene.Scene`.
        SceneError
            The scene's transient cannot be played on this device (e.g. no library built
            on it).
        """
        self._check_open()
        table = self._table_for(scene)
        self._homed = False
        self._load_scene(scene, table)
        self._loaded = scene

    def check_scene(self, scene: Scene) -> None:
        """Raise :class:`~device.errors.SceneError` when this device could not present
        ``scene``, without loading it (nothing moves; the loaded scene stays)."""
        self._check_open()
        k_max = max_spring(self.info)
        if scene.spring is not None and scene.spring > k_max:
            raise SceneError(f"spring {scene.spring:g} N/m is above the stiffest this device "
                             f"renders, {k_max:.3g} N/m (full force within one encoder count, "
                             "or the sampled spring unstable on its moving mass)", "spring",
                             where=scene.name)
        self._check_scene(scene, self._table_for(scene))

    def _table_for(self, scene: Scene) -> TransientTable | None:
        """``scene``'s transient as this device plays it (built once per transient)."""
        if not isinstance(scene, Scene):
            raise TypeError(f"expects a device.Scene, got {type(scene).__name__}")
        if scene.transient is None:
            return None
        table = self._tables.get(scene.transient)
        if table is None:
            from .tables import transient_table

            table = self._tables[scene.transient] = transient_table(scene.transient,
                                                                    self.info)
        return table

    def home(self, clearance: float | None = None) -> None:
        """Move the stylus to rest ``clearance`` [m] above the surface (None: the backend's
        default) and enable output with a ramp."""
        self._check_open()
        if self._loaded is None:
            raise DeviceError("load a scene before homing")
        self._check_fault()
        if clearance is not None:
            c = float(clearance)
            if not (math.isfinite(c) and c > 0):
                raise ValueError(f"home clearance must be finite and > 0 m, got {clearance!r}")
            clearance = c
        self._home(clearance)
        self._homed = True

    def run_window(self, duration: float = 5.0, *, from_first_contact: bool = True,
                   timeout: float = 30.0,
                   on_progress: Callable[[float, WindowResult], None] | None = None,
                   heartbeats: bool = True) -> WindowResult:
        """Render the loaded scene for one tapping window.

        Parameters
        ----------
        duration : float [s]
            Window length, counted from the first contact when ``from_first_contact``.
        timeout : float [s]
            Longest wait for a first contact; the result has ``timed_out`` set.
        on_progress : callable, optional
            Called as ``on_progress(t, partial_result)`` a few times per second of
            device time (live velocities, operator e-stop).
        heartbeats : bool
            Keep the host heartbeat going during the window (default). False makes the
            host go silent, which trips the watchdog: the device-safety test.
        """
        self._check_open()
        self._check_fault()
        if self._loaded is None or not self._homed:
            raise DeviceError("load a scene and home the device before running a window")
        for name, v in (("duration", duration), ("timeout", timeout)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"window {name} must be finite and > 0 s, got {v!r}")
        span = duration + timeout if from_first_contact else duration
        if span > self.max_window_s:
            what = (f"duration {duration:g} s + wait for a first contact {timeout:g} s"
                    if from_first_contact else f"duration {duration:g} s")
            raise ValueError(f"a window of {span:g} s ({what}) is longer than this device "
                             f"records in one window: {self.max_window_s:g} s "
                             f"({self._max_window_why()}); split it into shorter windows")
        return self._run_window(float(duration), bool(from_first_contact), float(timeout),
                                on_progress, bool(heartbeats))

    @property
    def max_window_s(self) -> float:
        """Longest window [s] this device records, its wait for a first contact included
        (:data:`MAX_WINDOW_TICKS` servo ticks)."""
        return MAX_WINDOW_TICKS / self.info.servo_rate_hz

    def _max_window_why(self) -> str:
        """Where :attr:`max_window_s` comes from, for the error that names it."""
        return f"{MAX_WINDOW_TICKS} ticks at {self.info.servo_rate_hz:g} Hz, each kept in memory"

    def end_window(self) -> None:
        """End the running window now, before its duration is up: the participant moved on
        (in a material-identification trial, to another surface). Call it from that window's
        ``on_progress``: a request names no window, so one sent from another thread as a
        window ends could reach the next. :meth:`run_window` then returns what was recorded
        up to the tick the device ended on, the output staying on (homed). Between windows
        it does nothing; a device that does not answer lets the window run its time."""
        self._check_open()
        self._end_window()

    def play_force(self, force, *, heartbeats: bool = True,
                   on_progress: Callable[[float, WindowResult], None] | None = None
                   ) -> WindowResult:
        """Play an open-loop force command [N per servo tick] while the hand holds still.

        The stylus is in free air; the command still passes the enable ramp, watchdog and
        current clamp. Used for system identification (swept sines), for checking
        transients, and by the self-test to have a force to cut with no contact (its
        e-stop, watchdog and exit checks). Home again before the next tapping window.

        Parameters
        ----------
        force : array_like [N]
            One command per servo tick.
        heartbeats : bool
            As for :meth:`run_window`: False makes the host go silent (the watchdog trips).
        on_progress : callable, optional
            As for :meth:`run_window`: called as ``on_progress(t, partial_result)`` a few
            times per second of device time, where an e-stop (or an exception) can act
            while the force plays. A backend whose ``_play_force`` takes no callback is
            given none when there is none.
        """
        self._check_open()
        self._check_fault()
        f = np.ascontiguousarray(force, dtype=float).reshape(-1)
        if f.size == 0 or not np.all(np.isfinite(f)):
            raise ValueError("force command must be a non-empty array of finite values [N]")
        if f.size > MAX_WINDOW_TICKS:
            raise ValueError(f"a force command of {f.size} ticks is longer than this device "
                             f"plays in one go: {MAX_WINDOW_TICKS} ticks "
                             f"({self.max_window_s:g} s); split it")
        self._homed = False
        if on_progress is None:
            return self._play_force(f, bool(heartbeats))
        return self._play_force(f, bool(heartbeats), on_progress)

    def set_trace_channels(self, channels: Sequence[str] | None = None) -> float:
        """Choose the trace channels the following windows and playbacks record.

        A device whose link is too narrow to stream every channel at every servo tick (a
        1-Mbaud UART) thins its traces out; asking only for what a measurement needs
        (system identification needs ``accel`` alone) lets it stream those at every tick.

        Parameters
        ----------
        channels : sequence of str, optional
            Names of :data:`~device.events.TRACE_CHANNELS` (``t`` always comes); None, the
            default, asks for all of them.

        Returns
        -------
        float [Hz]
            The rate they will come at: the servo rate, or less when the link cannot carry
            them at every tick. A backend may record more channels than asked (the
            simulator records all of them at every tick).

        Raises
        ------
        ValueError
            A name that is not a trace channel, or none at all.
        """
        self._check_open()
        if channels is not None:
            channels = tuple(dict.fromkeys(c for c in channels if c != "t"))
            unknown = [c for c in channels if c not in TRACE_CHANNELS]
            if unknown or not channels:
                raise ValueError(f"trace channels must be some of "
                                 f"{', '.join(c for c in TRACE_CHANNELS if c != 't')}; got "
                                 f"{', '.join(map(repr, unknown)) or 'none'}")
        return self._set_trace_channels(channels)

    def estop(self) -> None:
        """Latched emergency stop: output to zero now and until :meth:`clear_fault`."""
        self._homed = False
        self._estop()

    def clear_fault(self) -> None:
        """Clear a latched fault; output resumes (ramped) at the next :meth:`home`."""
        self._check_open()
        self._homed = False
        self._clear_fault()

    def zero(self) -> None:
        """Command zero output immediately (not latched); home again to enable."""
        self._homed = False
        self._zero()

    def close(self) -> None:
        """Zero output and release the device. Idempotent."""
        if self._closed:
            return
        try:
            self._close()
        finally:
            self._closed = True
            self._homed = False

    @property
    def current_limit(self) -> float:
        """The amplifier current limit in force [A]: the rating, or lower when a session set
        it (:meth:`set_current_limit`)."""
        return self.info.current_limit if self._current_limit is None else self._current_limit

    def set_current_limit(self, amps: float) -> float:
        """Clamp the amplifier current at ``amps`` [A] from now on (a protocol's
        ``[limits] max_current``); never above the device's rating. Returns the limit now
        in force.

        Raises
        ------
        DeviceSpecError
            ``amps`` is not a finite number > 0.
        CurrentLimitError
            Above the rating (:meth:`DeviceInfo.ceiling`): a session must not start.
        DeviceError
            The device cannot lower its limit: a session must not start either.
        """
        self._check_open()
        a = float(amps) if isinstance(amps, (int, float)) and not isinstance(amps, bool) \
            else float("nan")
        if not (math.isfinite(a) and a > 0):
            raise DeviceSpecError(f"current limit must be a finite number > 0 A, got {amps!r}")
        a = self.info.ceiling(a)
        self._set_current_limit(a)
        self._current_limit = a
        return a

    # ------------------------------------------------- optional, with defaults
    def reseed(self, entropy) -> None:
        """Restart the device's own randomness from ``entropy`` (a simulated device's
        tapping hand and sensor noise), so an attempt repeats exactly. Hardware has none:
        the default does nothing."""
        return None

    def set_simulated_hand(self, hand: SimulatedHand) -> bool:
        """Hold the stylus with a simulated person's hand; True when the device has a
        simulated hand (the simulated device), False otherwise (hardware: a person holds
        it). Takes effect from the next window."""
        return False

    @property
    def table_capacity(self) -> int | None:
        """The most transient-table items (rows × servo ticks) this device holds, or None
        when it sets no limit (the simulator). :meth:`check_scene` refuses a larger table."""
        return None

    def link_stats(self) -> dict:
        """Statistics of the link to the device (frames, errors, round trips); empty for a
        device without one."""
        return {}

    def host_clock(self, span: tuple[float, float] | None = None) -> HostClock | None:
        """Where this device's clock lies on this computer's, from its readings around
        ``span`` (device times [s], e.g. a window's first and last tick; default: its
        recent readings), or None when its time is not this computer's: a simulation in
        virtual time, which runs as fast as it can. Event markers put a window's contacts
        on a clock shared with other recordings through it. The default: None."""
        return None

    # ------------------------------------------------------ backend interface
    @abstractmethod
    def _load_scene(self, scene: Scene, table: TransientTable | None) -> None:
        """Prepare ``scene``; ``table`` is its transient as this device plays it (None for a
        spring or a real sample)."""

    def _check_scene(self, scene: Scene, table: TransientTable | None) -> None:
        """Backend checks beyond the transient table's (the simulator models the scene);
        raise SceneError. A backend that plays what it is given checks nothing more."""
        return None

    @abstractmethod
    def _home(self, clearance: float | None) -> None:
        """Home above the loaded scene's surface (``clearance`` checked, or None)."""

    @abstractmethod
    def _run_window(self, duration: float, from_first_contact: bool, timeout: float,
                    on_progress, heartbeats: bool) -> WindowResult:
        """Run one window (arguments checked)."""

    @abstractmethod
    def _end_window(self) -> None:
        """End the running window at the device's next tick (nothing when none runs)."""

    @abstractmethod
    def _play_force(self, force: np.ndarray, heartbeats: bool,
                    on_progress=None) -> WindowResult:
        """Play a checked force array [N per tick] open loop in free air (``on_progress``
        as :meth:`_run_window`'s)."""

    def _set_trace_channels(self, channels: tuple[str, ...] | None) -> float:
        """Record ``channels`` (checked; None: all) in the following windows; return their
        rate [Hz]. A backend that records every channel at every tick does nothing."""
        return float(self.info.servo_rate_hz)

    @abstractmethod
    def _estop(self) -> None:
        """Zero output now and latch an e-stop fault."""

    @abstractmethod
    def _clear_fault(self) -> None:
        """Clear the latched fault (output stays off until the next home)."""

    @abstractmethod
    def _zero(self) -> None:
        """Zero output now (not latched)."""

    @abstractmethod
    def _close(self) -> None:
        """Zero output and release the device."""

    def _set_current_limit(self, amps: float) -> None:
        """Clamp the current at ``amps`` [A] (checked ≤ rating). A backend that cannot says
        so: a session with a lower protocol limit then refuses to start."""
        raise DeviceError(f"{type(self).__name__} cannot lower its current limit; a protocol "
                          "with [limits] max_current below the rating cannot run on it")

    @abstractmethod
    def heartbeat(self) -> None:
        """Tell the device the host is alive (resets the watchdog)."""

    @property
    @abstractmethod
    def fault(self) -> FaultEvent | None:
        """The latched fault, or None."""

    @property
    @abstractmethod
    def output_force(self) -> float:
        """Force [N] the device is commanding right now (0 when idle, zeroed or closed)."""

    # ----------------------------------------------------------- shared checks
    def _check_open(self) -> None:
        if self._closed:
            raise DeviceError("device is closed")

    def _check_fault(self) -> None:
        f = self.fault
        if f is not None:
            raise DeviceFaultError(f"fault latched ({f.code}): clear it first"
                                   + self._fault_account(f.code))

    def _fault_account(self, code: str) -> str:
        """What this backend can add to a latched fault's message (a device's own account
        of a watchdog fault: who fell silent); empty when nothing."""
        return ""

    # ----------------------------------------------------------- conveniences
    def __enter__(self) -> HapticDevice:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def max_spring(info) -> float:
    """The stiffest virtual spring [N/m] a device renders as a spring: the smaller of the
    force range over one encoder count (current limit × force constant / resolution:
    stiffer reaches full force within one count, a relay) and 4·m·f_s² (a spring sampled
    at f_s on the moving mass m oscillates unstably above it, ω·T = 2)."""
    f_max = info.current_limit * info.force_constant
    stable = 4.0 * info.effective_mass * info.servo_rate_hz ** 2
    if not info.encoder_resolution > 0:  # a device that reports no resolution
        return stable
    return min(f_max / info.encoder_resolution, stable)
