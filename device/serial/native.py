"""The serial link's native thread (``firmware/src/hostlink.c``), loaded with ctypes.

A Python host's threads take turns at one interpreter lock, so a heartbeat written by a
Python thread waits behind whatever else the process does: drawing the participant's
window, decoding a trace stream, a garbage collection. On a loaded 2-core machine that
wait reached the device's 100-ms watchdog. :class:`NativeLink` hands the two jobs that must
not wait — taking bytes off the port as they arrive, and heartbeats — to a thread in C
that holds no interpreter lock, asks for real-time scheduling and locks its memory where
the system allows it, and heartbeats only while the host renews its lease (:meth:`renew`,
and every write; reads and statistics do not, so the link's reader thread cannot keep a
hung main loop alive), so a host whose main loop stopped still trips the device's
watchdog.

The library is built by setuptools with the package (``setup.py``; a plain C library, not
an extension module). Where it is missing — no compiler at install time, not POSIX — or
``HAPTICLAB_NATIVE_LINK=0`` is set, :func:`load` says why and the link runs its reader and
heartbeats in Python threads, as before.
"""

from __future__ import annotations

import ctypes
import errno
import importlib.machinery
import os
from pathlib import Path

__all__ = ["NativeLink", "load", "GAP_BINS", "RT_PRIORITY"]

#: frame-to-frame gap histogram: 1-ms bins, the last one ≥ 127 ms (hl_hostlink.h)
GAP_BINS = 128
#: the SCHED_FIFO priority the link's thread asks for: above every normal process, below
#: the kernel's interrupt threads (50)
RT_PRIORITY = 20


class _Stats(ctypes.Structure):
    _fields_ = [("rx_bytes", ctypes.c_uint64), ("tx_frames", ctypes.c_uint64),
                ("heartbeats", ctypes.c_uint64), ("last_rx_ns", ctypes.c_int64),
                ("gap_hist", ctypes.c_uint32 * GAP_BINS), ("gap_max_us", ctypes.c_uint32),
                ("wake_late_max_us", ctypes.c_uint32), ("rx_waits", ctypes.c_uint32),
                ("lease_lapses", ctypes.c_uint32), ("tx_timeouts", ctypes.c_uint32),
                ("write_max_us", ctypes.c_uint32), ("rt_priority", ctypes.c_int32),
                ("rt_errno", ctypes.c_int32), ("locked", ctypes.c_int32),
                ("error", ctypes.c_int32), ("silent_ms", ctypes.c_int32)]


_lib: ctypes.CDLL | None = None
_why_not: str | None = None


def _find() -> Path | None:
    here = Path(__file__).resolve().parent
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        p = here / f"_hostlink{suffix}"
        if p.is_file():
            return p
    return None


def load() -> tuple[ctypes.CDLL | None, str | None]:
    """The native library, or None and why not (loaded once per process)."""
    global _lib, _why_not
    if _lib is not None or _why_not is not None:
        return _lib, _why_not
    if os.environ.get("HAPTICLAB_NATIVE_LINK", "1") == "0":
        _why_not = "HAPTICLAB_NATIVE_LINK=0"
        return None, _why_not
    path = _find()
    if path is None:
        _why_not = ("the native link library was not built (setup.py builds it with the "
                    "package where a C compiler is present)")
        return None, _why_not
    try:
        lib = ctypes.CDLL(str(path), use_errno=True)
    except OSError as exc:
        _why_not = f"the native link library does not load ({exc})"
        return None, _why_not
    u8p = ctypes.POINTER(ctypes.c_uint8)
    lib.hl_link_open.argtypes = [ctypes.c_int, ctypes.c_int]
    lib.hl_link_heartbeat.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_size_t,
                                      ctypes.c_uint32, ctypes.c_uint32, ctypes.c_uint32]
    lib.hl_link_pause.argtypes = [ctypes.c_int, ctypes.c_int]
    lib.hl_link_write.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_size_t, ctypes.c_int]
    lib.hl_link_write.restype = ctypes.c_long
    lib.hl_link_read.argtypes = [ctypes.c_int, u8p, ctypes.c_size_t, ctypes.c_int]
    lib.hl_link_read.restype = ctypes.c_long
    lib.hl_link_renew.argtypes = [ctypes.c_int]
    lib.hl_link_stats_get.argtypes = [ctypes.c_int, ctypes.POINTER(_Stats), ctypes.c_int]
    lib.hl_link_close.argtypes = [ctypes.c_int]
    _lib = lib
    return _lib, None


