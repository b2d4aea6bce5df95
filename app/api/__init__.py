"""The programmatic API: run, resume and simulate sessions, analyse a data folder.

The command line is a thin layer over these functions. Every error they raise on purpose is
a :class:`~device.errors.HapticlabError` (bad input, unusable files, a device that fails);
a session that stops part way is not an error but a :class:`SessionResult` whose status
says so (everything recorded is on disk and :func:`resume_session` continues it).

``app.api`` is the public face: import from here. The code lives in one module per thing it
serves, and new code goes there:

- :mod:`app.api.sessions` — run, resume, simulate, preflight (with :mod:`app.api.results`
  for what they return);
- :mod:`app.api.devices` — open, list, self-test, emulate, forecast saturation;
- :mod:`app.api.protocols` — a protocol's plan, and the protocol checked against a device;
- :mod:`app.api.analysis` — the report, the exports, the power of a design;
- :mod:`app.api.benchmarks` — ``hapticlab bench``.

Examples
--------
>>> from app.api import run_session, simulate_study, analyze        # doctest: +SKIP
>>> r = run_session("realism", "P01", device="sim", responder="simulated", data="sim-data",
...                 audio=False)                                     # doctest: +SKIP
>>> r.status, r.folder                                               # doctest: +SKIP
('complete', PosixPath('sim-data/sub-P01/ses-1'))
"""

from __future__ import annotations

from .analysis import analyze, export, power
from .benchmarks import BENCH_OPTIONS, BENCHMARKS, benchmark
from .devices import (
    EMULATORS,
    device_list,
    device_selftest,
    emulate,
    open_device_for,
    saturation_forecast,
)
from .protocols import OVERHEAD_S, protocol_plan, validate_protocol
from .results import SessionResult, StudyResult
from .sessions import (
    DEFAULT_SIM_DATA,
    KIND_OF,
    preflight,
    preflight_line,
    resume_session,
    run_session,
    session_seed,
    simulate_study,
)

__all__ = ["SessionResult", "StudyResult", "run_session", "resume_session", "simulate_study",
           "analyze", "export", "session_seed", "protocol_plan", "validate_protocol", "power",
           "preflight", "preflight_line", "saturation_forecast", "open_device_for",
           "device_selftest", "device_list", "emulate", "EMULATORS", "benchmark", "BENCHMARKS",
           "BENCH_OPTIONS", "KIND_OF", "DEFAULT_SIM_DATA", "OVERHEAD_S"]
