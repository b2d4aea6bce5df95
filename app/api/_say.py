"""Where the API's messages go when the caller names no place: stderr, flushed."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

__all__ = ["to_stderr", "progress_to_stderr"]


def to_stderr(*args) -> None:
    """Print ``args`` to stderr at once (the operator reads them as they come)."""
    print(*args, file=sys.stderr, flush=True)


def progress_to_stderr(quiet_for: float = 2.0, every: float = 2.0,
                       stream=None) -> Callable[[str, int, int], None]:
    """A teller of how far long work has got, for ``progress(step, done, total)``: nothing
    for work done within ``quiet_for`` seconds; after that a line when a step begins and at
    most one every ``every`` seconds while it goes on (``hapticlab: loading sessions
    12,000 of 21,978 (31 s)``), rewritten in place on a terminal."""
    stream = stream or sys.stderr
    start = time.monotonic()
    last = {"step": None, "at": 0.0, "width": 0}
    tty = stream.isatty()

    def tell(step: str, done: int, total: int) -> None:
        now = time.monotonic()
        new = step != last["step"]
        if now - start < quiet_for or (not new and now - last["at"] < every
                                       and done != total):
            last["step"] = step
            return
        count = f" {done:,} of {total:,}" if total > 1 else ""
        line = f"hapticlab: {step}{count} ({now - start:.0f} s)"
        if tty:
            pad = max(0, last["width"] - len(line))
            stream.write(("\n" if new and last["step"] is not None else "\r") + line
                         + " " * pad)
        else:
            stream.write(line + "\n")
        stream.flush()
        last.update(step=step, at=now, width=len(line))

    return tell
