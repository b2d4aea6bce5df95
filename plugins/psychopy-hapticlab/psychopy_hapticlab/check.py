"""What a Haptic device check component drives: hapticlab's preflight or self-test of the
device, run at the start of an experiment, its verdict in the data.

``preflight`` asks the device who it is and whether a fault is latched (nothing moves:
about a second); ``selftest`` runs every check of hapticlab's device self-test (``hapticlab
device selftest``: the spring law, transients, saturation, e-stop, watchdog, ramp… about
10 s on the simulated device, the stylus moving). The check runs in a thread of its own,
so the routine's screen stays up and escape works meanwhile.

On a device whose contact is physical (a board, a bridge) five checks of the self-test need
someone to tap the stylus: what the self-test asks of the operator goes to PsychoPy's log
(warnings, which its console shows) and is the check's :attr:`HapticCheck.text`, drawn on
the experiment's window while it runs; ``deviceAlone`` runs only the checks the device does
alone, the five reported as not run. Only every check passed is a pass.
"""

from __future__ import annotations

import math
import threading
from typing import Any

from psychopy import logging

from .contact import cell, resolve_device
from .device import HapticFaultError

__all__ = ["HapticCheck", "CHECKS", "VERDICTS"]

#: what a Haptic device check runs
CHECKS = ("preflight", "selftest")

#: a check's verdicts: every check passed; one or more failed; none failed but some were not
#: run (device alone); the check could not run (the device failed under it); it never
#: started (its routine ended first). Only ``pass`` lets a ``stopOnFail`` experiment go on.
VERDICTS = ("pass", "fail", "incomplete", "error", "not started")

