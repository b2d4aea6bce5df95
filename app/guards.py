"""Exit guards the application installs (a driver never does): output to zero on every exit.

* :func:`install_signal_guards` makes SIGTERM (and SIGHUP, a closed terminal) raise
  :class:`Terminated` in the main thread, so every ``with open_device(...)`` block unwinds
  and closes its device — which zeroes output — and a session marks itself interrupted.
* :func:`close_at_exit` closes a device at interpreter exit if nothing else did.

The device's own watchdog covers a process killed outright (SIGKILL).
"""

from __future__ import annotations

import atexit
import signal
import threading
import weakref

__all__ = ["Terminated", "install_signal_guards", "close_at_exit"]


class Terminated(BaseException):  # noqa: N818 - a signal, like KeyboardInterrupt
    """The process was asked to stop (SIGTERM, SIGHUP)."""

    def __init__(self, signum: int):
        super().__init__(f"signal {signal.Signals(signum).name}")
        self.signum = signum


def _raise(signum, frame) -> None:
    raise Terminated(signum)


def install_signal_guards() -> None:
    """SIGTERM and SIGHUP raise :class:`Terminated` (main thread only; elsewhere a no-op)."""
    if threading.current_thread() is not threading.main_thread():
        return
    for sig in (signal.SIGTERM, signal.SIGHUP):
        try:
            signal.signal(sig, _raise)
        except (ValueError, OSError):  # not allowed here (an embedding host)
            pass


def close_at_exit(device) -> None:
    """Close ``device`` at interpreter exit unless it was closed before (held weakly)."""
    ref = weakref.ref(device)

    def close() -> None:
        d = ref()
        if d is not None:
            d.close()

    atexit.register(close)
