"""``hapticlab bench scale``: ``analyze`` and ``export`` against the number of rows.

Data: realism studies written by :mod:`benchmarks._study` (45.5 rows per participant on
average: the planned trials and one redrawn attempt for every other participant), of
10³, 10⁴, 10⁵ and 10⁶ rows by default (``--rows 1000,100000``: others). 10⁶ rows are 21,978
participants, as when many labs' data are pooled.

Each command runs in a child process of its own, so that its peak memory (the child's
maximum resident set, from ``wait4``) is its own and nothing is cached between sizes:

* ``analyze`` (report.json and report.md; HTML adds only rendering), with the time of each
  of its steps (loading, choosing the sessions, each analysis, figures, writing) as its
  progress reports them;
* ``export --format long-csv``.

Times are medians of ``--repeats`` runs for sizes up to 10⁴ and one run above (an analysis
of 10⁶ rows takes minutes). Ratios are to the smallest size, measured in the same run: time
growing as the rows do is linear; the memory ratio shows what grows with the data beyond
the interpreter's own. Writing the folders is not timed (it is the benchmark's set-up).
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ._common import emit, print_table

#: the sizes measured by default [rows]
ROWS = (1_000, 10_000, 100_000, 1_000_000)

#: the child that runs analyze in process, noting when each step began
_ANALYZE = """
import json, sys, time
from analysis.report import analyze
steps = []
def tell(step, done, total):
    step = step.split(" (")[0]  # 'analysing realism/testing', without its row count
    if not steps or steps[-1][0] != step:
        steps.append((step, time.perf_counter()))
t0 = time.perf_counter()
rep = analyze(sys.argv[1], sys.argv[2], formats=("json", "md"), progress=tell)
end = time.perf_counter()
marks = [*steps, ("end", end)]
print(json.dumps({"seconds": end - t0,
                  "steps": {s: b - a for (s, a), (_n, b) in zip(marks, marks[1:])},
                  "analyses": [a["id"] + ": " + (a.get("models", {}).get("ordinal")
                                                  if isinstance(a.get("models", {}).get(
                                                      "ordinal"), str) else "ordinal fitted")
                               for a in rep["analyses"]]}))
"""


def parse_rows(text: str | None) -> list[int]:
    """``--rows``: sizes as whole numbers ≥ 100 (``1000,1e6``), or the default."""
    from app.errors import UsageError

    if text is None:
        return list(ROWS)
    try:
        sizes = [int(float(x)) for x in str(text).split(",") if x.strip()]
    except ValueError:
        raise UsageError(f"--rows {text!r}: row counts separated by commas, e.g. "
                         "1000,100000 or 1e3,1e6") from None
    if not sizes or min(sizes) < 100:
        raise UsageError(f"--rows {text!r}: at least one size, each >= 100 rows")
    return sorted(set(sizes))


def _run(args: list[str]) -> tuple[float, int, str]:
    """Run ``python args``; (wall s, peak RSS bytes of that child, its stdout)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    out = proc.stdout.read()
    err = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, args[:4]))} failed:\n"
                           f"{err.decode(errors='replace')[-3000:]}")
    return wall, usage.ru_maxrss * 1024, out.decode()


def measure(rows: int, repeats: int, work: Path) -> dict:
    """Write a study of about ``rows`` rows, then time analyze and export on it."""
    from ._study import rows_per_participant, write_study

    per = rows_per_participant("realism")
    n = max(2, round(rows / per))
    data = work / f"study-{rows}"
    t0 = time.perf_counter()
    made = write_study(data, n, protocol="realism", seed=rows)
    written = time.perf_counter() - t0
    runs = repeats if rows <= 10_000 else 1
    analyze, export = [], []
    for k in range(runs):
        out = work / f"report-{rows}-{k}"
        wall, peak, text = _run(["-c", _ANALYZE, str(data), str(out)])
        analyze.append((wall, peak, json.loads(text.strip().splitlines()[-1])))
        wall, peak, _ = _run(["-m", "app", "export", str(data), "--out",
                              str(work / f"export-{rows}-{k}"), "--format", "long-csv"])
        export.append((wall, peak))
    mid = sorted(analyze, key=lambda r: r[0])[len(analyze) // 2]
    return {"rows": made["rows"], "participants": n, "write_s": written,
            "analyze_s": statistics.median(r[0] for r in analyze),
            "analyze_peak_mb": max(r[1] for r in analyze) / 2**20,
            "analyze_steps_s": mid[2]["steps"], "analyses": mid[2]["analyses"],
            "analyze_start_s": mid[0] - mid[2]["seconds"],
            "export_s": statistics.median(r[0] for r in export),
            "export_peak_mb": max(r[1] for r in export) / 2**20, "runs": runs}


def main(args) -> int:
    sizes = parse_rows(getattr(args, "rows", None))
    with tempfile.TemporaryDirectory(prefix="hapticlab-scale-") as tmp:
        results = []
        for rows in sizes:
            r = measure(rows, args.repeats, Path(tmp))
            results.append(r)
            print(f"{r['rows']:,} rows: analyze {r['analyze_s']:.1f} s "
                  f"({r['analyze_peak_mb']:.0f} MB), export {r['export_s']:.1f} s "
                  f"({r['export_peak_mb']:.0f} MB)", file=sys.stderr, flush=True)
    base = results[0]
    for r in results:
        r["rows_ratio"] = r["rows"] / base["rows"]
        r["analyze_time_ratio"] = r["analyze_s"] / base["analyze_s"]
        r["analyze_memory_ratio"] = r["analyze_peak_mb"] / base["analyze_peak_mb"]
        r["export_time_ratio"] = r["export_s"] / base["export_s"]
        r["export_memory_ratio"] = r["export_peak_mb"] / base["export_peak_mb"]
    payload = {"cores": os.cpu_count(), "load_average": os.getloadavg(), "sizes": results}
    if args.json:
        emit(payload, True)
        return 0
    print_table("scale: hapticlab analyze and export (long-csv) against rows; ratios to the "
                f"smallest size ({base['rows']:,} rows), same run",
                ["rows", "participants", "analyze (s)", "× time", "peak (MB)", "× memory",
                 "export (s)", "× time", "peak (MB)", "× memory"],
                [(f"{r['rows']:,}", f"{r['participants']:,}", f"{r['analyze_s']:.1f}",
                  f"{r['analyze_time_ratio']:.1f}", f"{r['analyze_peak_mb']:.0f}",
                  f"{r['analyze_memory_ratio']:.1f}", f"{r['export_s']:.1f}",
                  f"{r['export_time_ratio']:.1f}", f"{r['export_peak_mb']:.0f}",
                  f"{r['export_memory_ratio']:.1f}") for r in results])
    steps = sorted({s for r in results for s in r["analyze_steps_s"]},
                   key=lambda s: min(list(r["analyze_steps_s"]).index(s)
                                     for r in results if s in r["analyze_steps_s"]))
    print_table("where analyze's time goes (s): starting Python and importing, then each step "
                "its progress reports", ["rows", "start", *steps],
                [(f"{r['rows']:,}", f"{r['analyze_start_s']:.1f}",
                  *(f"{r['analyze_steps_s'].get(s, 0):.1f}" for s in steps)) for r in results])
    for r in results:
        print(f"{r['rows']:,} rows: {'; '.join(r['analyses'])}")
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at the end")
    return 0
