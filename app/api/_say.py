"""Where the API's messages go when the caller names no place: stderr, flushed."""

from __future__ import annotations

import sys

__all__ = ["to_stderr"]


def to_stderr(*args) -> None:
    """Print ``args`` to stderr at once (the operator reads them as they come)."""
    print(*args, file=sys.stderr, flush=True)
