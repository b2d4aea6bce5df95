"""The ``sim`` backend: a sampled-data physics simulation of the device, hand and samples."""

from __future__ import annotations

import hashlib
import json
import math
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, replace
from typing import Any

import numpy as np

from ..base import DeviceInfo, HapticDevice, SimulatedHand
from ..errors import DeviceError, DeviceSpecError, SceneError
from ..events import ContactEvent, FaultEvent, Flags, HostClock, SaturationEvent, WindowResult
from ..registry import AvailableDevice
from ..scene import MAX_REACH_M, Scene, TransientTable
from . import kernel as K
from ._window import STREAM_TICKS, Buffers, TracePieces, runs
from .compiled import CompiledScene, compile_scene, velocity_weights
from .params import DeviceParams, HandParams
from .tapper import HoldPlan, Tapper

__all__ = ["SimDevice", "CompiledScene", "compile_scene", "velocity_weights"]

_CHUNK_S = 0.1  # device time between progress callbacks / heartbeats in virtual time
#: live mode: pacing granularity [wall s]. In wall time, so that a faster-than-real-time
#: device (``speed`` > 1) still sleeps most of each chunk instead of spinning through it
_LIVE_CHUNK_S = 0.001
_SPIN_S = 0.0002  # live mode: the end of each wait is spun, not slept [s]
#: contact events a window's buffers first hold; they grow before a chunk could fill them,
#: so no contact is ever dropped (the kernel stores a contact only while there is room)
_EVENTS = 4096
#: live mode: a servo loop that finds itself this far behind the wall clock (its process
#: was stopped: a garbage collection, a loaded machine) lets its clock slip instead of
#: racing to catch up [wall s]. Racing would run device time past heartbeats the link has
#: received but not yet read, and trip the watchdog for a stall that was not the host's.
_SLIP_S = 0.02


