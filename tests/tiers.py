"""The suite's tiers, and the guard that keeps a test in its tier.

A test carries the markers of what it costs (``[tool.pytest.ini_options] markers`` in
pyproject.toml: integration, firmware, qemu, screen, r, slow). A test with none of them is
in the unit tier: :class:`TierGuard` marks it ``unit`` at collection, so ``pytest -m unit``
(``make check``) runs that tier and ``pytest -m "not unit"`` the rest.

The guard fails a unit test that

- starts a process (``subprocess``, ``fork``, ``exec``, ``posix_spawn``, ``os.system``:
  the interpreter's audit events) or opens a pseudo-terminal (``os.openpty``), in its
  setup (fixtures of any scope included) or its call; or
- costs more than :data:`UNIT_BUDGET_S` over its setup and call, counted as wall-clock time
  less the time the machine made the test's threads wait for a CPU
  (``/proc/self/task/*/schedstat``): a busy machine does not make a unit test look
  expensive, and a test that waits (a sleep, a device at real time) is not cheap because it
  waits.

So a test that starts a process is marked by whoever writes it, or fails where it is written,
and the unit tier stays a few minutes as it grows.
"""

from __future__ import annotations

import os
import sys
import time

import pytest

#: a unit test's bound: its setup and call [s], wall-clock time less the time it waited for
#: a CPU. The unit tier's tests take milliseconds to a few tenths of a second; one that takes
#: seconds belongs in the `slow` tier
UNIT_BUDGET_S = 4.0

#: the interpreter's audit events (PEP 578) of starting a process
_SPAWN_EVENTS = frozenset({"subprocess.Popen", "os.fork", "os.forkpty", "os.posix_spawn",
                           "os.exec", "os.spawn", "os.system", "pty.spawn"})

#: the guards watching a test now, innermost last (a pytester run nests one in another)
_WATCHING: list[list[str]] = []


def _audit(event: str, args: tuple) -> None:
    if _WATCHING and event in _SPAWN_EVENTS:
        what = args[1] if event == "subprocess.Popen" else args[:2]
        _WATCHING[-1].append(f"{event} {what!r}"[:200])


_real_openpty = os.openpty


def _openpty():
    if _WATCHING:
        _WATCHING[-1].append("os.openpty()")
    return _real_openpty()


_installed: list[bool] = []


def _install() -> None:
    """The audit hook (which cannot be removed, and costs a set look-up per event while no
    test is watched) and the pty wrapper, once per process."""
    if not _installed:
        sys.addaudithook(_audit)
        os.openpty = _openpty
        _installed.append(True)


def _waits() -> dict[str, float]:
    """How long each thread of this process has waited for a CPU so far [s], by thread id
    (empty where the kernel does not say)."""
    out = {}
    try:
        tids = os.listdir("/proc/self/task")
    except OSError:
        return out
    for tid in tids:
        try:
            with open(f"/proc/self/task/{tid}/schedstat") as f:
                out[tid] = int(f.read().split()[1]) / 1e9
        except (OSError, IndexError, ValueError):  # gone meanwhile
            continue
    return out


def _waited_for_cpu(before: dict[str, float], after: dict[str, float]) -> float:
    """The time the test waited for a CPU between two :func:`_waits` [s]: the longest any
    of its threads waited (the test's own thread, or a numerical library's worker thread
    it was blocked on; they wait side by side, so the longest is a lower bound)."""
    return max((t - before.get(tid, 0.0) for tid, t in after.items()), default=0.0)


#: markers pyproject.toml declares that are not tiers: the one this module gives, and the
#: one that says how tests are scheduled (tests/conftest.py)
NOT_TIERS = ("unit", "realtime")


def tier_markers(config) -> tuple[str, ...]:
    """The tiers' marker names, as pyproject.toml declares them."""
    names = (line.split(":", 1)[0].strip() for line in config.getini("markers"))
    return tuple(n for n in names if n and n not in NOT_TIERS)


class _Spent:
    """What a test did while watched: processes started, cost [s]."""

    def __init__(self) -> None:
        self.spawned: list[str] = []
        self.cost = 0.0


class TierGuard:
    """The pytest plugin: marks the unit tier and fails a unit test that leaves it."""

    def __init__(self, config, budget_s: float = UNIT_BUDGET_S) -> None:
        self.tiers = tier_markers(config)
        self.budget_s = budget_s
        self._spent: dict[str, _Spent] = {}
        _install()

    def is_unit(self, item) -> bool:
        return not any(item.get_closest_marker(t) for t in self.tiers)

    @pytest.hookimpl(tryfirst=True)
    def pytest_collection_modifyitems(self, items) -> None:
        # tryfirst: before `-m` deselects by marker
        for item in items:
            if self.is_unit(item):
                item.add_marker(pytest.mark.unit)

    def _watched(self, item):
        """Run one phase of a test (the caller's ``yield``), its spawns and its cost going
        to the test's record when it is a unit test."""
        if not self.is_unit(item):
            yield
            return
        spent = self._spent.setdefault(item.nodeid, _Spent())
        _WATCHING.append(spent.spawned)
        t0, w0 = time.monotonic(), _waits()
        try:
            yield
        finally:
            spent.cost += (time.monotonic() - t0) - _waited_for_cpu(w0, _waits())
            _WATCHING.pop()

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_setup(self, item):
        yield from self._watched(item)

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_call(self, item):
        yield from self._watched(item)

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_makereport(self, item, call):
        outcome = yield
        if call.when != "call":
            return
        spent = self._spent.pop(item.nodeid, None)
        report = outcome.get_result()
        if spent is None or not report.passed:
            return
        why = []
        if spent.spawned:
            more = len(spent.spawned) - 3
            why.append(f"it started a process or opened a pseudo-terminal: "
                       f"{'; '.join(spent.spawned[:3])}{f' and {more} more' if more > 0 else ''}"
                       f". Mark it `integration` (or the tier of what it starts)")
        if spent.cost > self.budget_s:
            why.append(f"its setup and call took {spent.cost:.1f} s (not counting time spent "
                       f"waiting for a CPU), over the unit tier's {self.budget_s:g} s. "
                       f"Make it cheaper or mark it `slow`")
        if why:
            report.outcome = "failed"
            report.longrepr = ("this test has no tier marker, so it is in the unit tier "
                               "(tests/tiers.py), but " + "; and ".join(why) + ".")
