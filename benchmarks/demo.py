"""``hapticlab bench demo``: the whole-study dry run of ``make demo``, stage by stage.

Runs the demo study (realism 9, factorial 9, identification 14 simulated participants,
then the analysis and report) into a temporary folder ``--repeats`` times and reports the
median time of each stage against the 3-minute budget of the issue (the ratio column is
budget / measured: above 1 is within budget).
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

from ._common import emit, print_table

BUDGET_S = 180.0


def main(args) -> int:
    from analysis.report import analyze
    from app.demo import simulate_demo_study

    runs: dict[str, list[float]] = {}
    for _ in range(max(1, min(args.repeats, 3))):
        with tempfile.TemporaryDirectory() as tmp:
            data = Path(tmp) / "data"
            total = time.perf_counter()
            for stage, s in simulate_demo_study(data, seed=1).items():
                runs.setdefault(stage, []).append(s)
            t0 = time.perf_counter()
            analyze(data, Path(tmp) / "report")
            runs.setdefault("analyze + report", []).append(time.perf_counter() - t0)
            runs.setdefault("whole demo", []).append(time.perf_counter() - total)
    med = {k: statistics.median(v) for k, v in runs.items()}
    rows = [(k, f"{v:.1f}", f"{BUDGET_S / v:.1f}× under budget" if k == "whole demo" else "")
            for k, v in med.items()]
    print_table(f"make demo, stage by stage (median of {len(runs['whole demo'])} runs, s)",
                ["stage", "s", "vs 3-min budget"], rows)
    emit({"stages_s": med, "budget_s": BUDGET_S}, args.json)
    return 0
