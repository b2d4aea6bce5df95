"""What the machine did to this test run while a test ran, for the report of a test that
failed: whether the host held the test's processes up, or a hypervisor took the CPUs away.

A test of real time (an e-stop acknowledged within 4 × 200 ms, a device silent for 1 s)
that fails on a busy computer has two candidate causes, the code and the machine. This
watcher samples, every :data:`PERIOD_S`:

- its own lateness waking up (a thread of normal priority in the pytest process: how long
  an ordinary thread waited for a CPU, or for the interpreter's lock while the test ran
  Python);
- the time each CPU was stolen by the hypervisor (``steal`` in ``/proc/stat``: the
  virtual CPU was not running at all, whatever priority its threads had);
- the kernel's CPU pressure (``/proc/pressure/cpu``, "some": time in which at least one
  runnable task waited for a CPU).

A failed test's report gets a section with the worst of each over the test's call. Reading
only ``/proc``, it costs a few microseconds every 20 ms.
"""

from __future__ import annotations

import os
import threading
import time
from collections import deque

PERIOD_S = 0.02
KEEP_S = 900.0  # the longest test (the kill-at-every-write-point one) runs ~130 s loaded
_TICK_S = 1.0 / os.sysconf("SC_CLK_TCK")  # /proc/stat's unit [s]


def _steal() -> list[float]:
    """Each CPU's stolen time so far [s] (empty where /proc/stat cannot be read)."""
    try:
        with open("/proc/stat") as f:
            rows = [line.split() for line in f if line.startswith("cpu") and line[3] != " "]
    except OSError:
        return []
    return [int(r[8]) * _TICK_S if len(r) > 8 else 0.0 for r in rows]


def _pressure_us() -> int | None:
    """The CPU pressure's "some" total so far [µs], or None (no PSI in this kernel)."""
    try:
        with open("/proc/pressure/cpu") as f:
            first = f.readline().split()
    except OSError:
        return None
    return next((int(x[6:]) for x in first if x.startswith("total=")), None)


def cpu_by_process() -> dict[int, tuple[str, float]]:
    """Every process's name and CPU time so far (user + system [s]), from ``/proc``: the
    machine's, not only this run's (the work a test competed with)."""
    out = {}
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/stat") as f:
                text = f.read()
        except OSError:  # gone meanwhile
            continue
        name = text[text.index("(") + 1:text.rindex(")")]
        fields = text[text.rindex(")") + 2:].split()
        out[int(d)] = (name, (int(fields[11]) + int(fields[12])) * _TICK_S)
    return out


def busiest(before: dict[int, tuple[str, float]], after: dict[int, tuple[str, float]],
            span: float, n: int = 6) -> str:
    """The ``n`` processes that used the most CPU between two :func:`cpu_by_process`
    snapshots ``span`` seconds apart, in words (a process started meanwhile counts from 0)."""
    used = sorted(((t - before.get(pid, (name, 0.0))[1], pid, name)
                   for pid, (name, t) in after.items()), reverse=True)[:n]
    return (f"CPU used over the test's {span:.1f} s, most first: " + ", ".join(
        f"{name} ({pid}) {t:.1f} s" for t, pid, name in used if t > 0))


class HostWatch:
    """A daemon thread keeping the last :data:`KEEP_S` of samples
    ``(t [s], lateness [s], steal per CPU [s], pressure [µs])``."""

    def __init__(self) -> None:
        self._samples: deque = deque(maxlen=int(KEEP_S / PERIOD_S))
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="hostwatch", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()

    def _run(self) -> None:
        last = time.monotonic()
        while not self._stop.wait(PERIOD_S):
            now = time.monotonic()
            sample = (now, max(0.0, now - last - PERIOD_S), _steal(), _pressure_us())
            last = now
            with self._lock:
                self._samples.append(sample)

    def summary(self, since: float, until: float) -> str:
        """The worst of what the samples between ``since`` and ``until`` (monotonic [s])
        saw, in words; a plain statement when there were too few samples to judge."""
        with self._lock:
            rows = [s for s in self._samples if since <= s[0] <= until]
        if len(rows) < 2:
            return "the host watcher took fewer than 2 samples during this test"
        late = max(r[1] for r in rows)
        at = next(r[0] for r in rows if r[1] == late) - since
        parts = [f"{len(rows)} samples over {rows[-1][0] - rows[0][0]:.1f} s; the watcher "
                 f"(a thread of pytest, sharing the test's GIL) woke up to "
                 f"{late * 1e3:.0f} ms late ({at:.1f} s into the test)"]
        first, prev_steal = rows[0][2], rows[0][2]
        if first and len(rows[-1][2]) == len(first):
            total = [b - a for a, b in zip(first, rows[-1][2], strict=True)]
            burst = [0.0] * len(first)
            for r in rows[1:]:
                if len(r[2]) == len(prev_steal):
                    burst = [max(m, b - a) for m, a, b in zip(burst, prev_steal, r[2],
                                                               strict=True)]
                prev_steal = r[2]
            parts.append("stolen by the hypervisor: " + ", ".join(
                f"cpu{i} {t * 1e3:.0f} ms (at most {b * 1e3:.0f} ms in one "
                f"{PERIOD_S * 1e3:.0f}-ms sample)" for i, (t, b) in enumerate(
                    zip(total, burst, strict=True))))
        else:
            parts.append("no steal figures (/proc/stat unreadable)")
        if rows[0][3] is not None and rows[-1][3] is not None:
            span = rows[-1][0] - rows[0][0]
            waited = (rows[-1][3] - rows[0][3]) / 1e6
            parts.append(f"some runnable task waited for a CPU {waited:.1f} s of the "
                         f"{span:.1f} s (/proc/pressure/cpu)")
        return "; ".join(parts)
