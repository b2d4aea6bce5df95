"""The API's benchmarks (``hapticlab bench WHAT``)."""

from __future__ import annotations

from ..errors import UsageError

__all__ = ["BENCHMARKS", "BENCH_OPTIONS", "benchmark"]


#: the benchmarks (``hapticlab bench WHAT``), each a module of ``benchmarks/``
BENCHMARKS = ("sim", "accuracy", "matching", "link", "crash", "analysis", "demo", "energy",
              "orderings", "causes", "factorial", "tick", "scale", "thresholds")
#: the benchmarks' options and their defaults (each benchmark reads those it uses; the
#: CLI's ``bench --help`` says which)
BENCH_OPTIONS = {"json": False, "repeats": 5, "fuzz": 100_000, "kills": 1000, "points": None,
                 "boundaries": None, "sessions": 200,
                 "seeds": None, "firmware": None, "load": None, "targets": None,
                 "seconds": 60.0, "baseline": False, "no_window": False, "rows": None}


def benchmark(what: str, **options) -> int:
    """Run benchmark ``what`` (one of :data:`BENCHMARKS`), which prints its table (JSON
    rows with ``json=True``) with ratios against a baseline run in the same process; its
    exit status.

    Raises
    ------
    UsageError
        No such benchmark, an option not in :data:`BENCH_OPTIONS`, a bad value of one, or
        one the benchmark does not read (:func:`benchmarks._options.check_options`).
    """
    import argparse
    import importlib

    if what not in BENCHMARKS:
        raise UsageError(f"no benchmark named {what!r}; available: {', '.join(BENCHMARKS)}")
    from benchmarks._options import check_options

    options = check_options(what, options, BENCH_OPTIONS)  # every value, before anything runs
    module = importlib.import_module(f"benchmarks.{what}")
    return module.main(argparse.Namespace(what=what, **options))