class SimDevice(HapticDevice):
    """Simulated haptic device (virtual time by default).

    Parameters
    ----------
    device : DeviceParams, optional
        Hardware parameters; ``rate_hz`` overrides its servo rate.
    hand : HandParams, optional
        Impedance of the hand holding the stylus.
    tapper : Tapper, optional
        The simulated person's tapping motion during windows.
    seed : int
        Seed of the ``numpy.random.Generator`` behind tapping and sensor noise.
    rate_hz : float, optional [Hz]
        Servo rate, 1,000–20,000 Hz (default 10,000).
    live : bool
        Pace the simulation to the wall clock (busy-wait), for interactive dry runs.
    speed : float
        In live mode, device seconds per wall second (1: real time).
    noise : bool
        Add accelerometer noise (turn off for reference comparisons).
    """

    def __init__(self, device: DeviceParams | None = None, hand: HandParams | None = None,
                 tapper: Tapper | None = None, seed: int = 0, rate_hz: float | None = None,
                 live: bool = False, noise: bool = True, speed: float = 1.0):
        super().__init__()
        dev = device or DeviceParams()
        if rate_hz is not None:
            if not 1_000 <= float(rate_hz) <= 20_000:
                raise DeviceSpecError(f"sim servo rate must be 1,000–20,000 Hz, got {rate_hz!r}")
            dev = dev.with_rate(rate_hz)
        self.params = dev
        self.hand = hand or HandParams()
        #: the hand the device was set up with: its identity and its transient libraries
        #: belong to this one, whoever holds the stylus later (:meth:`set_hand`)
        self.nominal_hand = self.hand
        self.tapper = tapper or Tapper()
        self._base_tapper = self.tapper  # a simulated person's tapping scales this one
        self.seed = int(seed)
        # independent streams, so switching sensor noise off does not change the taps
        ss = np.random.SeedSequence(self.seed)
        self.rng_tapping, self.rng_noise = (np.random.default_rng(c) for c in ss.spawn(2))
        self.live = bool(live)
        if not (speed > 0 and math.isfinite(speed)):
            raise DeviceSpecError(f"live speed must be finite and > 0, got {speed!r}")
        self.speed = float(speed)
        #: wall seconds the live clock has slipped behind the wall clock (see ``_SLIP_S``)
        self.slipped_s = 0.0
        self._stop_requested = False
        self._live_clock: HostClock | None = None  # live mode: the last window's pacing
        self.noise = bool(noise)
        # the serial number names the configuration, so a transient library built for
        # another simulated device (other mechanics, hand or rate) is refused like a
        # library from another physical device
        config = json.dumps([dev.to_dict(), asdict(self.hand)], sort_keys=True)
        serial = "SIM-" + hashlib.sha256(config.encode()).hexdigest()[:10]
        self._info = DeviceInfo(
            backend="sim", model="hapticlab simulated stylus device", serial_number=serial,
            firmware="sim", servo_rate_hz=dev.servo_rate_hz, current_limit=dev.current_limit,
            force_constant=dev.force_constant, effective_mass=dev.effective_mass,
            watchdog_s=dev.watchdog_s, encoder_resolution=dev.encoder_resolution,
            accel_range=dev.accel_range, simulated_contact=True, seeded=True,
            virtual_time=True)
        self._vel_w = velocity_weights(dev)
        self._kernel_device = self._device_args()
        self._pull_gains = self._hand_gains()
        self._cache: dict[Scene, CompiledScene] = {}
        self._scene: CompiledScene | None = None
        self._free_air: CompiledScene | None = None
        self._x: np.ndarray | None = None
        self._ist = np.zeros(K.IST, dtype=np.int64)
        self._fst = np.zeros(K.FST)
        #: the last window's first bounce on a real sample: the tip's speed into it and out
        #: of it, moving away [m/s], at the switches the kernel located inside ticks (NaN:
        #: none)
        self.first_bounce = (math.nan, math.nan)
        self._rb = np.zeros(len(self._vel_w))
        self._tick = 0  # device time in ticks
        self._tick_enabled = 0  # the tick output was last enabled at (home)
        self._t_heartbeat = 0.0
        self._enabled = False
        self._homed_clearance: float | None = None
        self._fault: FaultEvent | None = None
        self._estop_requested = False
        self._output_force = 0.0
        #: live mode: called with (first tick, traces) for each run of new ticks of a
        #: window or playback as it is simulated (a device streaming its traces); the
        #: pieces joined are the result's traces
        self.trace_sink: Callable[[int, dict[str, np.ndarray]], None] | None = None
        #: called before each block of ticks of a window or playback, live or in virtual
        #: time; it may wait (a live device's clock then slips). An emulator waits there
        #: until it has read its input: a device reads what arrived between ticks, so its
        #: watchdog never judges the host on time in which the device itself was not
        #: listening. In virtual time it is where a test acts at a device time it chose
        self.input_gate: Callable[[], None] | None = None

    def _device_args(self) -> tuple:
        """What the servo loop needs of the device (:func:`device.sim.kernel.run_ticks`)."""
        dev = self.params
        return (float(dev.encoder_resolution), self._vel_w, float(dev.contact_hysteresis),
                float(dev.force_constant), float(self.current_limit),
                int(round(dev.ramp_s / dev.dt)), float(dev.servo_rate_hz))

    def _set_current_limit(self, amps: float) -> None:
        self._current_limit = amps
        self._kernel_device = self._device_args()

    @property
    def _watchdog_device_s(self) -> float:
        """The watchdog period in device time [s]. It is a wall-clock safety limit: a live
        device paced at ``speed`` × real time lets ``speed`` × as much device time pass
        (an emulator at ×3 otherwise tripped it between the host's heartbeats)."""
        return self.params.watchdog_s * (self.speed if self.live else 1.0)

    def _hand_gains(self) -> tuple[float, float, float]:
        """The hand's pull per intended position, velocity and acceleration (impedance +
        feedforward of the moving mass and the device's friction)."""
        dev, hand = self.params, self.hand
        return (hand.stiffness, hand.damping + dev.motor_damping,
                dev.motor_mass + dev.tip_mass + hand.mass)

    def set_hand(self, hand: HandParams) -> None:
        """Another hand on the stylus (another person, a firmer or looser grasp).

        Takes effect from the next window; the loaded scene is reloaded (output off until
        :meth:`home`). The serial number and the transient libraries stay those of
        :attr:`nominal_hand`: a library is built once on a device and played to everyone,
        as in the study.
        """
        self._check_open()
        if not isinstance(hand, HandParams):
            raise TypeError(f"set_hand expects HandParams, got {type(hand).__name__}")
        if hand == self.hand:
            return
        self.hand = hand
        self._pull_gains = self._hand_gains()
        current = self.scene
        self._cache.clear()
        self._free_air = None
        if current is not None:
            self.load_scene(current)

    def host_clock(self, span: tuple[float, float] | None = None) -> HostClock | None:
        """In live mode, the last window's pacing: its ticks on the wall clock, within a
        pacing chunk and the time the window slipped; None in virtual time (and before a
        live window ran)."""
        return self._live_clock if self.live else None

    def set_simulated_hand(self, hand: SimulatedHand) -> bool:
        """A simulated person takes the stylus: their grasp scales the nominal hand's
        stiffness and damping, their tapping replaces the tapper's speeds, and their rhythm
        scales its dwell and pause (see :class:`~device.base.SimulatedHand`)."""
        if not isinstance(hand, SimulatedHand):
            raise TypeError(f"expects a SimulatedHand, got {type(hand).__name__}")
        nominal = self.nominal_hand
        self.set_hand(replace(nominal, stiffness=nominal.stiffness * hand.grasp,
                              damping=nominal.damping * hand.grasp))
        base = self._base_tapper
        self.tapper = replace(base, velocity_mean=hand.tap_speed, velocity_sd=hand.tap_speed_sd,
                              dwell=tuple(x * hand.rhythm for x in base.dwell),
                              pause=tuple(x * hand.rhythm for x in base.pause))
        return True

    @classmethod
    def with_ratings(cls, info: DeviceInfo, **options: Any) -> SimDevice:
        """A simulated device with another device's ratings: its servo rate, current limit,
        force constant and effective mass (the moving mass beyond the default tip is put on
        the motor side); everything else is this simulator's default."""
        base = DeviceParams()
        params = replace(base, servo_rate_hz=float(info.servo_rate_hz),
                         current_limit=float(info.current_limit),
                         force_constant=float(info.force_constant),
                         motor_mass=max(1e-4, float(info.effective_mass) - base.tip_mass))
        return cls(device=params, **options)

    @classmethod
    def from_spec(cls, arg: str | None = None, **options: Any) -> SimDevice:
        """Factory behind ``open_device("sim")``; ``"sim:RATE"`` sets the servo rate in Hz."""
        if arg:
            try:
                options.setdefault("rate_hz", float(arg))
            except ValueError:
                raise DeviceSpecError(f"sim spec 'sim:{arg}': expected a servo rate in Hz, "
                                  "e.g. 'sim:10000'") from None
        return cls(**options)

    @classmethod
    def available(cls) -> list[AvailableDevice]:
        """The simulated device, on every computer."""
        return [AvailableDevice("sim", "the simulated device, no hardware (sim:RATE "
                                "sets its servo rate [Hz])")]

    @classmethod
    @contextmanager
    def conformance_opener(cls) -> Iterator[Callable[[], SimDevice]]:
        """Fresh simulated devices with one seed (each check opens its own)."""
        yield lambda: cls.from_spec(None, seed=5)

    # ------------------------------------------------------------------ state
    @property
    def info(self) -> DeviceInfo:
        return self._info

    @property
    def time(self) -> float:
        """Device time [s]."""
        return self._tick * self.params.dt

    @property
    def fault(self) -> FaultEvent | None:
        return self._fault

    @property
    def output_force(self) -> float:
        return self._output_force

    @property
    def output_latched_off(self) -> bool:
        """True once the servo loop has zeroed output for a latched fault in this window
        (the fault's time is then the zeroing tick)."""
        return bool(self._ist[K.IST_FAULT_TICK] >= 0)

    @property
    def enabled(self) -> bool:
        """Output enabled (homed, no fault, not zeroed)."""
        return self._enabled

    # ---------------------------------------------------------------- control
    def _compiled(self, scene: Scene, table: TransientTable | None) -> CompiledScene:
        if scene not in self._cache:
            try:
                self._cache[scene] = compile_scene(scene, self.params, self.hand, table)
            except SceneError as exc:
                raise exc.within(where=f"scene '{scene.name}' {exc.where}".strip()) from None
        return self._cache[scene]

    def _check_scene(self, scene: Scene, table: TransientTable | None) -> None:
        self._compiled(scene, table)

    def _load_scene(self, scene: Scene, table: TransientTable | None) -> None:
        self._scene = self._compiled(scene, table)
        self._load_kernel(self._scene)
        self._enabled = False
        self._homed_clearance = None
        self._output_force = 0.0

    def _home(self, clearance: float | None) -> None:
        """Put the stylus at rest ``clearance`` [m] above the surface (default: the
        tapper's stroke top) and enable output with a ramp.

        Homing is modelled as completed position control: the state is set, not simulated.
        """
        c = self.tapper.top if clearance is None else clearance
        p = self._scene.plant
        z = p.surface_height + c
        x = np.zeros(p.n_states)
        x[K.Z1] = x[K.Z2] = z
        self._x = x
        self._reset_loop_state(z)
        self._tick_enabled = self._tick  # the enable ramp runs from here, in device time
        self._homed_clearance = c
        self._enabled = True
        self._output_force = 0.0
        self.heartbeat()

    def _load_kernel(self, cs: CompiledScene) -> None:
        """Run the servo loop for no ticks on ``cs``, so that its compiled code is loaded
        now, not inside a window: the first call in a process loads it (numba's cache, some
        0.5 s), and in a live window that stalled the paced clock at the window's first tick
        (the clock slipped), so an e-stop pressed half a second in was timed at the
        window's start. The call changes no state."""
        state = (np.zeros(cs.plant.n_states), np.zeros(K.IST, dtype=np.int64),
                 np.zeros(K.FST), np.zeros(len(self._vel_w)))
        none = np.zeros(0, dtype=np.int64)
        K.run_ticks(0, 0, state, cs.kernel_args, self._kernel_device, np.zeros(1), _EMPTY, 0,
                    -1, np.zeros((K.N_OUT, 0)), none, none.copy(), np.zeros(0))

    def _reset_loop_state(self, z: float) -> None:
        """Servo-loop state after enabling at rest at height ``z`` [m]."""
        self._ist[:] = 0
        self._ist[K.IST_ARMED] = 1
        self._ist[K.IST_PLAY] = -1
        self._ist[K.IST_FIRST] = -1
        self._ist[K.IST_STOP] = -1
        self._ist[K.IST_FAULT_TICK] = -1
        self._rb[:] = np.floor(z / self.params.encoder_resolution + 0.5) * \
            self.params.encoder_resolution

    def heartbeat(self) -> None:
        self._t_heartbeat = self.time

    def idle_until(self, t: float) -> None:
        """Let device time pass to ``t`` [s] with no window running (a live device's
        clock runs between windows too); an earlier ``t`` changes nothing."""
        self._tick = max(self._tick, int(t / self.params.dt))

    @property
    def watchdog_span(self) -> float:
        """Device time [s] without a heartbeat after which the watchdog trips."""
        return self._watchdog_device_s

    @property
    def last_heartbeat(self) -> float:
        """Device time [s] of the last heartbeat."""
        return self._t_heartbeat

    def reseed(self, entropy) -> None:
        """Restart the tapping and sensor-noise streams from ``entropy`` (e.g. [seed, trial,
        attempt]), so an attempt repeats exactly however the session got there."""
        ss = np.random.SeedSequence(entropy)
        self.rng_tapping, self.rng_noise = (np.random.default_rng(c) for c in ss.spawn(2))

    def request_stop(self) -> None:
        """End the running window at the next chunk (from another thread or a callback);
        unlike :meth:`end_window`, also on a closed device (an emulator shutting down)."""
        self._stop_requested = True

    def _end_window(self) -> None:
        self.request_stop()

    def trip_watchdog(self) -> None:
        """Latch a watchdog fault (used by an emulator when the host falls silent between
        windows; inside a window the servo loop trips it itself), timed at the tick the
        watchdog period ran out, as a device's servo zeroes its output then (the emulator
        notices between windows at its next turn)."""
        self._output_force = 0.0
        if self._fault is None:
            t = min(self.time, self._t_heartbeat + self._watchdog_device_s)
            self._fault = FaultEvent(t, "watchdog",
                                     f"no heartbeat for {self.params.watchdog_s:g} s: output "
                                     "zeroed")

    def _estop(self) -> None:
        self._estop_requested = True
        self._output_force = 0.0
        if self._fault is None:
            self._fault = FaultEvent(self.time, "estop", "emergency stop (latched)")

    def _clear_fault(self) -> None:
        self._fault = None
        self._estop_requested = False
        self._enabled = False  # output comes back only through home(), ramped

    def _zero(self) -> None:
        self._enabled = False
        self._output_force = 0.0

    def _close(self) -> None:
        self._zero()

    # ----------------------------------------------------------------- window
    def _run_window(self, duration: float, from_first_contact: bool, timeout: float,
                    on_progress: Callable[[float, WindowResult], None] | None,
                    heartbeats: bool) -> WindowResult:
        """Simulate one tapping window (see :meth:`HapticDevice.run_window`).

        ``heartbeats=False`` makes the simulated host go silent for the window, so the
        watchdog trips ``watchdog_s`` after the last heartbeat.
        """
        if self._x is None or not self._enabled:
            raise DeviceError("home the device before running a window")
        dev, cs = self.params, self._scene
        total_s = (timeout + duration) if from_first_contact else duration
        plan = replace(self.tapper, top=self._homed_clearance).plan(
            self.rng_tapping, total_s + 1.0, cs.plant.surface_height)
        self.last_plan = plan  # the intended taps of the last window (audits read them)
        n_max = int(math.ceil(total_s / dev.dt))
        stop_after = int(round(duration / dev.dt)) if from_first_contact else -1
        # the enable ramp ran from HOME in device time: a live device's clock ran meanwhile
        self._ist[K.IST_SINCE_ENABLE] = max(int(self._ist[K.IST_SINCE_ENABLE]),
                                            self._tick - self._tick_enabled)
        tick0 = self._tick
        # room for the whole window at once: zeros the window does not reach cost nothing,
        # and growing it midway copied every array so far (a stall the emulator's serve
        # loop shares)
        res = self._run(cs, plan, n_max, stop_after, _EMPTY, on_progress, heartbeats,
                        timeout if from_first_contact else None, total_s)
        # no contact within the timeout; a window ended sooner (end_window, a fault) is not
        res.timed_out = (from_first_contact and res.t_first_contact is None
                         and (self._tick - tick0) * dev.dt >= timeout - dev.dt / 2)
        return res

    def _play_force(self, f: np.ndarray, heartbeats: bool,
                    on_progress: Callable[[float, WindowResult], None] | None = None
                    ) -> WindowResult:
        """Play an open-loop force command [N per servo tick] while the hand holds still.

        Each call starts with the stylus at rest in free air (no surface within reach) and
        output enabled; the command still goes through the ramp, watchdog and current
        clamp. Used for system identification. Afterwards, home again before a window.
        """
        if self._free_air is None:
            far = Scene("free-air", surface_height=-MAX_REACH_M, spring=0.0)  # out of reach
            self._free_air = compile_scene(far, self.params, self.hand)
            self._load_kernel(self._free_air)
        self._x = np.zeros(self._free_air.plant.n_states)
        # output already on (homed) stays on, its ramp long done; off, it ramps up now
        since = self._tick - self._tick_enabled if self._enabled else 0
        self._reset_loop_state(0.0)
        self._ist[K.IST_SINCE_ENABLE] = since
        self._enabled = False  # a window needs home() afterwards
        self.heartbeat()
        return self._run(self._free_air, HoldPlan(0.0), f.size, -1, f, on_progress, heartbeats,
                         None, f.size * self.params.dt)

    def _run(self, cs: CompiledScene, plan, n_max: int, stop_after: int, f_ext: np.ndarray,
             on_progress, heartbeats: bool, timeout: float | None, initial_s: float
             ) -> WindowResult:
        dev = self.params
        dt = dev.dt
        self._ist[K.IST_STOP] = -1 if stop_after >= 0 else n_max
        self._ist[K.IST_FIRST] = -1
        self._ist[K.IST_NEV] = self._ist[K.IST_SWITCHES] = self._ist[K.IST_UNRESOLVED] = 0
        self._fst[K.FST_EIN] = self._fst[K.FST_EOUT] = 0.0
        self._fst[K.FST_VIN] = self._fst[K.FST_VOUT] = np.nan
        tick0 = self._tick
        buf = Buffers(min(n_max, int(round(initial_s / dt))), plan, self._pull_gains, dt)
        ev_tick = np.zeros(_EVENTS, dtype=np.int64)
        ev_vel = np.zeros(_EVENTS)
        chunk_s = _LIVE_CHUNK_S * self.speed if self.live else _CHUNK_S  # [device s]
        chunk = max(1, int(round(chunk_s / dt)))
        state = (self._x, self._ist, self._fst, self._rb)
        pieces = TracePieces(self, buf) if self.live and self.trace_sink is not None else None
        wall0 = start = time.perf_counter()
        slipped = 0.0
        late: list[float] = []
        n = 0
        self._stop_requested = False
        while n < n_max and not self._stop_requested:
            if self.input_gate is not None:
                self.input_gate()
            if heartbeats:
                self.heartbeat()
            n1 = min(n + chunk, n_max)
            buf.ensure(n1)
            nev = int(self._ist[K.IST_NEV])
            if nev + (n1 - n) > ev_tick.size:  # room for a contact at every tick of the chunk
                grow = max(2 * ev_tick.size, nev + (n1 - n))
                ev_tick = np.concatenate([ev_tick, np.zeros(grow - ev_tick.size, np.int64)])
                ev_vel = np.concatenate([ev_vel, np.zeros(grow - ev_vel.size)])
            wd = (self._t_heartbeat + self._watchdog_device_s - tick0 * dt) / dt
            zero_from = int(math.ceil(wd - 1e-9)) if wd < 2**62 else 2**62
            if self._estop_requested:
                zero_from = min(zero_from, n)
            n_done = K.run_ticks(n, n1, state, cs.kernel_args, self._kernel_device, buf.u_hand,
                                 f_ext, zero_from, stop_after, buf.out, buf.flags, ev_tick,
                                 ev_vel)
            self._tick = tick0 + n_done
            n = n_done
            if n:  # what a callback reads as the output now, live or in virtual time
                self._output_force = float(buf.cur[n - 1] * dev.force_constant)
            ft = int(self._ist[K.IST_FAULT_TICK])
            if ft >= 0:  # latch now, so callers see it mid-window, timed at the zeroing tick
                self._latch((tick0 + ft) * dt)
                if f_ext.size:  # a fault ends a playback at the tick that zeroed output
                    n = min(n, ft + 1)
                    break
            if self.live:
                target = wall0 + n * dt / self.speed
                lag = time.perf_counter() - target
                late.append(lag)
                if lag > _SLIP_S:  # the process was stopped: slip, do not race
                    wall0 += lag
                    target += lag
                    slipped += lag
                # sleep most of the wait (releasing the interpreter to the threads serving
                # the link), then spin the last fraction of a millisecond: sleep alone is
                # too coarse
                ahead = target - time.perf_counter() - _SPIN_S
                if ahead > 0:
                    time.sleep(ahead)
                while time.perf_counter() < target:
                    pass
            if n_done < n1:
                break  # window complete
            if timeout is not None and self._ist[K.IST_FIRST] < 0 and n * dt >= timeout:
                break  # nobody tapped
            if pieces is not None and n - pieces.done >= STREAM_TICKS:
                self.trace_sink(pieces.done, pieces.take(n))
            if on_progress is not None:
                partial = self._result(buf, n, tick0, ev_tick, ev_vel)
                if n and not f_ext.size:  # a playback's stylus has no surface in reach
                    partial.live_height = float(buf.pos[n - 1] - cs.plant.surface_height)
                on_progress(n * dt, partial)
        if pieces is not None and n > pieces.done:
            self.trace_sink(pieces.done, pieces.take(n))
        res = self._result(buf, n, tick0, ev_tick, ev_vel, final=True, pieces=pieces)
        res.energy = {"in": float(self._fst[K.FST_EIN]), "out": float(self._fst[K.FST_EOUT])}
        self.first_bounce = (-float(self._fst[K.FST_VIN]), float(self._fst[K.FST_VOUT]))
        res.warnings = _contact_warnings(cs.scene.name, int(self._ist[K.IST_SWITCHES]),
                                         int(self._ist[K.IST_UNRESOLVED]), n, cs.plant.n_sub)
        if self.live:
            wall = time.perf_counter() - start
            self.slipped_s += slipped
            # tick k of the window was paced to wall0 + k·dt/speed, its chunk computed
            # within the chunk before; a slip moved wall0 for the ticks after it
            self._live_clock = HostClock(wall0 - tick0 * dt / self.speed, 1 / self.speed,
                                         chunk * dt / self.speed + slipped, None, 1)
            lat = np.asarray(late)
            res.timing = {"achieved_rate_hz": n / wall if wall > 0 else float("nan"),
                          "slipped_s": slipped,
                          "lateness_p50_s": float(np.median(lat)) if lat.size else 0.0,
                          "lateness_p99_s": float(np.quantile(lat, 0.99)) if lat.size else 0.0,
                          "jitter_sd_s": float(np.std(np.diff(lat))) if lat.size > 1 else 0.0}
        self._output_force = float(buf.cur[n - 1] * dev.force_constant) if n else 0.0
        if self._fault is not None:
            self._output_force = 0.0
        return res

    def _latch(self, t_f: float) -> None:
        """The servo loop zeroed output at device time ``t_f`` [s]: latch the fault it
        means (a non-finite command, the operator's e-stop, or the watchdog)."""
        if self._ist[K.IST_FAULT_CODE] == K.FAULT_DIVERGED:
            if self._fault is None or self._fault.code != "diverged":
                self._fault = FaultEvent(t_f, "diverged", "the simulated stylus left every "
                                         f"physical bound (farther than {K.DIVERGED_M:g} m "
                                         f"from the surface or faster than {K.DIVERGED_MPS:g} "
                                         "m/s): output zeroed, window ended")
        elif self._ist[K.IST_FAULT_CODE] == K.FAULT_NAN:
            if self._fault is None or self._fault.code != "nan_command":
                self._fault = FaultEvent(t_f, "nan_command", "a force command that is not a "
                                         "finite number reached the clamp: output zeroed")
        elif self._estop_requested:
            if self._fault is None or self._fault.t != t_f:
                self._fault = FaultEvent(t_f, "estop", "emergency stop (latched): output zeroed")
        elif self._fault is None:
            self._fault = FaultEvent(t_f, "watchdog", f"no heartbeat for "
                                     f"{self.params.watchdog_s:g} s: output zeroed")

    def _result(self, buf: Buffers, n: int, tick0: int, ev_tick, ev_vel,
                final: bool = False, pieces: TracePieces | None = None) -> WindowResult:
        dev = self.params
        dt = dev.dt
        nev = min(int(self._ist[K.IST_NEV]), len(ev_tick))
        contacts = [ContactEvent((tick0 + int(ev_tick[i])) * dt, float(ev_vel[i]))
                    for i in range(nev)]
        first = self._ist[K.IST_FIRST]
        res = WindowResult(rate_hz=dev.servo_rate_hz,
                           t_first_contact=(tick0 + first) * dt if first >= 0 else None,
                           contacts=contacts)
        if not final:  # the caller says the height: it knows the surface
            return res
        flags = buf.flags[:n].astype(np.uint16)
        fcmd = buf.fcmd[:n]
        sat = (flags & np.uint16(Flags.SATURATED)) != 0
        res.saturations = [SaturationEvent((tick0 + a) * dt,
                                           float(np.max(np.abs(fcmd[a:b]))) / dev.force_constant,
                                           (b - a) * dt) for a, b in runs(sat)]
        ft = int(self._ist[K.IST_FAULT_TICK])
        if ft >= 0:  # the kernel zeroed output at tick ft
            self._latch((tick0 + ft) * dt)
            res.faults = [self._fault]
        res.traces = (pieces or TracePieces(self, buf)).joined(n)
        res.traces["t"] = (tick0 + np.arange(n)) * dt
        return res

    def _traces(self, buf: Buffers, a: int, b: int) -> dict[str, np.ndarray]:
        """The recorded traces of ticks [a, b) of a window: sensor noise, clipping and
        quantization applied, velocity from the encoder. Pieces taken in order join into the
        traces taken at once (the noise stream is drawn in order)."""
        dev = self.params
        acc = buf.acc[a:b].copy()
        if self.noise and dev.accel_noise_rms > 0:
            acc += self.rng_noise.normal(0.0, dev.accel_noise_rms, b - a)
        clipped = np.abs(acc) >= dev.accel_range
        acc = np.clip(acc, -dev.accel_range, dev.accel_range)
        lsb = 2 * dev.accel_range / 2**dev.accel_bits
        acc = np.round(acc / lsb) * lsb
        flags = buf.flags[a:b].astype(np.uint16)
        flags[clipped] |= np.uint16(Flags.ACCEL_CLIPPED)
        w = self._vel_w
        lo = a - (len(w) - 1)  # velocity at tick i is a filter over ticks i-len(w)+1 … i
        pos0 = buf.pos[0] if b else 0.0
        seg = (np.concatenate([np.full(-lo, pos0), buf.pos[:b]]) if lo < 0 else buf.pos[lo:b])
        return {
            "position": buf.pos[a:b].copy(),
            "velocity": np.convolve(seg, w[::-1], mode="valid"),
            "force_cmd": buf.fcmd[a:b].copy(),
            "force_out": buf.fout[a:b].copy(),
            "current": buf.cur[a:b].copy(),
            "accel": acc,
            "flags": flags,
            "true_position": buf.z2[a:b].copy(),
            "true_velocity": buf.v2[a:b].copy(),
            "true_accel": buf.a2[a:b].copy(),
        }


_EMPTY = np.zeros(0)
#: contact changes per servo tick above which a window is said to have chattered: a tap
#: makes two (touch and release) in a few thousand ticks; a stiff lossless contact on a
#: light block bounces many times a tick, and each change is located by bisection
CHATTER_PER_TICK = 0.05


def _contact_warnings(name: str, switches: int, unresolved: int, ticks: int,
                      n_sub: int) -> list[str]:
    """What a window's contact changes say about the simulation, in words (none: none)."""
    out = []
    if ticks and switches > CHATTER_PER_TICK * ticks:
        out.append(f"scene '{name}': the contact chattered ({switches} contact changes in "
                   f"{ticks} ticks, {switches / ticks:.2g} a tick, each located by "
                   "bisection): the simulation runs many times slower than usual; contact "
                   "damping, or a heavier block, stops a stiff lossless contact chattering")
    if unresolved:
        out.append(f"scene '{name}': contact changes passed unlocated ({unresolved} pieces "
                   f"of a tick came after {K.MAX_SWITCHES} changes in one of its {n_sub} "
                   "substeps): the contact's physics there is approximate (its energy account "
                   "may not balance)")
    return out
