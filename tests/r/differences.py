"""Print the largest difference between hapticlab's statistics and R's references, per
analysis (the table in docs/explanation/statistics.md).

    .venv/bin/python tests/r/differences.py

Relative differences (|ours − R| / |R|), except where tests/analysis/test_against_r.py
compares otherwise: the ordinal model's values and a TOST t at the margin are compared in
absolute units with a floor of 1. Not a test: the test asserts the tolerances; this prints
what was measured.
"""

from __future__ import annotations

import collections
import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def largest_differences() -> dict[str, float]:
    spec = importlib.util.spec_from_file_location(
        "test_against_r", ROOT / "tests" / "analysis" / "test_against_r.py")
    t = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(t)
    worst: dict[str, float] = collections.defaultdict(float)
    for study, make in t.studies.STUDIES.items():
        ours = t.OURS.get(study, t._ours_oneway)(make())
        for r in t.REF[t.REF["study"] == study].itertuples():
            o, ref = float(ours[(r.analysis, r.term, r.stat)]), float(r.value)
            if r.analysis.startswith("ordinal") or (r.analysis == "tost"
                                                    and r.stat.startswith("t_")):
                diff = abs(o - ref) / max(abs(ref), 1.0)
            else:
                diff = abs(o - ref) / abs(ref) if ref != 0 else abs(o)
            group = r.analysis + (" (CI of ηp²)" if r.stat.startswith("np2_ci") else "")
            worst[group] = max(worst[group], diff)
    return dict(sorted(worst.items()))


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    for group, diff in largest_differences().items():
        print(f"{group:28s} {diff:.1e}")