def _oserror(code: int, what: str) -> OSError:
    return OSError(code, f"{what}: {os.strerror(code)}")


class NativeLink:
    """One port served by the native thread.

    Parameters
    ----------
    fd : int
        An open, non-blocking file descriptor; the caller closes it after :meth:`close`.
    rt_priority : int
        SCHED_FIFO priority to ask for (0: the normal scheduler).

    Raises
    ------
    OSError
        The library is missing (``ENOSYS``, with the reason) or the thread did not start.
    """

    def __init__(self, fd: int, rt_priority: int = RT_PRIORITY):
        lib, why = load()
        if lib is None:
            raise OSError(errno.ENOSYS, why)
        self._lib = lib
        slot = lib.hl_link_open(int(fd), int(rt_priority))
        if slot < 0:
            raise _oserror(-slot, "native link")
        self.slot = slot
        self._buf = (ctypes.c_uint8 * 65536)()
        self.closed = False

    def heartbeat(self, frame: bytes, period_s: float, lease_s: float,
                  silence_s: float) -> None:
        """Heartbeat with ``frame`` after ``period_s`` [s] without a frame, while the lease
        (``lease_s`` [s] from the host's last renewal: :meth:`renew` or a write) holds;
        the device counts as silent after ``silence_s`` [s] without a byte (0: never)."""
        rc = self._lib.hl_link_heartbeat(self.slot, frame, len(frame),
                                         max(1, int(period_s * 1e6)), max(1, int(lease_s * 1e6)),
                                         max(0, int(silence_s * 1e6)))
        if rc < 0:
            raise _oserror(-rc, "native link heartbeat")

    def pause(self, paused: bool) -> None:
        self._lib.hl_link_pause(self.slot, int(bool(paused)))

    def renew(self) -> None:
        self._lib.hl_link_renew(self.slot)

    def write(self, data: bytes, timeout_s: float) -> None:
        """Write ``data`` whole (frames never interleave with the heartbeats).

        Raises
        ------
        TimeoutError
            The port took nothing more for ``timeout_s`` [s].
        OSError
            The port failed.
        """
        n = self._lib.hl_link_write(self.slot, bytes(data), len(data),
                                    max(0, int(timeout_s * 1000)))
        if n == -errno.ETIMEDOUT:
            raise TimeoutError(f"write timed out after {timeout_s:g} s")
        if n < 0:
            raise _oserror(-n, "write")

    def read(self, timeout_s: float) -> bytes:
        """What arrived (up to 64 KiB), waiting up to ``timeout_s`` [s] for the first byte;
        ``b""`` when nothing came.

        Raises
        ------
        OSError
            The port failed (``EIO``: the other end hung up) or the link was closed
            (``EBADF``).
        """
        n = self._lib.hl_link_read(self.slot, self._buf, len(self._buf),
                                   max(0, int(timeout_s * 1000)))
        if n < 0:
            raise _oserror(-n, "read")
        return bytes(self._buf[:n]) if n else b""

    def stats(self, reset: bool = False) -> dict:
        """The thread's figures: bytes and frames, the gaps between frames written while
        heartbeating (1-ms histogram and the longest [ms]), its worst wake-up lateness
        [ms], what it was granted (real-time priority, locked memory), the port's error
        and the device's silence [ms]."""
        s = _Stats()
        self._lib.hl_link_stats_get(self.slot, ctypes.byref(s), int(bool(reset)))
        return {"rx_bytes": s.rx_bytes, "tx_frames": s.tx_frames, "heartbeats": s.heartbeats,
                "last_rx_ns": s.last_rx_ns, "gap_hist": list(s.gap_hist),
                "gap_max_ms": s.gap_max_us / 1000, "wake_late_max_ms": s.wake_late_max_us / 1000,
                "rx_waits": s.rx_waits, "lease_lapses": s.lease_lapses,
                "tx_timeouts": s.tx_timeouts, "write_max_ms": s.write_max_us / 1000,
                "rt_priority": s.rt_priority,
                "rt_refused": os.strerror(s.rt_errno) if s.rt_errno else None,
                "memory_locked": ("ring, stack and state", "stack and state", "no")[
                    2 - s.locked] if s.locked in (0, 1, 2) else "no",
                "error": s.error, "silent_ms": s.silent_ms}

    def close(self) -> None:
        """Stop the thread (a read waiting elsewhere returns ``EBADF``); idempotent."""
        if not self.closed:
            self.closed = True
            self._lib.hl_link_close(self.slot)
