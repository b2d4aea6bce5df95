"""Backend-independent device checks: the same contract for ``sim`` and ``serial:…``.

Each check opens a fresh device through ``opener`` (a zero-argument callable returning
a :class:`~device.base.HapticDevice`), exercises one promise of the interface and
returns a short detail string, or raises :class:`CheckFailed`. The pytest suite
(``tests/device/test_backend_suite.py``) and ``hapticlab device selftest SPEC`` run
the same functions.

The scenes here are test fixtures with physical values from SPEC §1.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from .base import HapticDevice
from .errors import DeviceError, DeviceFaultError
from .events import Flags, WindowResult
from .scene import Material, Pulse, Ringing, Scene

__all__ = ["CHECKS", "TAPPED", "CheckFailed", "Operator", "run_selftest", "check_backend",
           "SUITE_SCENES"]

Opener = Callable[[], HapticDevice]

SUITE_SCENES = {
    # a 3.5-cm wood cube ringing as Table 1's wood (its contact and support derived)
    "wood": Scene("wood", material=Material(70_000.0, ringing=Ringing(-1500.0, 600.0, 592.0),
                                            mass=0.026)),
    "firm_spring": Scene("firm_spring", spring=680.0),
    "pulse_firm": Scene("pulse_firm", spring=680.0, transient=Pulse(5.7, 0.020)),
    "hard_pulse": Scene("hard_pulse", spring=680.0, transient=Pulse(200.0, 0.010)),
}


class CheckFailed(AssertionError):
    """A device check did not hold; the message says what was seen."""


def _require(cond: bool, msg: str) -> None:
    if not cond:
        raise CheckFailed(msg)


class Operator:
    """The person at a device with a physical contact, whom the self-test asks to tap the
    stylus during each check of :data:`TAPPED` (a simulated device's hand taps by itself).

    Each such check's window starts with a prompt, then waits up to ``wait_s`` for the
    first contact; it says when it got one (stop tapping) or when it gave up.

    Parameters
    ----------
    say : callable
        Where the operator reads, one line each (a terminal).
    wait_s : float [s]
        How long a window waits for the first contact after its prompt.
    """

    def __init__(self, say: Callable[[str], None], wait_s: float = 30.0) -> None:
        if not (math.isfinite(wait_s) and wait_s > 0):
            raise ValueError(f"the wait for a tap must be a positive number of seconds, "
                             f"got {wait_s!r}")
        self.say, self.wait_s, self.check = say, float(wait_s), ""

    #: what the operator is warned of before a check's prompt
    WARNINGS = {"saturation": "a hard pulse is coming: each tap is met by a kick as strong "
                              "as the device gives (its current limit), which is what this "
                              "check asks for; hold the stylus firmly and tap briskly"}

    def window(self, dev: HapticDevice, duration: float, **kw) -> WindowResult:
        """Run a window that needs the stylus tapped: warn, prompt, wait, say how it went."""
        if self.check in self.WARNINGS:
            self.say(f"[{self.check}] warning: {self.WARNINGS[self.check]}")
        self.say(f"[{self.check}] tap the stylus down onto the virtual surface now, and keep "
                 f"tapping until told to stop (waiting up to {self.wait_s:g} s for contact)")
        res = dev.run_window(duration, timeout=self.wait_s, **kw)
        if res.t_first_contact is None:
            self.say(f"[{self.check}] no contact in {self.wait_s:g} s: gave up waiting; stop "
                     "tapping, hold the stylus still above the surface")
            raise CheckFailed(f"no contact within {self.wait_s:g} s of the prompt to tap the "
                              "stylus: gave up waiting")
        self.say(f"[{self.check}] contact: window recorded; stop tapping, hold the stylus "
                 "still above the surface")
        return res


def _window(dev: HapticDevice, scene: Scene, duration: float = 1.0,
            operator: Operator | None = None, **kw) -> WindowResult:
    dev.load_scene(scene)
    dev.home()
    if operator is not None:
        return operator.window(dev, duration, **kw)
    return dev.run_window(duration, **kw)


def _record_at(res: WindowResult, t: float) -> int:
    """The first trace record at or after time ``t`` [s] (the traces may be decimated:
    one record every few servo ticks, on a narrow link)."""
    return int(math.ceil((t - res.traces["t"][0]) * res.rate_hz - 1e-6))


def _decimation(dev: HapticDevice, res: WindowResult) -> int:
    """Servo ticks per trace record: 1 unless the link is too narrow for every tick."""
    return int(round(dev.info.servo_rate_hz / res.rate_hz))


def check_info(opener: Opener) -> str:
    with opener() as dev:
        i = dev.info
        _require(1_000 <= i.servo_rate_hz <= 20_000, f"servo rate {i.servo_rate_hz} Hz")
        for name in ("current_limit", "force_constant", "effective_mass", "watchdog_s",
                     "encoder_resolution", "accel_range"):
            v = getattr(i, name)
            _require(math.isfinite(v) and v > 0, f"info.{name} = {v!r}")
        ticks = ("" if i.tick_p99_s is None else
                 f"; tick periods since it started: 99 % within {i.tick_p99_s * 1e3:.3g} ms, "
                 f"longest {i.tick_max_s * 1e3:.3g} ms (nominal {1e3 / i.servo_rate_hz:.3g})")
        return f"{i.model} at {i.servo_rate_hz:g} Hz, {i.max_force:.2f} N max{ticks}"


def check_real_sample(opener: Opener, operator: Operator | None = None) -> str:
    with opener() as dev:
        res = _window(dev, SUITE_SCENES["wood"], 1.5, operator)
        _require(len(res.contacts) >= 1, "no contact detected on a real sample")
        _require(not res.saturations, "a real sample reported saturation")
        cur = res.traces["current"]
        _require(bool(np.all(cur == 0)), f"real sample was rendered: |I| up to {np.abs(cur).max()}")
        v = res.velocities
        _require(bool(np.all((v > 0) & (v < 1.0))), f"implausible incoming speeds {v}")
        return f"{len(v)} contacts, speeds {v.min():.3f}–{v.max():.3f} m/s"


def check_spring_law(opener: Opener, operator: Operator | None = None) -> str:
    with opener() as dev:
        sc = SUITE_SCENES["firm_spring"]
        res = _window(dev, sc, 1.0, operator)
        tr = res.traces
        pen = np.maximum(sc.surface_height - tr["position"], 0.0)
        steady = (tr["flags"] & Flags.RAMP) == 0
        expect = sc.spring * pen
        err = np.abs(tr["force_cmd"] - expect)[steady]
        # 1 ppm: traces cross a serial link as IEEE-754 binary32
        _require(err.size > 0 and float(err.max()) <= 1e-6 * max(1.0, float(expect.max())),
                 f"force_cmd differs from K·penetration by up to {err.max():.3g} N")
        _require(float(expect.max()) > 0, "the stylus never penetrated the virtual spring")
        return (f"F = K·p holds on {int(steady.sum())} records at {res.rate_hz:g} Hz "
                f"(peak {expect.max():.2f} N)")


def check_transient_scaling(opener: Opener, operator: Operator | None = None) -> str:
    with opener() as dev:
        sc = SUITE_SCENES["pulse_firm"]
        res = _window(dev, sc, 1.5, operator)
        tr = res.traces
        _require(len(res.contacts) >= 1, "no contact")
        pulse = sc.transient
        n_pulse = int(round(pulse.duration * res.rate_hz))  # records
        slack = 0 if _decimation(dev, res) == 1 else 1  # a record more or less
        worst = 0.0
        whole = 0  # pulses that end before the window does (a late tap's is cut short)
        for c in res.contacts:
            i = _record_at(res, c.t)
            spring = sc.spring * max(sc.surface_height - tr["position"][i], 0.0)
            worst = max(worst, abs(tr["force_cmd"][i] - spring - pulse.gain * c.velocity))
            if i + n_pulse + 2 > len(tr["t"]):
                continue
            whole += 1
            on = (tr["flags"][i:i + n_pulse + 2] & Flags.TRANSIENT) != 0
            _require(abs(int(on.sum()) - n_pulse) <= slack,
                     f"pulse played {int(on.sum())} records, expected {n_pulse}")
        _require(whole >= 1, "no pulse ended inside the window")
        _require(worst <= 1e-5, f"pulse force differs from A·v by {worst:.3g} N")
        return (f"{len(res.contacts)} pulses of A·v (error {worst:.1e} N), {n_pulse} records "
                f"each at {res.rate_hz:g} Hz")


def check_saturation(opener: Opener, operator: Operator | None = None) -> str:
    with opener() as dev:
        res = _window(dev, SUITE_SCENES["hard_pulse"], 1.5, operator)
        lim = dev.info.current_limit
        cur = np.abs(res.traces["current"])
        _require(bool(res.saturations), "a 200 N·s/m pulse did not saturate")
        _require(float(cur.max()) <= lim * (1 + 1e-9), f"current {cur.max()} A above limit {lim}")
        peaks = [s.peak_current for s in res.saturations]
        _require(min(peaks) > lim, f"saturation peak {min(peaks)} A not above the limit {lim} A")
        # the fastest tap's pulse alone asks for gain × v (its spring adds to that): a device
        # that clipped the pulse table would saturate less, or not at all
        pulse = SUITE_SCENES["hard_pulse"].transient
        v = max(c.velocity for c in res.contacts)
        want = pulse.gain * v / dev.info.force_constant
        _require(max(peaks) >= 0.99 * want, f"the pulse of a {v:.3f}-m/s tap asked for "
                 f"{max(peaks):.2f} A at most; {pulse.gain:g} N·s/m × v asks for {want:.2f} A")
        return (f"{len(peaks)} saturations of {len(res.contacts)} taps, peaks "
                f"{min(peaks):.2f}–{max(peaks):.2f} A (the fastest tap's pulse asks for "
                f"≥ {want:.2f} A), clamp {lim} A")


def check_window_length(opener: Opener, operator: Operator | None = None) -> str:
    with opener() as dev:
        res = _window(dev, SUITE_SCENES["firm_spring"], 1.0, operator)
        _require(res.t_first_contact is not None, "no first contact")
        span = res.traces["t"][-1] - res.t_first_contact
        _require(abs(span - 1.0) <= 2.0 / res.rate_hz, f"window spans {span:.5f} s, expected 1 s")
        return f"window of {span:.4f} s from the first contact"


#: the force [N] the safety checks cut, played open loop in free air: a 100-Hz, ±0.5-N
#: square wave, the size of the play_force check's sine (a buzz in a hand holding the stylus
#: still). No contact is needed, so a device with a physical contact does these checks
#: alone. Square, so that every tick's force is 0.5 N: a cosine crossed zero every 5 ms,
#: and a device reporting at 40 Hz (every 2.5 periods) samples it at one |phase| all along,
#: at 0 mN exactly for 1 start in 50 at 10 kHz (1 in 20 at 4 kHz), when the e-stop and
#: exit checks saw no force to cut (review r60). Zero-mean, so that it pushes the held
#: stylus nowhere (a force with a 0.3-N floor left it moving into the play_force check)
_CUT_N, _CUT_HZ = 0.5, 100.0
#: output counts as on from 1 mN: the wire's force step
_OUTPUT_ON_N = 1e-3
#: "just before" an event [s]: half the force's period, so its peak lies inside
_JUST_BEFORE_S = 0.5 / _CUT_HZ


def _force_to_cut(dev: HapticDevice, seconds: float) -> np.ndarray:
    """``seconds`` [s] of the force the safety checks cut, one command per servo tick."""
    rate = dev.info.servo_rate_hz
    t = np.arange(int(round(seconds * rate))) / rate
    return _CUT_N * np.where(np.cos(2 * np.pi * _CUT_HZ * t) >= 0, 1.0, -1.0)


def _output_on(dev: HapticDevice) -> bool:
    """The device says it is putting out force now (a callback's view)."""
    return abs(dev.output_force) >= _OUTPUT_ON_N


def _cut(dev: HapticDevice, res: WindowResult, event: str) -> float:
    """The peak force [N] the device put out just before ``res``'s fault (within
    :data:`_JUST_BEFORE_S`, or its last three records when they are sparser), after
    requiring that there was one and that the current is zero from the fault on: a check
    that output was cut passes only when there was output to cut."""
    tr = res.traces
    t_f = res.faults[0].t
    span = max(_JUST_BEFORE_S, 3.0 / res.rate_hz)
    near = (tr["t"] < t_f) & (tr["t"] >= t_f - span)
    force = np.abs(tr["current"][near]) * dev.info.force_constant
    peak = float(force.max()) if force.size else 0.0
    _require(peak >= _OUTPUT_ON_N, f"no force was being output before the {event}: nothing "
             f"shown (at most {peak * 1e3:.3g} mN in the {span * 1e3:.3g} ms before it)")
    after = tr["t"] >= t_f
    _require(bool(np.all(tr["current"][after] == 0)), f"current not zero after the {event}")
    return peak


def check_estop(opener: Opener) -> str:
    """An ESTOP while the device puts out force (a free-air playback: no contact needed)
    latches an estop fault and zeroes the output that was there just before it; a device
    that reports what it saw (LINK_REPORT) did so within its stated bound from the frame's
    arrival (``estop_bound_s``), traces streaming meanwhile."""
    with opener() as dev:
        dev.load_scene(SUITE_SCENES["firm_spring"])  # to home and run a window once cleared
        sent: list[float] = []

        def stop(t: float, _partial: WindowResult) -> None:
            # past the enable ramp, once the device says force is on, or at 0.5 s whatever
            # it said: the trace before the fault is the judge (_cut)
            if not sent and t >= 0.1 and (_output_on(dev) or t >= 0.5):
                sent.append(dev.output_force)
                dev.estop()

        seen = getattr(dev, "device_link_report", None)
        took = ""
        try:
            if seen is not None:
                seen(reset=True)
            res = dev.play_force(_force_to_cut(dev, 1.5), on_progress=stop)
            _require(bool(sent), "no force was being output before the e-stop: nothing "
                     f"shown (a 1.5-s playback of {_CUT_N:g} N ended before the "
                     "device reported force or 0.5 s passed, so the e-stop was never "
                     "pressed)")
            _require(bool(res.faults), "the e-stop was pressed after the playback had "
                     "ended (this computer held the host up for over a second?): nothing "
                     "was cut")
            _require(res.faults[0].code == "estop", f"faults: {res.faults}")
            peak = _cut(dev, res, "e-stop")
            report = seen() if seen is not None else None
            bound = dev.estop_bound_s() if report is not None else None
            ms = report["estop_max_ms"] if report is not None else None
            if bound is not None:  # hapticlab's firmware or emulator: a stated bound
                _require(ms is not None, "the device counted no ESTOP in its LINK_REPORT")
                # 1 µs: the report's resolution
                _require(ms <= bound * 1e3 + 1e-3, f"output zeroed {ms:.3f} ms after the "
                         f"ESTOP arrived, over the device's bound of {bound * 1e3:.3f} ms")
                took = (f"; zeroed within {ms:.3f} ms of its arrival (bound "
                        f"{bound * 1e3:.3f} ms)")
            elif ms is not None:  # another device: its own figure, not judged
                took = f"; zeroed within {ms:.3f} ms of its arrival, as the device counts it"
            _require(dev.output_force == 0.0, "output not zero after the e-stop")
            for call in (dev.home, lambda: dev.run_window(0.5)):
                try:
                    call()
                except DeviceFaultError:
                    pass
                else:
                    raise CheckFailed("the e-stop did not stay latched")
        finally:
            dev.clear_fault()  # a device keeps its fault across connections; leave it clean
        dev.home()
        again = dev.run_window(0.5, from_first_contact=False)
        _require(not again.faults, "fault came back after clearing")
        return (f"cut {peak:.2f} N of played force at t={res.faults[0].t:.3f} s, latched"
                f"{took}; cleared and re-homed")


def check_end_window(opener: Opener) -> str:
    """A participant who moves on ends a window before its duration: the result covers the
    ticks up to the device's end, no fault, output still on for the next window."""
    with opener() as dev:
        asked = 10.0

        def move_on(t: float, _partial: WindowResult) -> None:
            if t >= 0.3:
                dev.end_window()

        res = _window(dev, SUITE_SCENES["firm_spring"], asked, from_first_contact=False,
                      on_progress=move_on)
        _require(not res.faults and not res.timed_out,
                 f"faults {res.faults}, timed out {res.timed_out}")
        span = res.traces["t"][-1] - res.traces["t"][0]
        _require(span < asked - 1.0, f"a window ended at 0.3 s ran {span:.3f} s of {asked:g}")
        dev.end_window()  # between windows: nothing, also not to the next window
        again = dev.run_window(0.2, from_first_contact=False)  # homed still: no home() here
        ran = again.traces["t"][-1] - again.traces["t"][0] if again.traces["t"].size else 0.0
        _require(not again.faults and ran >= 0.2 - 2.0 / again.rate_hz,  # its last record
                 f"the window after an end between windows ran {ran:.4f} s of 0.2")
        # ended at once, perhaps before any contact: not a window that timed out
        now = dev.run_window(asked, timeout=30.0, on_progress=lambda t, p: dev.end_window())
        _require(not now.timed_out and not now.faults,
                 f"a window ended at once: timed out {now.timed_out}, faults {now.faults}")
        return f"ended after {span:.3f} s of a {asked:g}-s window; the next ran homed"


def check_watchdog(opener: Opener) -> str:
    """The host falls silent while the device puts out force (a free-air playback without
    heartbeats): the watchdog trips within its period, zeroes the output that was there just
    before, and latches."""
    with opener() as dev:
        wd = dev.info.watchdog_s
        try:
            res = dev.play_force(_force_to_cut(dev, max(1.0, 2 * wd)), heartbeats=False)
            _require(bool(res.faults) and res.faults[0].code == "watchdog",
                     f"faults: {res.faults}")
            t0 = res.traces["t"][0]
            dt_f = res.faults[0].t - t0
            _require(dt_f <= wd + 2.0 / res.rate_hz + 0.05,
                     f"watchdog tripped after {dt_f:.4f} s")
            peak = _cut(dev, res, "watchdog trip")
            _require(dev.fault is not None, "watchdog fault not latched")
        finally:
            dev.clear_fault()  # a device keeps its fault across connections; leave it clean
        return (f"cut {peak:.2f} N of played force {dt_f * 1e3:.1f} ms into a silence "
                f"(T_wd {wd * 1e3:g} ms)")


def check_ramp(opener: Opener) -> str:
    """Output enabled is ramped up, from the enabling command's tick. Seen in a playback
    from output off, which enables output itself: a window after HOME would need the host
    to start it within the ramp's 50 ms of device time, a deadline a busy computer (QEMU
    beside two CPU-bound processes) does not always keep."""
    with opener() as dev:
        dev.zero()
        res = dev.play_force(np.full(int(0.2 * dev.info.servo_rate_hz), 0.2))
        ramp = (res.traces["flags"] & Flags.RAMP) != 0
        _require(bool(ramp[0]), "no output ramp after enabling")
        n = int(np.argmin(ramp)) if not ramp.all() else len(ramp)
        _require(not ramp[n:].any(), "ramp flag not one run from enable")
        return f"output ramp over the first {n / res.rate_hz * 1e3:.0f} ms"


def check_zero_on_exit(opener: Opener) -> str:
    """A session that fails by an exception while the device puts out force (a free-air
    playback) leaves it, by the ``with`` block's exit, with zero output and closed."""
    dev = opener()
    before: list[float] = []

    def fail(t: float, _partial: WindowResult) -> None:
        if t >= 0.1 and _output_on(dev):  # past the enable ramp
            before.append(dev.output_force)
            raise RuntimeError("simulated failure inside the session")

    try:
        with dev:
            dev.play_force(_force_to_cut(dev, 1.5), on_progress=fail)
            raise RuntimeError("simulated failure inside the session")  # no force came
    except RuntimeError:
        pass
    _require(dev.output_force == 0.0, f"output {dev.output_force} N after exit by exception")
    _require(bool(before), "no force was being output before the exit: nothing shown (the "
             f"device reported none during a 1.5-s playback of {_CUT_N:g} N)")
    try:
        dev.run_window(0.3)
    except DeviceError:
        pass
    else:
        raise CheckFailed("a closed device still ran a window")
    return f"closed with zero output after an exception while putting out {abs(before[0]):.2f} N"


def check_play_force(opener: Opener) -> str:
    with opener() as dev:
        rate = dev.info.servo_rate_hz
        n = int(0.3 * rate)
        t = np.arange(n) / rate
        force = np.where(t > 0.1, 0.5 * np.sin(2 * np.pi * 100 * t), 0.0)  # after the ramp
        res = dev.play_force(force)
        tr = res.traces
        d = _decimation(dev, res)
        t, force = t[::d], force[::d]
        _require(len(tr["t"]) == t.size, f"{len(tr['t'])} records for {n} commanded ticks "
                 f"at decimation {d}")
        on = t > 0.1
        err = np.max(np.abs(tr["force_cmd"][on] - force[on]))
        # the wire carries force commands in 1-mN steps
        _require(err <= 5e-4 + 1e-9, f"commanded force differs from the request by {err:.3g} N")
        # the stylus moves: its accelerometer says so, or, on a device without one, its
        # velocity (the commercial devices' bridges)
        name, unit = ("accel", "m/s²") if "accel" in tr else ("velocity", "m/s")
        a_on = np.std(tr[name][t > 0.15])
        a_off = np.std(tr[name][(t > 0.06) & (t < 0.1)])
        _require(a_on > 5 * a_off, f"no {name} response: {a_on:.3g} vs {a_off:.3g} {unit}")
        _require(not res.contacts, "free-air playback reported a contact")
        return (f"100-Hz force played open loop: {name} {a_on:.3g} {unit} rms vs {a_off:.3g} "
                "at rest")


def check_bad_input(opener: Opener) -> str:
    with opener() as dev:
        for call, exc in ((lambda: dev.load_scene("wood"), TypeError),
                          (lambda: dev.run_window(1.0), DeviceError)):
            try:
                call()
            except exc:
                pass
            else:
                raise CheckFailed(f"bad call accepted (expected {exc.__name__})")
        dev.load_scene(SUITE_SCENES["firm_spring"])
        dev.home()
        try:
            dev.run_window(-1.0)
        except ValueError:
            pass
        else:
            raise CheckFailed("negative window duration accepted")
        return "rejects non-scenes, unhomed windows and negative durations"


CHECKS: dict[str, Callable[[Opener], str]] = {
    "info": check_info,
    "real_sample": check_real_sample,
    "spring_law": check_spring_law,
    "transient_scaling": check_transient_scaling,
    "saturation": check_saturation,
    "window_length": check_window_length,
    "estop": check_estop,
    "end_window": check_end_window,
    "watchdog": check_watchdog,
    "ramp": check_ramp,
    "zero_on_exit": check_zero_on_exit,
    "play_force": check_play_force,
    "bad_input": check_bad_input,
}

#: the checks a device with a physical contact cannot do alone: each needs the stylus tapped
#: down onto the virtual surface during its window (taken by an :class:`Operator`); the
#: others need no contact (a simulated device's hand taps in all of them by itself)
TAPPED = ("real_sample", "spring_law", "transient_scaling", "saturation", "window_length")


def _clear_left_fault(opener: Opener) -> str | None:
    """Clear a fault left latched on the device; return its code (None: there was none,
    or the device cannot be reached to say)."""
    try:
        with opener() as dev:
            if dev.fault is None:
                return None
            code = dev.fault.code
            dev.clear_fault()
            return code
    except Exception:  # noqa: BLE001 - the failed check already says what went wrong
        return None


def run_selftest(spec: str, opener: Opener, *, operator: Operator | None = None,
                 device_alone: bool = False, say: Callable[[str], None] | None = None) -> dict:
    """Run every check; return ``{"backend", "passed", "failed", "not_run", "checks":
    [...]}``, each check's row ``name``, ``status`` (``passed``, ``failed`` or ``not run``),
    ``ok`` (passed) and ``detail``.

    A check that fails may leave a fault latched (a device keeps it across connections);
    it is named in that check's row and cleared, so that the checks after it test what
    they say instead of failing with "clear it first".

    Parameters
    ----------
    operator : Operator, optional
        The person who taps the stylus in the checks of :data:`TAPPED`, asked at each (a
        device with a physical contact); first told which checks need them.
    device_alone : bool
        Run only the checks the device does alone: those of :data:`TAPPED` are reported
        as not run, never as passed.
    say : callable, optional
        Where the plan is said (default: the operator's, else nowhere).
    """
    say = say or (operator.say if operator is not None else None)
    alone = [n for n in CHECKS if n not in TAPPED]
    tapped = [n for n in CHECKS if n in TAPPED]
    if say is not None and tapped and (operator is not None or device_alone):
        say(f"self-test of {spec}: {len(alone)} checks the device does alone "
            f"({', '.join(alone)}); {len(tapped)} need someone to tap the stylus "
            f"({', '.join(tapped)})"
            + (": not run (device alone)" if device_alone else
               ": you will be asked at each; until then hold the stylus still above the "
               "virtual surface"))
    rows = []
    for name, fn in CHECKS.items():
        if name in TAPPED and device_alone:
            rows.append({"name": name, "status": "not run", "ok": False,
                         "detail": "needs someone to tap the stylus: not run (device alone)"})
            continue
        try:
            if name in TAPPED and operator is not None:
                operator.check = name
                detail = fn(opener, operator)
            else:
                detail = fn(opener)
            status = "passed"
        except Exception as exc:  # a check reports, never crashes the self-test
            detail, status = f"{type(exc).__name__}: {exc}", "failed"
            left = _clear_left_fault(opener)
            if left is not None:
                detail += f" (it left a latched {left} fault: cleared for the next checks)"
        rows.append({"name": name, "status": status, "ok": status == "passed",
                     "detail": detail})
    count = {k: sum(r["status"] == k for r in rows) for k in ("passed", "failed", "not run")}
    return {"backend": spec, "passed": count["passed"], "failed": count["failed"],
            "not_run": count["not run"], "checks": rows}


def check_backend(name: str) -> dict:
    """Run every check against the registered backend ``name``, through the device it gives
    for the suite (``conformance_opener``): what a backend's own tests call, in its own
    distribution, to show it keeps the contract. Returns :func:`run_selftest`'s report.

    Raises
    ------
    UnknownBackendError, BackendError
        No such backend, or it cannot be loaded.
    NotImplementedError
        The backend gives no device for the suite.
    """
    from .registry import backend

    with backend(name).conformance_opener() as opener:
        return run_selftest(name, opener)