class HapticCheck:
    """A device check and its verdict.

    Parameters
    ----------
    device : str or HapticlabDevice
        The device, or its name in DeviceManager.
    name : str
        The component's name (data columns ``<name>.<field>``).
    check : str
        ``preflight`` or ``selftest``.
    stopOnFail : bool
        Anything but a pass stops the experiment (a :class:`HapticFaultError` naming the
        checks that failed or were not run, raised after the verdict is recorded).
    deviceAlone : bool
        Self-test of a device whose contact is physical: run only the checks the device
        does alone, those that need someone to tap the stylus reported as not run (so never
        a pass). A device whose contact is simulated runs them all regardless.
    tapWait : float [s]
        Self-test of a device whose contact is physical: how long each check that needs a
        tap waits for the first contact after asking for it.
    win : psychopy.visual.Window, optional
        Where :meth:`draw` shows :attr:`text` to the operator.
    """

    def __init__(self, device, name: str = "hapticCheck", check: str = "preflight",
                 stopOnFail: bool = True, deviceAlone: bool = False, tapWait: float = 30.0,
                 win=None):
        if check not in CHECKS:
            raise ValueError(f"{name}: check must be one of {', '.join(CHECKS)}, got {check!r}")
        tapWait = float(tapWait)
        if not (math.isfinite(tapWait) and tapWait > 0):
            raise ValueError(f"{name}: tapWait must be a positive number of seconds, got "
                             f"{tapWait!r}")
        self.device = resolve_device(device)
        self.name = name
        self.check = check
        self.stopOnFail = bool(stopOnFail)
        self.deviceAlone = bool(deviceAlone)
        self.tapWait = tapWait
        self.win = win
        self.status = None
        self.result: dict | None = None
        #: what the operator should read now: the last line the self-test said (which
        #: checks need a tap, "tap the stylus … now", "contact: … stop tapping"), then the
        #: verdict; empty while there is nothing to say (a simulated device's self-test, a
        #: preflight)
        self.text = ""
        self._said = False
        self._stim = None
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None

    def _say(self, line: str) -> None:
        """A line for the operator (from the check's thread): the log and :attr:`text`."""
        logging.warning(f"hapticlab {self.name}: {line}")
        self.text, self._said = line, True

    def _run(self) -> None:
        try:
            if self.check == "selftest":
                rows = self.device.selftest(deviceAlone=self.deviceAlone,
                                            tapWait=self.tapWait, say=self._say)["checks"]
            else:
                rows = [{"name": c.name, "ok": c.ok,
                         "status": "passed" if c.ok else "failed",
                         "detail": c.detail + (f" — {c.fix}" if c.fix and not c.ok else "")}
                        for c in self.device.preflight()]
            self.result = {"checks": rows,
                           **{k.replace(" ", "_"): sum(r["status"] == k for r in rows)
                              for k in ("passed", "failed", "not run")}}
            if self._said:  # the operator was told what to do: now what came of it
                self.text = self._summary()
        except BaseException as exc:  # noqa: BLE001 - handed to the main thread
            self._error = exc

    def _summary(self) -> str:
        r = self.result
        return (f"{self.check}: {r['passed']} passed, {r['failed']} failed, "
                f"{r['not_run']} not run")

    def _named(self, status: str) -> str:
        return ";".join(r["name"] for r in self.result["checks"] if r["status"] == status)

    def start(self) -> None:
        """The component starts: the check begins (in its own thread)."""
        from psychopy.constants import STARTED

        self.result, self._error, self.text, self._said = None, None, "", False
        self._thread = threading.Thread(target=self._run, name=f"hapticlab {self.check}",
                                        daemon=True)
        self._thread.start()
        self.status = STARTED
        logging.exp(f"hapticlab {self.name}: {self.check} of {self.device.label} started"
                    + (" (device-alone checks only)" if self.deviceAlone
                       and self.check == "selftest" else ""))

    def poll(self) -> bool:
        """True once the check has finished."""
        from psychopy.constants import FINISHED, STARTED

        if self.status == STARTED and not self._thread.is_alive():
            self.status = FINISHED
        return self.status == FINISHED

    def draw(self, win=None) -> None:
        """Show :attr:`text` at the foot of ``win`` (default: the one given when made), so
        that the operator at a physical device reads when to tap; nothing while there is
        nothing to say."""
        win = win or self.win
        if win is None or not self.text:
            return
        if self._stim is None:
            from psychopy import visual

            self._stim = visual.TextStim(win, text="", units="norm", pos=(0, -0.8),
                                         height=0.07, wrapWidth=1.9, color="white")
        if self._stim.text != self.text:
            self._stim.text = self.text
        self._stim.draw()

    def wait(self) -> dict:
        """Run the check (when not started) and wait for it; its result."""
        if self._thread is None:
            self.start()
        self._thread.join()
        self.poll()
        return self.result or {}

    @property
    def verdict(self) -> str:
        """One of :data:`VERDICTS`: ``pass`` (every check passed), ``fail`` (one or more
        failed), ``incomplete`` (none failed, some not run), ``error`` (the check could not
        run) or ``not started``."""
        if self._error is not None:
            return "error"
        if self.result is None:
            return "not started"
        if self.result["failed"]:
            return "fail"
        return "incomplete" if self.result["not_run"] else "pass"

    def data(self) -> dict[str, Any]:
        """The verdict's columns (without the ``<name>.`` prefix)."""
        info = self.device.info
        out: dict[str, Any] = {"check": self.check, "verdict": self.verdict,
                               "device": self.device.spec, "device_model": info.model,
                               "device_id": info.serial_number, "firmware": info.firmware,
                               "servo_rate_hz": info.servo_rate_hz,
                               "current_limit_a": self.device.device.current_limit,
                               "physical_contact": not info.simulated_contact}
        if self.check == "selftest":
            out["device_alone"] = self.deviceAlone and not info.simulated_contact
        if self.result is not None:
            mark = {"passed": "ok", "failed": "FAIL", "not run": "not run"}
            out.update({"passed": self.result["passed"], "failed": self.result["failed"],
                        "not_run": self.result["not_run"],
                        "failed_checks": self._named("failed"),
                        "not_run_checks": self._named("not run"),
                        "checks": "; ".join(f"{r['name']}: {mark[r['status']]} "
                                            f"({r['detail']})" for r in self.result["checks"])})
        if self._error is not None:
            out["error"] = f"{type(self._error).__name__}: {self._error}"
        return out

    def record(self, handler) -> dict[str, Any]:
        """End Routine: wait for the check, write its verdict into ``handler``, then stop
        the experiment when anything but a pass and ``stopOnFail``."""
        if self._thread is not None:
            self._thread.join()
            self.poll()
        data = self.data()
        for k, v in data.items():
            handler.addData(f"{self.name}.{k}", cell(v))
        said = (f"hapticlab {self.name}: {self.check} of {self.device.label}: "
                f"{data['verdict']}"
                + (f" ({self._summary()})" if self.result is not None else "")
                + "".join(f"; {label} {data[k].replace(';', ', ')}"
                          for k, label in (("failed_checks", "failed:"),
                                           ("not_run_checks", "not run:")) if data.get(k))
                + (f"; {data['error']}" if "error" in data else ""))
        (logging.exp if data["verdict"] == "pass" else logging.warning)(said)
        if self.stopOnFail and data["verdict"] != "pass":
            raise HapticFaultError(f"{self.device.label} ({self.device.spec}) did not pass its "
                                   f"{self.check}: {self._why(data)}; the experiment stops "
                                   "here, the verdict is in its data", self.device.label)
        return data

    def _why(self, data: dict) -> str:
        """What kept the check from a pass, in words."""
        if data["verdict"] == "error":
            return f"it could not run ({data['error']})"
        if data["verdict"] == "not started":
            return "it never started (its routine ended first)"
        why = []
        if data["failed_checks"]:
            why.append(f"failed {data['failed_checks'].replace(';', ', ')}")
        if data["not_run_checks"]:
            why.append(f"did not run {data['not_run_checks'].replace(';', ', ')} (they need "
                       "someone to tap the stylus: untick Device alone)")
        return "; ".join(why)
