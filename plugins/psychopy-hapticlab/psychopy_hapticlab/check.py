"""What a Haptic device check component drives: hapticlab's preflight or self-test of the
device, run at the start of an experiment, its verdict in the data.

``preflight`` asks the device who it is and whether a fault is latched (nothing moves:
about a second); ``selftest`` runs every check of hapticlab's device self-test (``hapticlab
device selftest``: the spring law, transients, saturation, e-stop, watchdog, ramp… about
10 s on the simulated device, the stylus moving). The check runs in a thread of its own,
so the routine's screen stays up and escape works meanwhile.
"""

from __future__ import annotations

import threading
from typing import Any

from psychopy import logging

from .contact import cell, resolve_device
from .device import HapticFaultError

__all__ = ["HapticCheck", "CHECKS"]

#: what a Haptic device check runs
CHECKS = ("preflight", "selftest")


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
        A failed check stops the experiment (a :class:`HapticFaultError` naming what failed,
        raised after the verdict is recorded).
    """

    def __init__(self, device, name: str = "hapticCheck", check: str = "preflight",
                 stopOnFail: bool = True):
        if check not in CHECKS:
            raise ValueError(f"{name}: check must be one of {', '.join(CHECKS)}, got {check!r}")
        self.device = resolve_device(device)
        self.name = name
        self.check = check
        self.stopOnFail = bool(stopOnFail)
        self.status = None
        self.result: dict | None = None
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None

    def _run(self) -> None:
        try:
            if self.check == "selftest":
                out = self.device.selftest()
                rows = out["checks"]
            else:
                rows = [{"name": c.name, "ok": c.ok, "detail": c.detail + (
                    f" — {c.fix}" if c.fix and not c.ok else "")}
                    for c in self.device.preflight()]
            self.result = {"checks": rows, "passed": sum(r["ok"] for r in rows),
                           "failed": sum(not r["ok"] for r in rows)}
        except BaseException as exc:  # noqa: BLE001 - handed to the main thread
            self._error = exc

    def start(self) -> None:
        """The component starts: the check begins (in its own thread)."""
        from psychopy.constants import STARTED

        self.result, self._error = None, None
        self._thread = threading.Thread(target=self._run, name=f"hapticlab {self.check}",
                                        daemon=True)
        self._thread.start()
        self.status = STARTED
        logging.exp(f"hapticlab {self.name}: {self.check} of {self.device.label} started")

    def poll(self) -> bool:
        """True once the check has finished."""
        from psychopy.constants import FINISHED, STARTED

        if self.status == STARTED and not self._thread.is_alive():
            self.status = FINISHED
        return self.status == FINISHED

    def wait(self) -> dict:
        """Run the check (when not started) and wait for it; its result."""
        if self._thread is None:
            self.start()
        self._thread.join()
        self.poll()
        return self.result or {}

    @property
    def verdict(self) -> str:
        """``pass``, ``fail``, ``error`` (the check could not run) or ``not_run``."""
        if self._error is not None:
            return "error"
        if self.result is None:
            return "not_run"
        return "pass" if self.result["failed"] == 0 else "fail"

    def data(self) -> dict[str, Any]:
        """The verdict's columns (without the ``<name>.`` prefix)."""
        info = self.device.info
        out: dict[str, Any] = {"check": self.check, "verdict": self.verdict,
                               "device": self.device.spec, "device_model": info.model,
                               "device_id": info.serial_number, "firmware": info.firmware,
                               "servo_rate_hz": info.servo_rate_hz,
                               "current_limit_a": self.device.device.current_limit}
        if self.result is not None:
            out.update({"passed": self.result["passed"], "failed": self.result["failed"],
                        "failed_checks": ";".join(r["name"] for r in self.result["checks"]
                                                  if not r["ok"]),
                        "checks": "; ".join(f"{r['name']}: {'ok' if r['ok'] else 'FAIL'} "
                                            f"({r['detail']})" for r in self.result["checks"])})
        if self._error is not None:
            out["error"] = f"{type(self._error).__name__}: {self._error}"
        return out

    def record(self, handler) -> dict[str, Any]:
        """End Routine: wait for the check, write its verdict into ``handler``, then stop
        the experiment when it failed and ``stopOnFail``."""
        if self._thread is not None:
            self._thread.join()
            self.poll()
        data = self.data()
        for k, v in data.items():
            handler.addData(f"{self.name}.{k}", cell(v))
        logging.exp(f"hapticlab {self.name}: {self.check} {data['verdict']}"
                    + (f" ({data['failed_checks']})" if data.get("failed_checks") else ""))
        if self.stopOnFail and data["verdict"] in ("fail", "error"):
            what = data.get("failed_checks") or data.get("error", "")
            raise HapticFaultError(f"{self.device.label} ({self.device.spec}) failed its "
                                   f"{self.check}: {what}; the experiment stops before any "
                                   "trial", self.device.label)
        return data
