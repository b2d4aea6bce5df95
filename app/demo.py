"""``make demo``: a whole study with simulated participants, analysed, with its report.

Realism (9 participants), factorial (9) and identification (14) sessions run headless on
the simulated device through the real runner, engine and recorder; the analysis then
writes the report. Data go to ``OUT/data/``, the report to ``OUT/report/``.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import time
from pathlib import Path

__all__ = ["run_demo", "STUDY"]

#: (protocol, participants, id prefix, group) of the demo study, as in the papers.
STUDY = (("realism", 9, "R", ""), ("factorial", 9, "F", ""),
         ("identification", 7, "IE", "expert"), ("identification", 7, "IN", "novice"))


def run_demo(seed: int = 1, out: str | Path = "out/demo") -> int:
    """Simulate, analyse and report; returns 0 when the report is written."""
    from analysis.report import analyze
    from app.simulate_cli import simulate

    out = Path(out)
    data, report = out / "data", out / "report"
    for d in (data, report):  # a demo always starts from nothing
        if d.exists():
            shutil.rmtree(d)
    t0 = time.perf_counter()
    for i, (protocol, n, prefix, group) in enumerate(STUDY):
        print(f"simulating {protocol}: {n} participants{f' ({group})' if group else ''}",
              file=sys.stderr, flush=True)
        rc = simulate(argparse.Namespace(protocol=protocol, participants=n, seed=seed * 10 + i,
                                         data=str(data), device="sim", traces="contacts",
                                         prefix=prefix, group=group))
        if rc != 0:
            return rc
    t_sim = time.perf_counter() - t0
    print("analysing …", file=sys.stderr, flush=True)
    analyze(data, report)
    t_all = time.perf_counter() - t0
    print(f"data:   {data}/\nreport: {report / 'report.html'} (and report.json, report.md)\n"
          f"simulated in {t_sim:.0f} s, analysed in {t_all - t_sim:.0f} s")
    return 0
