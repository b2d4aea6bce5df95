"""The backend-independent device suite, run unchanged against every registered backend
(``device.backends()``: hapticlab's own and any installed), each through the opener it gives
for the suite (``conformance_opener``). A backend registered without one fails the suite,
never skips it."""

import numpy as np
import pytest

from device import backend, backends, open_device
from device.base import HapticDevice
from device.suite import CHECKS, CheckFailed, run_selftest


@pytest.fixture(scope="module", params=backends())
def opener(request):
    """The backend's own way into the suite, for the module (an emulator it starts is
    stopped after)."""
    try:
        reach = backend(request.param).conformance_opener()
    except NotImplementedError as exc:
        pytest.fail(f"the registered backend {request.param!r} has no way into the device "
                    f"suite: {exc}")
    with reach as opener:
        yield opener


@pytest.mark.integration  # the serial and emulator backends' ways start an emulator
@pytest.mark.realtime
@pytest.mark.parametrize("check", sorted(CHECKS))
def test_backend_contract(opener, check):
    detail = CHECKS[check](opener)
    assert isinstance(detail, str) and detail


class _Lying(HapticDevice):
    """A backend that delegates to a real device but breaks one promise, to show the checks
    can fail. It implements only the backend interface (the ``_`` methods): the base class's
    templates do the shared checks."""

    def __init__(self, inner, lie):
        super().__init__()
        self.inner, self.lie = inner, lie

    info = property(lambda self: self.inner.info)
    fault = property(lambda self: self.inner.fault)

    @property
    def output_force(self):
        return 1.0 if self.lie == "output" else self.inner.output_force

    def _load_scene(self, scene, table):
        self.inner.load_scene(scene)

    def _home(self, clearance):
        self.inner.home(clearance)

    def _run_window(self, duration, from_first_contact, timeout, on_progress, heartbeats):
        if self.lie == "sticky_end" and getattr(self, "pending", False):
            self.pending, asked = False, on_progress  # an earlier end reaches this window

            def on_progress(t, partial):
                self.inner.end_window()
                if asked is not None:
                    asked(t, partial)

        res = self.inner.run_window(duration, from_first_contact=from_first_contact,
                                    timeout=timeout, on_progress=on_progress,
                                    heartbeats=heartbeats)
        if self.lie == "velocity":
            res.contacts = [type(c)(c.t, c.velocity * 1.1) for c in res.contacts]
        if self.lie == "unclamped":
            res.traces["current"] = res.traces["force_cmd"] / self.inner.info.force_constant
        if self.lie == "no_fault":
            res.faults = []
        return res

    def _play_force(self, force, heartbeats, on_progress=None):
        res = self.inner.play_force(force, heartbeats=heartbeats, on_progress=on_progress)
        if self.lie == "no_fault":
            res.faults = []
        return res

    def _end_window(self):
        self.pending = True
        if self.lie != "no_end":
            self.inner.end_window()

    def heartbeat(self):
        self.inner.heartbeat()

    def _estop(self):
        if self.lie != "no_estop":
            self.inner.estop()

    def _clear_fault(self):
        self.inner.clear_fault()

    def _zero(self):
        self.inner.zero()

    def _close(self):
        self.inner.close()


@pytest.mark.parametrize("lie, check", [
    ("output", "zero_on_exit"),
    ("velocity", "transient_scaling"),
    ("unclamped", "saturation"),
    ("no_fault", "watchdog"),
    ("no_estop", "estop"),
    ("no_end", "end_window"),
    ("sticky_end", "end_window"),
])
def test_checks_catch_a_device_that_breaks_its_contract(lie, check):
    with pytest.raises(CheckFailed):
        CHECKS[check](lambda: _Lying(open_device("sim", seed=5), lie))


def test_selftest_summary_shape():
    report = run_selftest("sim", lambda: open_device("sim", seed=5))
    assert report["backend"] == "sim"
    assert report["passed"] == len(CHECKS) and report["failed"] == 0
    assert [r["name"] for r in report["checks"]] == list(CHECKS)


def test_selftest_reports_failures_without_crashing():
    report = run_selftest("liar", lambda: _Lying(open_device("sim", seed=5), "velocity"))
    failed = [r["name"] for r in report["checks"] if not r["ok"]]
    # both checks weigh what was played against the incoming speed the device reported
    assert sorted(failed) == ["saturation", "transient_scaling"] and report["failed"] == 2
    assert np.isfinite(report["passed"])
