"""``make demo``: a whole study with simulated participants, analysed, with its report.

Realism (9 participants), factorial (9) and identification (14) sessions run headless on
the simulated device through the real runner, engine and recorder; the analysis then
writes the report. Data go to ``OUT/data/``, the report to ``OUT/report/``.
"""

from __future__ import annotations

import shutil
import sys
import time
from pathlib import Path

__all__ = ["run_demo", "simulate_demo_study", "STUDY"]

#: (protocol, participants, id prefix, group) of the demo study, as in the papers.
#: Identification: 6 experts and 8 novices (Table 3: 18 and 24 answers of 3 each).
STUDY = (("realism", 9, "R", ""), ("factorial", 9, "F", ""),
         ("identification", 6, "IE", "expert"), ("identification", 8, "IN", "novice"))


class StudyStopped(RuntimeError):
    """A simulated session did not complete; ``rc`` is its exit code."""

    def __init__(self, rc: int):
        super().__init__(f"a simulated session stopped with exit code {rc}")
        self.rc = rc


def simulate_demo_study(data: str | Path, seed: int) -> dict[str, float]:
    """Simulate every session of :data:`STUDY` (the demo's four groups, each by
    :func:`app.api.simulate_study`) into ``data``; returns seconds per stage."""
    from app.api import simulate_study as simulate

    times = {}
    for i, (protocol, n, prefix, group) in enumerate(STUDY):
        print(f"simulating {protocol}: {n} participants{f' ({group})' if group else ''}",
              file=sys.stderr, flush=True)
        study = simulate(protocol, n, seed=seed * 10 + i, data=data, prefix=prefix,
                         group=group, traces="contacts")
        if not study.complete:
            raise StudyStopped(study.sessions[-1].exit_code)
        times[f"simulate {protocol} ({n}{', ' + group if group else ''})"] = study.seconds
    return times


def run_demo(seed: int = 1, out: str | Path = "out/demo") -> int:
    """Simulate, analyse and report; returns 0 when the report is written."""
    from app.api import analyze

    out = Path(out)
    data, report = out / "data", out / "report"
    for d in (data, report):  # a demo always starts from nothing
        if d.exists():
            shutil.rmtree(d)
    t0 = time.perf_counter()
    try:
        simulate_demo_study(data, seed)
    except StudyStopped as exc:
        return exc.rc
    t_sim = time.perf_counter() - t0
    print("analysing …", file=sys.stderr, flush=True)
    analyze(data, report)
    t_all = time.perf_counter() - t0
    print(f"data:   {data}/\nreport: {report / 'report.html'} (and report.json, report.md)\n"
          f"simulated in {t_sim:.0f} s, analysed in {t_all - t_sim:.0f} s")
    return 0
