"""Helpers shared by the benchmarks: medians of repeats and table printing."""

from __future__ import annotations

import contextlib
import json
import os
import statistics
import tempfile
import time
from collections.abc import Callable, Sequence
from typing import Any

__all__ = ["median_time", "print_table", "emit", "library_store", "parse_seeds"]


@contextlib.contextmanager
def library_store(prefix: str):
    """Matched-sample libraries built during a benchmark go to a temporary store, removed
    afterwards, unless ``HAPTICLAB_LIBRARIES`` names one already."""
    if "HAPTICLAB_LIBRARIES" in os.environ:
        yield
        return
    with tempfile.TemporaryDirectory(prefix=prefix) as tmp:
        os.environ["HAPTICLAB_LIBRARIES"] = tmp
        try:
            yield
        finally:
            os.environ.pop("HAPTICLAB_LIBRARIES", None)


def parse_seeds(text: str | None, default: Sequence[int]) -> list[int]:
    """``--seeds 1,2,3`` as a list (``default`` when not given); anything else is refused
    by name (a seed is a whole number >= 0, and at least one is needed)."""
    from app.errors import UsageError

    if not text:
        return list(default)
    try:
        seeds = [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise UsageError(f"--seeds {text!r}: whole numbers separated by commas, e.g. 1,2,3"
                         ) from None
    if not seeds or any(s < 0 for s in seeds):
        raise UsageError(f"--seeds {text!r}: at least one seed, each >= 0")
    return seeds


def median_time(fn: Callable[[], Any], repeats: int) -> float:
    """Median wall time [s] of ``repeats`` calls (machines are shared and noisy)."""
    times = []
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def print_table(title: str, columns: Sequence[str], rows: Sequence[Sequence[Any]]) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title=title)
    for c in columns:
        table.add_column(c, no_wrap=True)
    for r in rows:
        table.add_row(*[str(x) for x in r])
    Console(width=160).print(table)


def emit(payload: dict, as_json: bool) -> None:
    if as_json:
        print(json.dumps(payload, indent=2))
